"""The demo's outcome with the identified closed-edge leakage: its commissioning days (twelve
10 s snapshots each) identify the leakage, and V012 (Table 2's broken edge 1r halfway through
the span) is still faulty and V010 (past the x̂ wear bound) still worn — on those two valves of
the demo plant alone, with the demo's own data (``run_demo(valves=…)``), not the whole demo, and
its report without pictures (``detail=0``: the report's own tests draw them)."""

from __future__ import annotations

import pytest

from flows.common.warehouse_db import connect, query_frame


@pytest.mark.slow
def test_demo_ranks_v012_faulty_and_v010_worn(tmp_path, monkeypatch):
    import functools

    import flows.demo

    monkeypatch.setattr(flows.demo, "run_report", functools.partial(flows.demo.run_report, detail=0))
    flows.demo.run_demo(tmp_path, show_progress=False, valves=("V010", "V012"))
    with connect(tmp_path) as con:
        cond = query_frame(con, "SELECT valve_id, edge, state, leak_scale, leak_scale_baseline, n_ok_windows FROM valve_condition")
        base = query_frame(con, "SELECT valve_id, edge, source, leak_scale, leak_scale_ci_low FROM baselines")
        held = query_frame(con, "SELECT count(*) FILTER (WHERE leak_scale_held) AS n FROM edge_fits")["n"][0]
    states = {(r["valve_id"], r["edge"]): r["state"] for r in cond.iter_rows(named=True)}
    assert states[("V012", "1r")] == "faulty"
    assert "worn" in {states[("V010", e)] for e in ("s1", "1r", "s2", "2r")}
    assert (base["source"] == "commissioning").all() and base["leak_scale_ci_low"].is_not_null().all()  # identified
    assert (cond["leak_scale"].drop_nulls() >= 0).all()
    # an edge's leakage is a number where some window resolved it, else undetermined (null; windows
    # that could not tell it held the commissioning's, edge_fits.leak_scale_held)
    assert (cond["n_ok_windows"].filter(cond["leak_scale"].is_null()) > 0).all()
    assert cond["leak_scale"].is_not_null().all() or held > 0

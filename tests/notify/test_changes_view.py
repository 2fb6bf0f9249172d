"""View ``condition_changes`` on hand-built ``condition_history`` runs (in-memory DuckDB with
the views of sql/), and end to end from ``valve_condition`` on hand-built fits."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl
import pytest

from flows.common.warehouse_db import insert_frame
from flows.notify.night import history_rows
from schemas.fields import CONDITION_HISTORY_FIELDS, EDGES, polars_schema
from tests.report.viewdb import Warehouse

T0 = datetime(2026, 9, 1, 2, 30, tzinfo=timezone.utc)


@pytest.fixture
def wh():
    w = Warehouse()
    yield w
    w.con.close()


def _run(w: Warehouse, night: int, edges: dict[tuple[str, str], dict], below: float | None = None) -> None:
    """Record run ``night`` (run_at T0 + night days): (valve, edge) → state and the rest."""
    at = T0 + timedelta(days=night)
    rows = [{
        "run_id": f"run{night}", "run_at": at, "run_kind": "report", "valve_id": v, "edge": e, "edge_order": EDGES.index(e) + 1,
        "state": d["state"], "reason": d.get("reason", d["state"]), "remaining_hours": d.get("remaining"),
        "remaining_below_h": below, "first_alarm_start": d.get("first"), "last_alarm_start": d.get("last", d.get("first")),
        "last_ok_window_start": at - timedelta(hours=3), "report_path": "/r/report.html",
    } for (v, e), d in edges.items()]  # fmt: skip
    insert_frame(w.con, "condition_history", pl.DataFrame(rows, schema=polars_schema(CONDITION_HISTORY_FIELDS)))


def _changes(w: Warehouse) -> list[tuple]:
    return [tuple(r) for r in w.q("SELECT valve_id, edge, change, state_before, state_after FROM condition_changes").iter_rows()]


def test_no_run_and_the_first_run(wh):
    assert _changes(wh) == []
    a1 = T0 - timedelta(hours=5)
    _run(wh, 0, {("V1", "s1"): {"state": "healthy"}, ("V1", "1r"): {"state": "faulty", "first": a1},
                 ("V2", "s1"): {"state": "worn"}, ("V2", "1r"): {"state": "unknown"}})  # fmt: skip
    # nothing to compare with: what is faulty or worn is named, with no state before
    assert _changes(wh) == [("V1", "1r", "faulty", None, "faulty"), ("V2", "s1", "worn", None, "worn")]
    assert wh.q("SELECT window_start FROM condition_changes WHERE change = 'faulty'").item() == a1


def test_every_kind_of_change_against_the_run_before_only(wh):
    a1, a2 = T0 - timedelta(hours=5), T0 + timedelta(hours=20)
    night0 = {("V1", "s1"): {"state": "healthy"}, ("V1", "1r"): {"state": "faulty", "first": a1},
              ("V1", "s2"): {"state": "healthy", "remaining": 900.0}, ("V2", "s1"): {"state": "worn"},
              ("V2", "1r"): {"state": "healthy"}}  # fmt: skip
    _run(wh, 0, night0, below=500)
    _run(wh, 1, night0, below=500)
    assert _changes(wh) == []  # the same condition twice: no change
    night2 = night0 | {("V1", "1r"): {"state": "faulty", "first": a1, "last": a2, "reason": "fault: alpha_hat 0.3"},
                       ("V1", "s2"): {"state": "healthy", "remaining": 400.0}, ("V2", "s1"): {"state": "healthy"},
                       ("V2", "1r"): {"state": "faulty", "first": a2}}  # fmt: skip
    _run(wh, 2, night2, below=500)
    assert _changes(wh) == [
        ("V1", "1r", "new_alarm", "faulty", "faulty"),
        ("V1", "s2", "remaining_below", "healthy", "healthy"),
        ("V2", "s1", "recovered", "worn", "healthy"),
        ("V2", "1r", "faulty", "healthy", "faulty"),
    ]
    row = wh.q("SELECT * FROM condition_changes WHERE change = 'new_alarm'").to_dicts()[0]
    assert (row["window_start"], row["reason"], row["run_id"], row["run_id_before"]) == (a2, "fault: alpha_hat 0.3", "run2", "run1")
    _run(wh, 3, night2, below=500)
    assert _changes(wh) == []  # still below the horizon, still faulty: said once
    _run(wh, 4, night2 | {("V1", "s2"): {"state": "healthy", "remaining": 100.0}})  # no horizon configured
    assert _changes(wh) == []


def test_the_latest_run_is_the_latest_in_time_not_the_last_written(wh):
    _run(wh, 5, {("V1", "s1"): {"state": "worn"}})
    _run(wh, 4, {("V1", "s1"): {"state": "healthy"}})  # an older run written later
    assert _changes(wh) == [("V1", "s1", "worn", "healthy", "worn")]


def test_from_valve_condition_a_broken_edge_and_its_window(wh):
    hours = np.arange(0.0, 100.0)
    wh.add_valve("V1")
    wh.add_healthy_edges("V1", hours)

    def record(night: int) -> None:
        rows = history_rows(wh.q("SELECT * FROM valve_condition"), run_id=f"n{night}", run_at=T0 + timedelta(days=night),
                            kind="report", remaining_below_h=None, report="/r/report.html")  # fmt: skip
        insert_frame(wh.con, "condition_history", rows)

    record(0)
    assert _changes(wh) == []  # all healthy
    wh.add_fits("V1", "1r", np.arange(100.0, 104.0), 0.3, 0.23, 0.1)  # Table 2's broken edge from window 100 h on
    record(1)
    assert _changes(wh) == [("V1", "1r", "faulty", "healthy", "faulty")]
    row = wh.q("SELECT window_start, reason FROM condition_changes").to_dicts()[0]
    first = wh.q("SELECT min(window_start) FROM edge_fits WHERE edge = '1r' AND alpha_hat < 0.5").item()
    assert row["window_start"] == first and row["reason"].startswith("fault: alpha_hat")
    assert first.strftime("%Y-%m-%d %H:%M") in row["reason"]  # "… alarm window(s) since <the first>"

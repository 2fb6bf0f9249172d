"""The sql/ views against hand-built fits with known answers (in-memory DuckDB, no Prefect)."""

from __future__ import annotations

import html

import duckdb
import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

from flows.common.errors import ValvemonError
from flows.report.export import export_bi
from flows.report.html import render_report
from flows.report.remaining import remaining_text, two_figures
from flows.report.views import SQL_DIR, create_views, discover_views, materialise_views, ordered_views
from schemas.fields import EDGES
from tests.report.viewdb import COMMISSIONED

HOURS = np.arange(0.0, 200.0, 1.0)  # one window per operating hour


def test_views_load_in_dependency_order(wh):
    views = ordered_views(discover_views())
    names = [v.name for v in views]
    for v in views:
        for d in v.depends_on:
            assert names.index(d) < names.index(v.name)
    layers = {v.name: v.layer for v in views}
    assert layers["stg_edge_fits"] == "staging" and layers["valve_condition"] == "report"
    assert {"valve_condition", "fleet_ranking", "fault_alarms", "threshold_breaches", "parameter_trends",
            "trend_daily", "trend_operating_hours", "standstill_indicator"} <= set(names)
    cols = wh.q("SELECT * FROM valve_condition LIMIT 0").columns
    assert cols[:7] == ["valve_id", "edge", "state", "reason", "remaining_hours", "remaining_hours_low", "remaining_hours_high"]


def test_a_cycle_and_a_layer_violation_are_refused(tmp_path):
    for layer in ("staging", "core", "report"):
        (tmp_path / layer).mkdir()
    (tmp_path / "staging" / "stg_a.sql").write_text("select * from core_b")
    (tmp_path / "core" / "core_b.sql").write_text("select * from stg_a")
    with pytest.raises(ValvemonError, match="staging view may not read the core view 'core_b'"):
        ordered_views(discover_views(tmp_path))
    (tmp_path / "staging" / "stg_a.sql").write_text("select * from stg_c -- reads c")
    (tmp_path / "staging" / "stg_c.sql").write_text("select * from stg_a")
    with pytest.raises(ValvemonError, match="cycle"):
        ordered_views(discover_views(tmp_path))
    assert SQL_DIR.is_dir()


def test_views_are_created_again_only_when_their_sql_or_the_tables_changed(tmp_path):
    for layer in ("staging", "core", "report"):
        (tmp_path / layer).mkdir()
    (tmp_path / "staging" / "stg_t.sql").write_text("select * from t")
    (tmp_path / "core" / "core_t.sql").write_text("select a + 1 as b from stg_t")
    con = duckdb.connect()
    con.execute("CREATE TABLE t (a INTEGER)")

    def oids():
        return dict(con.execute("SELECT view_name, view_oid FROM duckdb_views() WHERE NOT internal").fetchall())

    assert create_views(con, tmp_path) == ["stg_t", "core_t"]
    first = oids()
    create_views(con, tmp_path)
    assert oids() == first  # the same SQL over the same tables: nothing made again
    con.execute("ALTER TABLE t ADD COLUMN c INTEGER")  # what add_missing_columns does after an upgrade
    create_views(con, tmp_path)
    assert con.execute("SELECT * FROM stg_t").description[1][0] == "c"
    second = oids()
    assert second["stg_t"] != first["stg_t"]
    (tmp_path / "core" / "core_t.sql").write_text("select a + 2 as b from stg_t")
    con.execute("INSERT INTO t VALUES (1, 0)")
    create_views(con, tmp_path)
    assert con.execute("SELECT b FROM core_t").fetchall() == [(3,)]
    con.execute("CREATE OR REPLACE VIEW core_t AS SELECT 0 AS b")  # made by hand: its stamp is gone
    create_views(con, tmp_path)
    assert con.execute("SELECT b FROM core_t").fetchall() == [(3,)]


def test_normal_scatter_raises_no_alarm_and_is_healthy(wh):
    # Table 2's normal valve, window after window: α̂ 0.98 ± 0.01, x̂ 0.23 ± 0.1 %, e 0.10 ± 0.01 mm²
    wh.add_valve("N1")
    wh.add_healthy_edges("N1", HOURS, seed=1)
    assert wh.q("SELECT count(*) AS n FROM fault_alarms")["n"][0] == 0
    assert wh.q("SELECT count(*) AS n FROM threshold_breaches")["n"][0] == 0
    states = wh.q("SELECT state FROM valve_condition WHERE valve_id = 'N1'")["state"].to_list()
    assert states == ["healthy"] * 4
    z = wh.q("SELECT max(abs(z)) AS z FROM fit_checks WHERE valve_id = 'N1'")["z"][0]
    assert 0 < z < 6  # scored, but nowhere near the threshold


def test_table3_wear_raises_no_alarm(wh):
    # Table 3: α̂ 1.04 → 1.17 and x̂ 0.1 → 3.7 % of x_max over 700 … 16,700 h, one window a day, with scatter
    rng = np.random.default_rng(3)
    h = np.arange(700.0, 16_700.0 + 1, 24.0)
    f = (h - 700) / 16_000
    wh.add_valve("W1")
    wh.add_fits("W1", "s2", h, 1.04 + 0.13 * np.sqrt(f) + 0.01 * rng.standard_normal(h.size),
                0.1 + 3.6 * f + 0.1 * rng.standard_normal(h.size), 0.32 - 0.14 * f + 0.01 * rng.standard_normal(h.size))
    assert wh.q("SELECT count(*) AS n FROM fault_alarms")["n"][0] == 0
    c = wh.condition("W1", "s2")
    assert c["state"] == "healthy", c["reason"]
    assert c["alpha_level"] == pytest.approx(1.17, abs=0.02) and c["x_hat_pct_level"] == pytest.approx(3.7, abs=0.2)
    # x̂ rises 0.225 %/1000 h: its bound of 6 % is ahead, after the latest window
    assert c["remaining_hours"] > 0 and c["limiting_parameter"] in ("x_hat_pct", "alpha_hat")


def test_one_faulty_window_among_normal_ones_is_caught(wh, tmp_path):
    # the paper's faulty edge 1r (Table 2: α̂ 2.53, x̂ 11.8 %, e 1.13 mm²) in the latest window; its
    # edge s1 wears toward its bound within the horizon (as the demo's V012, whose fleet row once
    # took its remaining life from a healthy edge), and valve D wears faster than that s1
    wh.add_valve("F1")
    wh.add_healthy_edges("F1", HOURS, seed=2, skip=("1r", "s1"))
    wh.add_fits("F1", "s1", HOURS, 1.0 + 0.0005 * HOURS, 0.2, 0.1)  # 1.30 at 600 h
    wh.add_valve("D")
    wh.add_healthy_edges("D", HOURS, seed=3, skip=("s2",))
    wh.add_fits("D", "s2", HOURS, 1.0 + 0.001 * HOURS, 0.2, 0.1)  # 1.30 at 300 h
    a, x, e = np.full(HOURS.size, 0.98), np.full(HOURS.size, 0.23), np.full(HOURS.size, 0.10)
    a[-1], x[-1], e[-1] = 2.53, 11.8, 1.13
    wh.add_fits("F1", "1r", HOURS, a, x, e)
    # computed once, as the report does (test_materialised_views_give_the_views_rows: the same rows as the views)
    materialise_views(wh.con, ("valve_condition", "fleet_ranking", "fault_alarms", "threshold_breaches"))
    alarms = wh.q("SELECT * FROM fault_alarms")
    assert alarms.height == 1 and alarms["edge"][0] == "1r" and alarms["operating_hours"][0] == HOURS[-1]
    assert alarms["beyond_fault_bound"][0] and alarms["change_alarm"][0]
    c = wh.condition("F1", "1r")
    assert c["state"] == "faulty" and "alpha_hat 2.53" in c["reason"] and c["remaining_basis"] == "faulty"
    assert (c["remaining_hours"], c["remaining_hours_low"], c["remaining_hours_high"]) == (0.0, 0.0, 0.0)
    assert remaining_text(c) == "now (faulty)"
    assert [wh.condition("F1", e)["state"] for e in ("s1", "s2", "2r")] == ["healthy"] * 3
    assert wh.condition("F1", "s1")["remaining_hours"] == pytest.approx(401.0, abs=1.0)
    breaches = wh.q("SELECT parameter, bound_kind FROM threshold_breaches WHERE bound_kind = 'fault' AND valve_id = 'F1' ORDER BY parameter")
    assert breaches["parameter"].to_list() == ["alpha_hat", "e_mm2", "x_hat_pct"]
    # the fleet row, in the view and in the BI export: first, no life left, the faulty edge named
    exported = pl.read_parquet(export_bi(wh.con, tmp_path)["fleet_ranking"])
    for rank in (wh.q("SELECT * FROM fleet_ranking ORDER BY urgency_rank"), exported):
        first = rank.row(0, named=True)
        assert (first["valve_id"], first["state"], first["worst_edge"], first["limiting_edge"]) == ("F1", "faulty", "1r", "1r")
        assert (first["remaining_hours"], first["remaining_hours_low"], first["remaining_hours_high"]) == (0.0, 0.0, 0.0)
        assert first["remaining_basis"] == "faulty" and first["reason"].startswith("fault: ")
        assert rank["valve_id"].to_list() == ["F1", "D"] and rank["remaining_hours"][1] == pytest.approx(101.0, abs=1e-6)  # 1.30 at 300 h, latest 199 h


def test_a_departure_inside_the_bounds_is_caught_by_the_change_detector(wh):
    # α̂ jumps from 1.00 to 1.25: inside every bound, but 25 σ-floors away from its own history
    wh.add_valve("C1")
    a = np.full(HOURS.size, 1.0) + 0.005 * np.sin(HOURS)
    a[150] = 1.25
    wh.add_fits("C1", "s1", HOURS, a, 0.2, 0.1)
    alarms = wh.q("SELECT * FROM fault_alarms")
    assert alarms["operating_hours"].to_list() == [150.0]
    assert alarms["change_alarm"][0] and not alarms["beyond_fault_bound"][0]
    assert alarms["alpha_z"][0] > 6
    # 49 h later the alarm is past fault_hold_hours (24 h): the edge is healthy again, the alarm stays on record
    assert wh.condition("C1", "s1")["state"] == "healthy"


def test_a_trend_beyond_its_wear_bound_is_worn(wh):
    # x̂ = 0.1 + 0.01 h % crosses the wear bound 6 % at 590 h; fits until 800 h
    h = np.arange(0.0, 800.0, 1.0)
    wh.add_valve("T1")
    wh.add_fits("T1", "s2", h, 1.0, 0.1 + 0.01 * h, 0.1)
    c = wh.condition("T1", "s2")
    assert c["state"] == "worn" and "x_hat_pct level" in c["reason"] and "above wear bound 6" in c["reason"]
    assert (c["remaining_hours"], c["remaining_hours_low"], c["remaining_hours_high"]) == (0.0, 0.0, 0.0)
    assert wh.q("SELECT count(*) AS n FROM fault_alarms")["n"][0] == 0  # slow wear: no short-term alarm
    first = wh.q("SELECT min(operating_hours) AS h FROM threshold_breaches WHERE bound_kind = 'wear'")["h"][0]
    assert first == 591.0  # the first window beyond 6 %


def test_remaining_life_of_an_exactly_linear_trend_is_its_crossing(wh):
    # x̂ = 0.1 + 0.01 h %: reaches 6 % at exactly 590 h; the latest window is at 199 h → 391 h left
    wh.add_valve("L1")
    wh.add_fits("L1", "s2", HOURS, 1.0, 0.1 + 0.01 * HOURS, 0.1)
    c = wh.condition("L1", "s2")
    assert c["state"] == "healthy" and c["limiting_parameter"] == "x_hat_pct"
    assert c["end_of_life_hours"] == pytest.approx(590.0, abs=1e-6)
    assert c["remaining_hours"] == pytest.approx(391.0, abs=1e-6)
    # the interval holds the point (to rounding: an exact line has a zero-width interval, and its
    # pooled sums vary in the last bits with DuckDB's thread order)
    assert c["remaining_hours_low"] - 1e-9 <= c["remaining_hours"] <= c["remaining_hours_high"] + 1e-9
    assert c["remaining_hours_high"] - c["remaining_hours_low"] < 1e-3


def test_a_crossing_beyond_the_horizon_is_no_forecast(wh, tmp_path):
    # α̂ = 1 + 0.0001 h on every edge: a significant trend that reaches 1.30 at 3000 h, 2801 h after
    # the latest window: 14 × the 199 h of data, beyond the horizon of 3 × 199 = 597 h
    wh.add_valve("H1")
    for edge in EDGES:
        wh.add_fits("H1", edge, HOURS, 1.0 + 0.0001 * HOURS, 0.2, 0.1)
    materialise_views(wh.con, ("parameter_trends", "valve_condition", "fleet_ranking"))  # once, as the report does
    trend = wh.q("SELECT * FROM parameter_trends WHERE valve_id = 'H1' AND edge = 's1' AND parameter = 'alpha_hat' AND side = 'high'")
    assert trend["crossing_status"][0] == "predicted" and trend["remaining_hours"][0] == pytest.approx(2801.0, abs=1e-3)
    c = wh.condition("H1", "s1")
    assert c["state"] == "healthy" and c["remaining_basis"] == "beyond_horizon" and c["limiting_parameter"] == "alpha_hat"
    assert c["remaining_hours"] is None and c["remaining_hours_low"] is None and c["remaining_hours_high"] is None
    assert c["end_of_life_hours"] is None and c["remaining_horizon_hours"] == pytest.approx(597.0)
    assert "only beyond the horizon" in c["reason"] and "2801" not in c["reason"]
    rank = pl.read_parquet(export_bi(wh.con, tmp_path)["fleet_ranking"]).row(0, named=True)
    assert (rank["remaining_hours"], rank["remaining_basis"], rank["urgency_tier"]) == (None, "beyond_horizon", 6)
    # the human-facing words: the horizon rounded down to two figures, so "more than" stays true
    words = "> 590 h (no wear toward a bound within the horizon)"
    assert remaining_text(c) == remaining_text(rank) == words
    page = render_report(plant="P", generated_at=COMMISSIONED, ranking=wh.q("SELECT * FROM fleet_ranking"),
                         conditions=wh.q("SELECT * FROM valve_condition"), fleet_png=_png(tmp_path), valve_pngs={},
                         discrepancy={}, snapshot=tmp_path)
    assert html.escape(words) in page and "2801" not in page and "2,801" not in page


def test_a_worn_valves_near_term_forecast_is_unchanged(wh):
    # Table 3's wear rate (x̂ +7.75 nm/h = 0.22 %/1000 h of x_max 3.5 mm) on a valve at 5.5 %, 6-hourly
    # windows with scatter: 6 % is ~2,300 h ahead, inside the horizon of 3 × the 2,000 h of data
    rng = np.random.default_rng(11)
    h = np.arange(20_000.0, 22_000.0, 6.0)
    x = 5.5 + 7.75e-6 / 3.5 * 100 * (h - h[-1]) + 0.05 * rng.standard_normal(h.size)
    wh.add_valve("W")
    wh.add_fits("W", "s2", h, 1.17, x, 0.18)
    trend = wh.q("SELECT * FROM parameter_trends WHERE valve_id = 'W' AND parameter = 'x_hat_pct' AND side = 'high'").row(0, named=True)
    c = wh.condition("W", "s2")
    assert c["remaining_basis"] == "forecast" and c["limiting_parameter"] == "x_hat_pct"
    # the same forecast as the trend's (to rounding: two queries pool the day sums in DuckDB's thread order)
    assert (c["remaining_hours"], c["remaining_hours_low"], c["remaining_hours_high"], c["end_of_life_hours"]) == pytest.approx((
        trend["remaining_hours"], trend["remaining_hours_low"], trend["remaining_hours_high"], trend["end_of_life_hours"]), rel=1e-12)
    assert 1500 < c["remaining_hours"] < 3000 and c["remaining_hours_high"] < c["remaining_horizon_hours"]
    assert remaining_text(c) == (f"{two_figures(c['remaining_hours'])} h (95 %: {two_figures(c['remaining_hours_low'])}–"
                                 f"{two_figures(c['remaining_hours_high'])} h)")


def _png(tmp_path):
    path = tmp_path / "fleet.png"
    path.write_bytes(b"png")
    return path


def test_remaining_life_interval_covers_the_crossing_of_a_noisy_trend(wh):
    # α̂ = 1 + 0.0005 h with scatter 0.005: reaches 1.30 at 600 h; the interval must contain it
    rng = np.random.default_rng(7)
    wh.add_valve("L2")
    wh.add_fits("L2", "1r", HOURS, 1.0 + 0.0005 * HOURS + 0.005 * rng.standard_normal(HOURS.size), 0.2, 0.1)
    c = wh.condition("L2", "1r")
    assert c["limiting_parameter"] == "alpha_hat"
    assert c["end_of_life_hours"] == pytest.approx(600.0, rel=0.1)
    assert c["remaining_hours_low"] < 600.0 - HOURS[-1] < c["remaining_hours_high"]
    assert c["remaining_hours_low"] < c["remaining_hours"] < c["remaining_hours_high"]
    trend = wh.q("SELECT * FROM parameter_trends WHERE valve_id = 'L2' AND parameter = 'alpha_hat' AND side = 'high'").row(0, named=True)
    assert trend["slope_per_hour"] == pytest.approx(0.0005, rel=0.1) and trend["crossing_status"] == "predicted"
    low = wh.q("SELECT crossing_status FROM parameter_trends WHERE valve_id = 'L2' AND parameter = 'alpha_hat' AND side = 'low'")
    assert low["crossing_status"][0] == "away_from_bound"


def test_too_little_data_is_unknown(wh):
    wh.add_valve("U1")
    wh.add_fits("U1", "s1", HOURS[:5], 1.0, 0.2, 0.1)  # 5 ok windows, 10 needed
    wh.add_fits("U1", "1r", HOURS[:30], 1.0, 0.2, 0.1, status="too_few_points")
    materialise_views(wh.con, ("valve_condition", "fleet_ranking"))  # once, as the report does
    c = {e: wh.condition("U1", e) for e in EDGES}
    assert [c[e]["state"] for e in EDGES] == ["unknown"] * 4
    assert "too little data: 5" in c["s1"]["reason"]
    assert "no ok fit in 30 window(s); last status too_few_points" in c["1r"]["reason"]
    assert c["s2"]["reason"] == "no fits yet" and c["s1"]["remaining_hours"] is None
    rank = wh.q("SELECT * FROM fleet_ranking").row(0, named=True)
    assert rank["state"] == "unknown" and rank["urgency_tier"] == 5


def test_a_short_span_gives_a_state_but_no_forecast(wh):
    wh.add_valve("S1", trend_min_span_hours=100.0)
    h = np.arange(0.0, 50.0, 1.0)
    wh.add_fits("S1", "s1", h, 1.0 + 0.001 * h, 0.2, 0.1)
    c = wh.condition("S1", "s1")
    assert c["state"] == "healthy" and c["remaining_hours"] is None
    st = wh.q("SELECT DISTINCT crossing_status FROM parameter_trends WHERE valve_id = 'S1'")["crossing_status"].to_list()
    assert st == ["too_little_data"]


def test_fits_against_an_older_baseline_are_left_out(wh):
    wh.add_valve("B1")
    wh.add_fits("B1", "s1", HOURS, 2.5, 11.0, 1.1, baseline_version=1)  # against the old baseline
    wh.add_fits("B1", "s1", HOURS + 200, 1.0, 0.2, 0.1, baseline_version=2)
    assert wh.condition("B1", "s1")["state"] == "healthy"
    assert wh.q("SELECT count(*) AS n FROM stg_edge_fits")["n"][0] == HOURS.size


def test_x_hat_a_window_did_not_determine_is_left_out(wh):
    # the latest window's x̂ far beyond the fault bound, but its points too short a range of u to
    # tell a shift from a scale: its α̂ and e count, its x̂ neither alarms nor is the edge's x̂
    wh.add_valve("N1")
    x, det = np.full(HOURS.size, 0.23), np.ones(HOURS.size, bool)
    x[-1], det[-1] = 11.8, False
    wh.add_fits("N1", "s1", HOURS, 0.98, x, 0.10, x_determined=det)
    params = wh.q("SELECT parameter, count(*) AS n FROM stg_fit_parameters GROUP BY parameter ORDER BY parameter")
    assert params["n"].to_list() == [HOURS.size, HOURS.size, HOURS.size - 1]  # alpha_hat, e_mm2, x_hat_pct
    assert wh.q("SELECT count(*) AS n FROM fault_alarms")["n"][0] == 0
    c = wh.condition("N1", "s1")
    assert c["state"] == "healthy" and c["x_hat_pct"] == pytest.approx(0.23)
    x[-1], det[-1] = 11.8, True  # the same x̂ determined: faulty
    wh.add_fits("N1", "s2", HOURS, 0.98, x, 0.10, x_determined=det)
    assert wh.condition("N1", "s2")["state"] == "faulty"


def test_leakage_a_window_could_not_resolve_is_undetermined(wh, tmp_path):
    # windows whose leak_scale interval was too wide hold the commissioning's (edge_fits.leak_scale_held):
    # the views show no number for them, the edge's leakage is the median of the windows that resolved
    # it, or none (the report says undetermined)
    wh.add_valve("L1")
    held = np.zeros(HOURS.size, bool)
    held[-3:] = True
    leak = np.where(held, 10.0, 0.2)
    wh.add_fits("L1", "s1", HOURS, 0.98, 0.23, 0.10, leak=leak, leak_held=held)
    wh.add_fits("L1", "s2", HOURS, 0.98, 0.23, 0.10, leak=10.0, leak_held=True)
    assert wh.q("SELECT count(leak_scale) AS n FROM stg_edge_fits WHERE edge = 's1'")["n"][0] == HOURS.size - 3
    assert wh.condition("L1", "s1")["leak_scale"] == pytest.approx(0.2)
    c = wh.condition("L1", "s2")
    assert c["leak_scale"] is None and c["n_ok_windows"] == HOURS.size
    page = render_report(plant="P", generated_at=COMMISSIONED, ranking=wh.q("SELECT * FROM fleet_ranking"),
                         conditions=wh.q("SELECT * FROM valve_condition"), fleet_png=_png(tmp_path), valve_pngs={"L1": []},
                         discrepancy={}, snapshot=tmp_path)
    assert page.count("undetermined") == 1  # s2; s1 shows 0.20


def test_configured_bounds_are_used(wh):
    # the same fits: healthy with the defaults, worn with a tighter α̂ wear bound
    wh.add_valve("K1")
    wh.add_valve("K2", alpha_wear_high=1.10)
    for v in ("K1", "K2"):
        wh.add_fits(v, "s1", HOURS, 1.15, 0.2, 0.1)
    materialise_views(wh.con, ("valve_condition",))  # once, as the report does
    assert wh.condition("K1", "s1")["state"] == "healthy"
    assert wh.condition("K2", "s1")["state"] == "worn"


def test_eq9_indicator_against_the_design_value(wh):
    wh.add_valve("E1")
    wh.add_valve("E2")
    for v in ("E1", "E2"):
        wh.add_healthy_edges(v, HOURS, seed=4)
    wh.add_standstill("E1", HOURS[::10], -0.15)  # healthy Table 1 valve rests near -0.17
    r = np.full(HOURS[::10].size, -0.16)
    r[-1] = -1.4  # the paper's broken edge
    wh.add_standstill("E2", HOURS[::10], r)
    materialise_views(wh.con, ("standstill_indicator", "valve_condition", "fleet_ranking"))  # once, as the report does
    ind = {row["valve_id"]: row for row in wh.q("SELECT * FROM standstill_indicator").iter_rows(named=True)}
    assert ind["E1"]["eq9_ok"] and not ind["E2"]["eq9_ok"]
    assert ind["E2"]["eq9_deviation"] == pytest.approx(-1.4 + 0.17)
    assert ind["E2"]["eq9_drift"] == pytest.approx(-1.4 + 0.16)
    assert ind["E2"]["n_recent_failures"] == 1
    c = wh.condition("E2", "s1")
    assert c["state"] == "healthy" and "Eq. 9 standstill check fails" in c["reason"] and c["eq9_ok"] is False
    rank = wh.q("SELECT valve_id, urgency_tier FROM fleet_ranking ORDER BY urgency_rank")
    assert rank.row(0) == ("E2", 3)


def test_fleet_ranking_orders_by_urgency(wh):
    for v in ("A_healthy", "B_faulty", "C_worn", "D_soon", "E_later", "F_unknown"):
        wh.add_valve(v)
    for v in ("A_healthy", "B_faulty", "C_worn", "D_soon", "E_later"):
        wh.add_healthy_edges(v, HOURS, seed=5, skip=("s1",))
    flat = np.zeros(HOURS.size)
    wh.add_fits("A_healthy", "s1", HOURS, 1.0 + flat, 0.2, 0.1)
    wh.add_fits("B_faulty", "s1", HOURS, np.where(HOURS == HOURS[-1], 2.5, 1.0), 0.2, 0.1)
    wh.add_fits("C_worn", "s1", HOURS, 1.4 + flat, 0.2, 0.1)
    wh.add_fits("D_soon", "s1", HOURS, 1.0 + 0.001 * HOURS, 0.2, 0.1)  # 1.3 at 300 h
    wh.add_fits("E_later", "s1", HOURS, 1.0 + 0.0004 * HOURS, 0.2, 0.1)  # 1.3 at 750 h
    wh.add_fits("F_unknown", "s1", HOURS[:3], 1.0, 0.2, 0.1)
    rank = wh.q("SELECT valve_id, state FROM fleet_ranking ORDER BY urgency_rank")
    # the random scatter of the healthy edges may give a forecast too, but far beyond these
    assert rank["valve_id"].to_list()[:4] == ["B_faulty", "C_worn", "D_soon", "E_later"]
    assert rank["state"].to_list()[:2] == ["faulty", "worn"]
    assert set(rank["valve_id"].to_list()[4:]) == {"A_healthy", "F_unknown"}


def test_trend_views(wh):
    wh.add_valve("D1")
    wh.add_fits("D1", "s1", HOURS, 1.0 + 0.001 * HOURS, 0.2, 0.1)
    daily = wh.q("SELECT * FROM trend_daily WHERE parameter = 'alpha_hat' ORDER BY day_utc")
    assert daily["n_windows"].to_list() == [24] * 8 + [8]  # 200 hourly windows from 2025-01-01 00:00 UTC
    assert str(daily["day_utc"][0]) == "2025-01-01"
    assert daily["median_value"][0] == pytest.approx(1.0115)
    oh = wh.q("SELECT * FROM trend_operating_hours WHERE parameter = 'alpha_hat' ORDER BY operating_hours")
    assert oh.height == HOURS.size
    assert np.allclose(oh["trend_value"].to_numpy(), 1.0 + 0.001 * HOURS)
    assert oh["rolling_median"][0] is None and oh["rolling_median"][30] == pytest.approx(1.0 + 0.001 * 17.5)


def test_materialised_views_give_the_views_rows(wh):
    # the report computes each view once into a temporary table of the same name; what it reads must not change
    wh.add_valve("M1")
    wh.add_healthy_edges("M1", HOURS, seed=6, skip=("s1",))
    wh.add_fits("M1", "s1", HOURS, np.where(HOURS == 150, 1.25, 1.0), 0.1 + 0.01 * HOURS, 0.1)
    names = ("valve_condition", "fleet_ranking", "trend_daily", "fault_alarms")
    before = {n: wh.q(f"SELECT * FROM {n}") for n in names}
    done = materialise_views(wh.con, names)
    assert done.index("fit_checks") < done.index("window_alarms") < done.index("valve_condition") < done.index("fleet_ranking")
    assert "stg_edge_fits" not in done  # staging views stay views
    temp = {r[0] for r in wh.con.execute("SELECT table_name FROM duckdb_tables() WHERE temporary").fetchall()}
    assert set(names) <= temp
    for n in names:  # the trend's sums are merged in an order DuckDB's threads choose: equal to rounding
        assert_frame_equal(wh.q(f"SELECT * FROM {n}"), before[n], check_exact=False, rel_tol=1e-6)
    assert before["fault_alarms"].height == 1 and wh.condition("M1", "s1")["state"] == "healthy"

"""The daily summaries (flows/report/summaries.py): night after night (four), the views read from the
summaries and the open windows give what they give computed from scratch (every window open),
after late data re-monitors a closed day, after a bound changes, and after a run killed
halfway and rerun; a rerun with nothing new writes nothing."""

from __future__ import annotations

from datetime import timedelta

import numpy as np
import pytest
from polars.testing import assert_frame_equal

import flows.report.summaries as summaries
from flows.report.summaries import update_summaries
from flows.report.views import materialise_views
from schemas.fields import EDGES
from tests.report.viewdb import COMMISSIONED, Warehouse

VIEWS = {  # the views the report reads, and their keys
    "valve_condition": "valve_id, edge",
    "fleet_ranking": "valve_id",
    "parameter_trends": "valve_id, edge, parameter, side",
    "trend_daily": "valve_id, edge, day_utc, parameter",
    "fault_alarms": "valve_id, edge, window_start",
}
TABLES = ("edge_day_summaries", "parameter_day_summaries", "alarm_windows", "summary_watermarks")
PER_DAY = {"C1": 24, "S1": 4}  # a window an hour; a snapshot every 6 h


def night(wh: Warehouse, day: int, rng: np.random.Generator, *, again: bool = False, late: int = 0) -> None:
    """The fits of UTC day ``day`` of both valves, monitored ``late`` days after the night after it
    (``again``: re-monitored, replacing the day's rows)."""
    monitored = COMMISSIONED + timedelta(days=day + 1 + late, hours=2)
    for valve, per_day in PER_DAY.items():
        hours = day * 24 + np.arange(per_day) * 24 / per_day
        if again:
            wh.con.execute("DELETE FROM edge_fits WHERE valve_id = ? AND window_start >= ? AND window_start < ?",
                           [valve, COMMISSIONED + timedelta(days=day), COMMISSIONED + timedelta(days=day + 1)])
        for edge in EDGES:
            n = hours.size
            alpha = 1.0 - 2e-3 * hours / 24 + 0.01 * rng.standard_normal(n)
            if edge == "1r" and valve == "C1":
                alpha[hours == 32] = 0.7  # an alarm on day 1, as a break
            status = np.where(rng.random(n) < 0.1, "too_few_points", "ok")
            wh.add_fits(valve, edge, hours, alpha, 0.2 + 0.03 * hours / 24 + 0.1 * rng.standard_normal(n),
                        0.1 + 0.01 * rng.standard_normal(n), status=status, x_determined=rng.random(n) > 0.2,
                        leak=1.0 + 0.05 * rng.standard_normal(n), monitored_at=monitored)


def from_scratch(wh: Warehouse) -> dict:
    """The views with no summary at all (every window open), in a transaction rolled back."""
    wh.con.execute("BEGIN TRANSACTION")
    try:
        for t in TABLES:
            wh.con.execute(f"DELETE FROM {t}")
        return views(wh)
    finally:
        wh.con.execute("ROLLBACK")


def views(wh: Warehouse) -> dict:
    """The views, each computed once (as the report does: temporary tables shadowing them)."""
    made = materialise_views(wh.con, tuple(VIEWS))
    try:
        return {name: wh.q(f"SELECT * FROM {name} ORDER BY {key}") for name, key in VIEWS.items()}
    finally:
        for name in reversed(made):
            wh.con.execute(f"DROP TABLE temp.{name}")


def assert_same(got: dict, want: dict) -> None:
    for name in VIEWS:  # the trend's sums merge a day at a time: equal to rounding
        assert_frame_equal(got[name], want[name], check_exact=False, rel_tol=1e-9, abs_tol=1e-12), name


@pytest.fixture
def plant(wh: Warehouse) -> Warehouse:
    for valve in PER_DAY:  # short histories and trend span, so that nights move them
        wh.add_valve(valve, change_history_hours=8.0, change_history_windows=8, change_min_history=4,
                     trend_min_fits=10, trend_min_span_hours=12.0, trend_span_hours=60.0, fault_hold_hours=12.0)
    return wh


def test_night_after_night_the_summaries_give_the_full_recomputation(plant, monkeypatch):
    wh, rng = plant, np.random.default_rng(7)
    for day in range(4):
        night(wh, day, rng)
        update_summaries(wh.con, COMMISSIONED + timedelta(days=day + 1))
        assert_same(views(wh), from_scratch(wh))
    marks = wh.q("SELECT * FROM summary_watermarks ORDER BY valve_id")
    assert marks["summarised_before"].to_list() == [COMMISSIONED + timedelta(days=3)] * 2  # the latest day stays open
    assert (marks["raw_from"] < marks["summarised_before"]).all()
    assert wh.q("SELECT count(DISTINCT day_utc) AS n FROM edge_day_summaries")["n"][0] == 3
    closed = views(wh)
    assert closed["fault_alarms"].filter(closed["fault_alarms"]["valve_id"] == "C1").height >= 1  # the break, kept when its day closed
    assert wh.q("SELECT count(*) AS n FROM alarm_windows")["n"][0] >= 1
    # nothing new: nothing written
    assert update_summaries(wh.con, COMMISSIONED + timedelta(days=5)) == 0
    # late data: day 1 re-monitored with other values; the closed days from it on are computed again
    night(wh, 1, rng, again=True, late=30)
    assert update_summaries(wh.con, COMMISSIONED + timedelta(days=31)) == len(PER_DAY) * 4 * 2  # days 1-2, 4 edges
    assert_same(views(wh), from_scratch(wh))
    # a changed detector setting rebuilds the summaries
    wh.con.execute("UPDATE condition_bounds SET change_z = 4.0")
    assert update_summaries(wh.con, COMMISSIONED + timedelta(days=32)) == len(PER_DAY) * 4 * 3
    assert_same(views(wh), from_scratch(wh))
    # a run killed halfway (after its deletes, while it computes the days) leaves the summaries as they were
    night(wh, 4, rng, late=32)
    before = {t: wh.q(f"SELECT * FROM {t} ORDER BY ALL") for t in TABLES}

    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(summaries, "materialise_views", killed)
    with pytest.raises(KeyboardInterrupt):
        update_summaries(wh.con, COMMISSIONED + timedelta(days=33))
    for t in TABLES:
        assert_frame_equal(wh.q(f"SELECT * FROM {t} ORDER BY ALL"), before[t])
    assert_same(views(wh), from_scratch(wh))  # the views are right meanwhile, only slower
    monkeypatch.undo()
    assert update_summaries(wh.con, COMMISSIONED + timedelta(days=33)) == len(PER_DAY) * 4
    assert_same(views(wh), from_scratch(wh))

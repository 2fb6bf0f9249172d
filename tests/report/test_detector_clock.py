"""The change detector and the trends on the clock: continuously recorded valves (a window every
minute) and snapshot valves (a window every hour, or sparser) judged alike (sql/core/fit_checks.sql,
parameter_trends.sql; docs/monitoring.md, "The detector's clock")."""

from __future__ import annotations

import numpy as np
import pytest

from flows.report.views import materialise_views
from schemas.fields import EDGES

MINUTE = 1 / 60
WEEK_MINUTES = np.arange(7 * 24 * 60) * MINUTE  # 10,080 one-minute windows, in hours

# Window-to-window standard deviation of one-minute windows per edge (α̂, x̂ in % of x_max, e in
# mm²), measured on simulated continuous recordings: three Table 1 valves in the wear scenario at
# 8,000 h, 20 min each, fitted against the nominal characteristic, 60 windows per valve and edge
# (`bench/window_length.py --valves 3 --duration-s 1200 --lengths 60 --per-edge`; supply drift
# held to 10 bar per recording, so a day's changes of operation are not in it). The largest
# deviation seen was 2.7 standard deviations; the test draws ten times that spread, normal.
SCATTER = {
    "s1": (0.000050, 0.00210, 0.00056),
    "1r": (0.000049, 0.00208, 0.00154),
    "s2": (0.000057, 0.00254, 0.00220),
    "2r": (0.000053, 0.00218, 0.00030),
}
SPREAD = 10.0
LEVEL = {"s1": (1.03, 0.4, 0.10), "1r": (1.02, 0.3, 0.12), "s2": (1.04, 0.5, 0.15), "2r": (1.01, 0.2, 0.09)}
# Table 3's wear rates: x̂ +3.6 % of x_max and α̂ +0.13 over 16,000 h, carried along the week
X_RATE, ALPHA_RATE = 3.6 / 16_000, 0.13 / 16_000


def healthy(hours: np.ndarray, edge: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    (sa, sx, se), (a, x, e) = SCATTER[edge], LEVEL[edge]
    n = hours.size
    return (a + ALPHA_RATE * hours + SPREAD * sa * rng.standard_normal(n),
            x + X_RATE * hours + SPREAD * sx * rng.standard_normal(n),
            e + SPREAD * se * rng.standard_normal(n))  # fmt: skip


def test_a_week_of_a_healthy_continuous_valve_raises_no_alarm_and_uses_all_its_windows(wh):
    wh.add_valve("C1")
    rng = np.random.default_rng(27)
    for edge in EDGES:
        wh.add_fits("C1", edge, WEEK_MINUTES, *healthy(WEEK_MINUTES, edge, rng))
    materialise_views(wh.con, ("valve_condition", "parameter_trends", "trend_daily"))  # as the report does: each view once
    checks = wh.q("SELECT count(*) FILTER (WHERE is_alarm) AS alarms, count(*) FILTER (WHERE beyond_wear_bound) AS breaches, "
                  "min(ref_n) FILTER (WHERE operating_hours >= 24) AS lo, max(ref_n) AS hi FROM fit_checks").row(0)
    # no alarm, no bound crossed; the history is a day of windows once a day has passed, not 24 minutes
    assert checks == (0, 0, 1440, 1440)
    conditions = wh.q("SELECT c.state, t.n_fits, t.level_n FROM valve_condition c JOIN parameter_trends t USING (valve_id, edge)")
    assert set(conditions.rows()) == {("healthy", 10_080, 1440)}  # the trend on every window, the level on the last day's
    daily = wh.q("SELECT n_windows, n_ok, n_alarms FROM trend_daily WHERE edge = 's1' AND parameter = 'alpha_hat'")
    assert daily.rows() == [(1440, 1440, 0)] * 7  # what the pictures show: a point a day


@pytest.mark.parametrize("step_h", [MINUTE, 1.0])  # continuous recording; hourly snapshots
def test_the_first_alarm_is_the_first_window_after_a_break(wh, step_h):
    # B1's edge 1r breaks like Table 2's (α̂ +1.5, x̂ +11.8 % of x_max, e +1.13 mm²: beyond the fault
    # bounds), B2's by less, inside every bound (only the change detector sees it); both between two
    # windows, 36 h in; edge s1 stays healthy
    hours = np.arange(0.0, 48.0, step_h)
    broken = hours >= 36.0 + step_h / 2
    rng = np.random.default_rng(11)
    for valve, jump in (("B1", (1.5, 11.8, 1.13)), ("B2", (0.25, 1.5, 0.05))):
        wh.add_valve(valve)
        for edge in ("s1", "1r"):
            a, x, e = healthy(hours, edge, rng)
            if edge == "1r":
                a, x, e = a + jump[0] * broken, x + jump[1] * broken, e + jump[2] * broken
            wh.add_fits(valve, edge, hours, a, x, e)
    materialise_views(wh.con, ("valve_condition",))
    first = wh.q("SELECT valve_id, edge, min(operating_hours) AS h, bool_or(beyond_fault_bound) AS bound "
                 "FROM window_alarms WHERE is_alarm GROUP BY ALL ORDER BY valve_id")
    # none before the break, the first in its first window; B2 by the change detector alone
    assert first.rows() == [("B1", "1r", hours[broken][0], True), ("B2", "1r", hours[broken][0], False)]
    states = wh.q("SELECT valve_id, edge, state FROM valve_condition WHERE edge IN ('s1', '1r') ORDER BY valve_id, edge_order")
    assert states.rows() == [("B1", "s1", "healthy"), ("B1", "1r", "faulty"), ("B2", "s1", "healthy"), ("B2", "1r", "faulty")]


@pytest.mark.parametrize(("step_h", "history"), [(MINUTE, 1440), (1.0, 24), (6.0, 24)])
def test_the_history_is_a_day_or_change_history_windows_windows(wh, step_h, history):
    # a continuous recording: a day of one-minute windows; hourly snapshots: a day; 6-hourly
    # snapshots: the 24 windows of change_history_windows (6 days), as before the clock
    hours = np.arange(0.0, 24.0 * 9, step_h)[:2000]
    wh.add_valve("H1")
    wh.add_fits("H1", "s1", hours, 1.0, 0.2, 0.1)
    got = wh.q("SELECT f.ref_n, t.level_n FROM fit_checks f JOIN parameter_trends t USING (valve_id, edge, parameter) "
               "WHERE f.parameter = 'alpha_hat' ORDER BY f.window_start DESC LIMIT 1").row(0)
    assert got == (history, history)

"""The long-term level that decides ``worn`` uses the windows the history promises, whatever
``trend_span_hours`` says (issue 46, item 6): the alarm-free ok windows of the last
``change_history_hours`` before the latest ok window, or the last ``change_history_windows``
(24) of them if those reach further back. A valve with a window a day whose α̂ sits at 1.2297
above a wear bound of 1.2 was healthy with ``trend_span_hours = 120`` (the level then took only
the 6 windows of the span, fewer than ``change_min_history``) and worn with 240 h."""

from __future__ import annotations

import numpy as np
import pytest

DAILY = np.arange(0.0, 40 * 24.0, 24.0)  # a snapshot a day for 40 days


@pytest.mark.parametrize("span", [120.0, 240.0, 5000.0])
def test_the_level_uses_its_windows_whatever_the_trend_span(wh, span):
    rng = np.random.default_rng(4)
    alpha = 1.2297 + rng.normal(0.0, 0.002, DAILY.size)
    wh.add_valve("W1", alpha_wear_high=1.2, trend_span_hours=span)
    wh.add_fits("W1", "s1", DAILY, alpha, 0.2, 0.1)
    trend = wh.q("SELECT * FROM parameter_trends WHERE edge = 's1' AND parameter = 'alpha_hat' AND side = 'high'").row(0, named=True)
    assert trend["level_n"] == 24  # the latest 24 windows: 24 days reach further back than 24 h
    assert trend["level"] == pytest.approx(float(np.median(alpha[-24:])))
    assert trend["level_beyond_bound"]
    c = wh.condition("W1", "s1")
    assert c["state"] == "worn" and "alpha_hat level" in c["reason"], c["reason"]


def test_a_sound_edge_stays_healthy_with_a_short_trend_span(wh):
    """The same valve at α̂ 1.0: the level below the bound, healthy (the fix names no edge worn that is not)."""
    wh.add_valve("W2", alpha_wear_high=1.2, trend_span_hours=120.0)
    wh.add_fits("W2", "s1", DAILY, 1.0, 0.2, 0.1)
    assert wh.condition("W2", "s1")["state"] != "worn"

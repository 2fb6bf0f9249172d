"""A faulty edge's reason names when its alarms began: the first alarm window within
``fault_hold_hours``, not the last (issue 46, minor item), and the last one too."""

from __future__ import annotations

from datetime import timedelta

import numpy as np

from tests.report.viewdb import COMMISSIONED

HOURS = np.arange(0.0, 200.0, 1.0)


def test_the_reason_says_since_the_first_alarm(wh):
    alpha = np.where(HOURS >= 190.0, 0.3, 1.0)  # below the fault bound 0.5 from 190 h: ten alarm windows
    wh.add_valve("F1")
    wh.add_fits("F1", "s1", HOURS, alpha, 0.2, 0.1)
    c = wh.condition("F1", "s1")
    first, last = COMMISSIONED + timedelta(hours=190), COMMISSIONED + timedelta(hours=199)
    assert c["state"] == "faulty"
    assert f"(10 alarm window(s) since {first:%Y-%m-%d %H:%M} UTC, the last at {last:%Y-%m-%d %H:%M} UTC)" in c["reason"], c["reason"]

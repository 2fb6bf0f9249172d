"""The remaining life in words, for the human-facing table and report.

The numbers and the rule behind them are the view ``valve_condition`` (``remaining_basis``,
``remaining_hours``, ``remaining_hours_low`` / ``_high``, ``remaining_horizon_hours``), read as
they are by ``fleet_ranking`` and the BI export at full precision. Here they are only worded, and
rounded to two significant figures: a linear extrapolation of wear supports no more.
"""

from __future__ import annotations

import math


def two_figures(hours: float, *, down: bool = False) -> str:
    """``hours`` to two significant figures with thousands separators (``down``: rounded toward
    zero, for a "more than" that must stay true). [h]"""
    if hours <= 0:
        return "0"
    step = 10.0 ** (math.floor(math.log10(hours)) - 1)
    value = (math.floor(hours / step) if down else round(hours / step)) * step
    return f"{value:,.0f}" if value >= 10 else f"{value:.2g}"


def remaining_text(row: dict) -> str:
    """A ``valve_condition`` or ``fleet_ranking`` row's remaining life, e.g. ``now (faulty)``,
    ``1,200 h (95 %: 900–1,600 h)``, ``> 6,400 h (no wear toward a bound within the horizon)``."""
    basis = row.get("remaining_basis")
    if basis in ("faulty", "worn"):
        return f"now ({basis})"
    if basis == "forecast":
        point, low, high = (row["remaining_hours"], row["remaining_hours_low"], row.get("remaining_hours_high"))
        if high is None:  # the interval reaches beyond the horizon
            horizon = two_figures(row["remaining_horizon_hours"], down=True)
            return f"{two_figures(point)} h (95 %: {two_figures(low)} h to beyond the {horizon} h horizon)"
        return f"{two_figures(point)} h (95 %: {two_figures(low)}–{two_figures(high)} h)"
    if basis == "beyond_horizon":
        return f"> {two_figures(row['remaining_horizon_hours'], down=True)} h (no wear toward a bound within the horizon)"
    if basis == "no_trend":
        return "no significant wear trend"
    return "unknown (too little data)"

"""Field registry of the report's tables and the BI hand-off (the sibling of :mod:`schemas.fields`).

``condition_bounds`` and ``standstill_checks`` are tables `valvemon report` writes into the
warehouse database; ``valve_condition`` and ``fleet_ranking`` are views (``sql/report``) whose
columns are fixed here, so the exported Parquet files keep a stable, documented schema.
"""

from __future__ import annotations

import polars as pl

from schemas.fields import EDGES, UTC_US, Field

STATES: tuple[str, ...] = ("healthy", "worn", "faulty", "unknown")
"""The states of ``valve_condition`` (interfaces.md)."""

PARAMETERS: tuple[str, ...] = ("alpha_hat", "x_hat_pct", "e_mm2")
"""The three condition parameters of step 4b, as named in ``edge_fits``."""

CONDITION_BOUNDS_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier."),
    Field("valve_type", pl.Utf8, "", "Valve type of the plant configuration."),
    Field("x_max_mm", pl.Float64, "mm", "Spool stroke x_max (x_hat_pct is in % of it).", ge=0.0),
    Field("alpha_fault_low", pl.Float64, "", "alpha_hat below this in one window: faulty."),
    Field("alpha_fault_high", pl.Float64, "", "alpha_hat above this in one window: faulty."),
    Field("alpha_wear_low", pl.Float64, "", "Long-term level of alpha_hat below this: worn."),
    Field("alpha_wear_high", pl.Float64, "", "Long-term level of alpha_hat above this: worn."),
    Field("x_hat_pct_fault_low", pl.Float64, "%", "x_hat_pct below this in one window: faulty."),
    Field("x_hat_pct_fault_high", pl.Float64, "%", "x_hat_pct above this in one window: faulty."),
    Field("x_hat_pct_wear_low", pl.Float64, "%", "Long-term level of x_hat_pct below this: worn."),
    Field("x_hat_pct_wear_high", pl.Float64, "%", "Long-term level of x_hat_pct above this: worn."),
    Field("e_mm2_fault_high", pl.Float64, "mm²", "e_mm2 above this in one window: faulty."),
    Field("e_mm2_wear_high", pl.Float64, "mm²", "Long-term level of e_mm2 above this: worn."),
    Field("change_z", pl.Float64, "", "Robust z-score beyond which a window departs significantly from its recent trend."),
    Field("change_history_windows", pl.Int32, "", "Previous ok windows the rolling median and MAD are taken over; also the windows of the long-term level."),
    Field("change_min_history", pl.Int32, "", "Fewest previous ok windows for a z-score."),
    Field("alpha_sigma_floor", pl.Float64, "", "Smallest scale of the alpha_hat z-score."),
    Field("x_hat_pct_sigma_floor", pl.Float64, "%", "Smallest scale of the x_hat_pct z-score."),
    Field("e_mm2_sigma_floor", pl.Float64, "mm²", "Smallest scale of the e_mm2 z-score."),
    Field("fault_hold_hours", pl.Float64, "h", "An alarm keeps the edge faulty this long after its window."),
    Field("trend_min_fits", pl.Int32, "", "Fewest ok, alarm-free windows for a trend (else unknown)."),
    Field("trend_min_span_hours", pl.Float64, "h", "Shortest span of operating hours for a remaining-life forecast."),
    Field("trend_span_hours", pl.Float64, "h", "Trailing span of operating hours the trend is fitted on."),
    Field("eq9_expected", pl.Float64, "", "Eq. 9 residual the valve's design gives at rest."),
    Field("eq9_tolerance", pl.Float64, "", "Largest |residual - expected| of a sound valve."),
    Field("updated_at", UTC_US, "", "When the row was written from the plant configuration."),
)
"""Each configured valve's bounds (table ``condition_bounds``, replaced by every report)."""

STANDSTILL_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier."),
    Field("window_start", UTC_US, "", "First sample of the monitoring window (UTC)."),
    Field("window_end", UTC_US, "", "Last sample of the monitoring window (UTC)."),
    Field("operating_hours", pl.Float64, "h", "Calendar hours since commissioning at window_start."),
    Field("n_samples", pl.Int64, "", "Standstill samples of the window used (cylinder at rest, |x| small, settled).", ge=0),
    Field("ps_bar", pl.Float64, "bar", "Median supply pressure over those samples."),
    Field("pr_bar", pl.Float64, "bar", "Median return pressure."),
    Field("p1_bar", pl.Float64, "bar", "Median head-side pressure."),
    Field("p2_bar", pl.Float64, "bar", "Median rod-side pressure."),
    Field("x_spool_mm", pl.Float64, "mm", "Median spool position."),
    Field("eq9_residual", pl.Float64, "", "Median of (p1-pr)/(ps-p1) - (ps-p2)/(p2-pr) (Eq. 9; 0 for the idealised valve)."),
    Field("computed_at", UTC_US, "", "When this row was computed."),
)
"""Eq. 9 at standstill per window (table ``standstill_checks``, filled incrementally from the lake)."""

VALVE_CONDITION_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier."),
    Field("edge", pl.Utf8, "", "Control edge.", isin=EDGES),
    Field("state", pl.Utf8, "", "healthy, worn, faulty or unknown.", isin=STATES),
    Field("reason", pl.Utf8, "", "Why, in words, with the numbers."),
    Field("remaining_hours", pl.Float64, "h", "Operating hours until a parameter's trend reaches its wear bound (0 when worn).", nullable=True),
    Field("remaining_hours_low", pl.Float64, "h", "Lower end of its 95 % interval.", nullable=True),
    Field("remaining_hours_high", pl.Float64, "h", "Upper end of its 95 % interval.", nullable=True),
    Field("limiting_parameter", pl.Utf8, "", "The parameter whose trend reaches its bound first.", nullable=True),
    Field("end_of_life_hours", pl.Float64, "h", "Operating hours at which that happens.", nullable=True),
    Field("operating_hours", pl.Float64, "h", "Operating hours of the latest ok window.", nullable=True),
    Field("last_window_start", UTC_US, "", "Latest monitoring window of the edge (any status).", nullable=True),
    Field("last_ok_window_start", UTC_US, "", "Latest window with an estimate.", nullable=True),
    Field("alpha_hat", pl.Float64, "", "alpha_hat of the latest ok window.", nullable=True),
    Field("x_hat_pct", pl.Float64, "%", "x_hat_pct of the latest ok window.", nullable=True),
    Field("e_mm2", pl.Float64, "mm²", "e_mm2 of the latest ok window.", nullable=True),
    Field("alpha_level", pl.Float64, "", "Long-term level (median of the latest alarm-free windows) of alpha_hat.", nullable=True),
    Field("x_hat_pct_level", pl.Float64, "%", "Long-term level of x_hat_pct.", nullable=True),
    Field("e_mm2_level", pl.Float64, "mm²", "Long-term level of e_mm2.", nullable=True),
    Field("n_windows", pl.Int64, "", "Windows of the edge against its current baseline.", ge=0),
    Field("n_ok_windows", pl.Int64, "", "Of which gave an estimate.", ge=0),
    Field("n_recent_alarms", pl.Int64, "", "Alarm windows within fault_hold_hours of the latest ok window.", ge=0),
    Field("eq9_ok", pl.Boolean, "", "Latest Eq. 9 standstill check of the valve passed (null: no standstill data).", nullable=True),
    Field("edge_order", pl.Int32, "", "1..4 for s1, 1r, s2, 2r (for sorting)."),
)
"""View ``valve_condition`` (interfaces.md), as exported to ``export/valve_condition.parquet``."""

FLEET_RANKING_FIELDS: tuple[Field, ...] = (
    Field("urgency_rank", pl.Int64, "", "1 = look at this valve first.", ge=1),
    Field("valve_id", pl.Utf8, "", "Valve identifier."),
    Field("state", pl.Utf8, "", "Worst state of its edges (unknown only if all four are).", isin=STATES),
    Field("urgency_tier", pl.Int32, "", "1 faulty, 2 worn, 3 Eq. 9 fails, 4 healthy with forecast, 5 unknown, 6 healthy."),
    Field("edges_faulty", pl.Int64, "", "Faulty edges.", ge=0),
    Field("edges_worn", pl.Int64, "", "Worn edges.", ge=0),
    Field("edges_unknown", pl.Int64, "", "Edges without enough data.", ge=0),
    Field("worst_edge", pl.Utf8, "", "The edge that decides the state.", isin=EDGES),
    Field("reason", pl.Utf8, "", "Its reason."),
    Field("remaining_hours", pl.Float64, "h", "Soonest remaining life over the edges.", nullable=True),
    Field("remaining_hours_low", pl.Float64, "h", "Lower end of its 95 % interval.", nullable=True),
    Field("remaining_hours_high", pl.Float64, "h", "Upper end of its 95 % interval.", nullable=True),
    Field("limiting_edge", pl.Utf8, "", "The edge with the soonest remaining life.", nullable=True),
    Field("eq9_ok", pl.Boolean, "", "Latest Eq. 9 standstill check passed.", nullable=True),
    Field("eq9_residual", pl.Float64, "", "Its residual.", nullable=True),
    Field("operating_hours", pl.Float64, "h", "Operating hours of the latest ok window.", nullable=True),
    Field("last_window_start", UTC_US, "", "Latest monitoring window.", nullable=True),
)
"""View ``fleet_ranking``, as exported to ``export/fleet_ranking.parquet``."""

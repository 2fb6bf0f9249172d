"""Step 3: which samples may become opening-area points of which edge, and why the rest may not.

Rules, applied per sample and edge in this order (the paper's order, after the technical one):

| rule            | removes a sample of an edge when                                                       |
|-----------------|----------------------------------------------------------------------------------------|
| `no_derivative` | a Savitzky–Golay value is null (stencil at a window/run edge) or an input is missing |
| `standstill`    | abs(v_X) < standstill_velocity_m_s                                                          |
| `pressure_peak` | abs(dp1/dt) or abs(dp2/dt) > peak_dpdt_pa_s, or on the edge's port abs(V dp/dt / β) > compressibility_ratio_max · abs(A v_X) |
| `spool_range`   | s1, 2r: x < limit; 1r, s2: x > −limit, limit = largest opposite-side underlap + margin  |
| `small_dp`      | abs(Δp) across the edge < min_dp_pa                                                         |

A sample is selected for an edge when no rule removes it. :func:`selection_stats` reports, per
window, edge and rule, how many samples the rule flags on its own (``n_flagged``) and how many it
removes that no earlier rule already removed (``n_removed``; these add up to
``n_samples − n_selected``).
"""

from __future__ import annotations

import polars as pl

from transforms.params import EDGES, MonitorParams
from transforms.points import DEFAULT_SIGNALS, EDGE_PORT, EDGE_SIGN, Signals, edge_dp_expr

__all__ = [
    "RULES",
    "STATS_COLUMNS",
    "add_selection_flags",
    "rule_exprs",
    "selected_column",
    "selection_stats",
]

RULES: tuple[str, ...] = ("no_derivative", "standstill", "pressure_peak", "spool_range", "small_dp")

STATS_COLUMNS = (
    "valve_id",
    "window_id",
    "window_start",
    "window_end",
    "edge",
    "rule",
    "n_samples",
    "n_flagged",
    "n_removed",
    "n_selected",
)


def selected_column(edge: str) -> str:
    """Name of the boolean column that :func:`add_selection_flags` adds for ``edge``."""
    return f"selected_{edge}"


def _flag_name(rule: str, edge: str) -> str:
    return f"_flag_{rule}_{edge}"


def _removed_name(rule: str, edge: str) -> str:
    return f"_removed_{rule}_{edge}"


def rule_exprs(edge: str, params: MonitorParams, signals: Signals = DEFAULT_SIGNALS) -> dict[str, pl.Expr]:
    """Boolean expressions, one per rule of :data:`RULES`: True = the rule removes the sample.

    Rules after ``no_derivative`` are False where their inputs are null (that rule covers it).
    """
    if edge not in EDGES:
        raise ValueError(f"unknown edge {edge!r}")
    needed = (signals.ps, signals.pr, signals.p1, signals.p2, signals.x_spool, signals.x_cyl,
              signals.dp1_dt, signals.dp2_dt, signals.v_cyl)
    no_derivative = pl.any_horizontal(*(pl.col(c).is_null() for c in dict.fromkeys(needed)))

    v = pl.col(signals.v_cyl)
    beta = params.bulk_modulus_pa
    standstill = v.abs() < params.standstill_velocity_m_s

    dp1, dp2 = pl.col(signals.dp1_dt), pl.col(signals.dp2_dt)
    absolute_peak = (dp1.abs() > params.peak_dpdt_pa_s) | (dp2.abs() > params.peak_dpdt_pa_s)
    x_cyl = pl.col(signals.x_cyl)
    k = params.compressibility_ratio_max
    if EDGE_PORT[edge] == 1:
        v1 = params.v01_m3 + params.piston_area_m2 * x_cyl
        ratio_peak = (dp1 * v1).abs() > (k * beta * params.piston_area_m2) * v.abs()
    else:
        v2 = params.v02_m3 - params.annulus_area_m2 * x_cyl
        ratio_peak = (dp2 * v2).abs() > (k * beta * params.annulus_area_m2) * v.abs()
    pressure_peak = absolute_peak | ratio_peak

    limit = params.spool_limit_m(edge)
    x = pl.col(signals.x_spool)
    spool_range = (x < limit) if EDGE_SIGN[edge] > 0 else (x > -limit)

    small_dp = edge_dp_expr(edge, signals).abs() < params.min_dp_pa

    return {
        "no_derivative": no_derivative,
        "standstill": standstill.fill_null(False),
        "pressure_peak": pressure_peak.fill_null(False),
        "spool_range": spool_range.fill_null(False),
        "small_dp": small_dp.fill_null(False),
    }


def add_selection_flags(
    frame: pl.DataFrame | pl.LazyFrame,
    params: MonitorParams,
    *,
    signals: Signals = DEFAULT_SIGNALS,
    edges: tuple[str, ...] = EDGES,
) -> pl.DataFrame | pl.LazyFrame:
    """Add per edge a boolean ``selected_<edge>`` and the internal per-rule flag columns
    (``_flag_<rule>_<edge>``, ``_removed_<rule>_<edge>``) that :func:`selection_stats` sums."""
    exprs: list[pl.Expr] = []
    for edge in edges:
        prior: pl.Expr | None = None
        for rule, flag in rule_exprs(edge, params, signals).items():
            exprs.append(flag.alias(_flag_name(rule, edge)))
            removed = flag if prior is None else flag & ~prior
            exprs.append(removed.alias(_removed_name(rule, edge)))
            prior = flag if prior is None else prior | flag
        assert prior is not None
        exprs.append((~prior).alias(selected_column(edge)))
    return frame.with_columns(exprs)


def selection_stats(flagged: pl.DataFrame | pl.LazyFrame, *, edges: tuple[str, ...] = EDGES) -> pl.DataFrame:
    """Tidy counts per window, edge and rule (:data:`STATS_COLUMNS`) from
    :func:`add_selection_flags`' output (which must also carry the window columns)."""
    if not edges:
        raise ValueError("no edges")
    lf = flagged.lazy() if isinstance(flagged, pl.DataFrame) else flagged
    aggs: list[pl.Expr] = [
        pl.col("valve_id").first(),
        pl.col("window_start").first(),
        pl.col("window_end").first(),
        pl.len().cast(pl.Int64).alias("n_samples"),
    ]
    for edge in edges:
        aggs.append(pl.col(selected_column(edge)).sum().cast(pl.Int64).alias(f"sel|{edge}"))
        for rule in RULES:
            aggs.append(pl.col(_flag_name(rule, edge)).sum().cast(pl.Int64).alias(f"fl|{rule}|{edge}"))
            aggs.append(pl.col(_removed_name(rule, edge)).sum().cast(pl.Int64).alias(f"rm|{rule}|{edge}"))
    wide = lf.group_by("window_id", maintain_order=True).agg(aggs).collect()
    parts = []
    for edge in edges:
        for rule in RULES:
            parts.append(
                wide.select(
                    "valve_id",
                    "window_id",
                    "window_start",
                    "window_end",
                    pl.lit(edge, dtype=pl.Utf8).alias("edge"),
                    pl.lit(rule, dtype=pl.Utf8).alias("rule"),
                    "n_samples",
                    pl.col(f"fl|{rule}|{edge}").alias("n_flagged"),
                    pl.col(f"rm|{rule}|{edge}").alias("n_removed"),
                    pl.col(f"sel|{edge}").alias("n_selected"),
                )
            )
    out = pl.concat(parts, how="vertical")
    edge_rank = {e: i for i, e in enumerate(EDGES)}
    rule_rank = {r: i for i, r in enumerate(RULES)}
    return out.sort(
        pl.col("valve_id"),
        pl.col("window_start"),
        pl.col("edge").replace_strict(edge_rank, return_dtype=pl.Int8),
        pl.col("rule").replace_strict(rule_rank, return_dtype=pl.Int8),
        maintain_order=True,
    )

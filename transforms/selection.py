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

The rules exist twice: as polars expressions (:func:`rule_exprs`, :func:`add_selection_flags`,
:func:`selection_stats`: the readable reference, usable on any frame) and as one compiled pass
over numpy arrays (:func:`selection_codes`, :func:`stats_frame`: what the monitor runs, about
40 boolean columns fewer per row). The tests hold the two to identical counts.
"""

from __future__ import annotations

import numba
import numpy as np
import polars as pl

from transforms.arrays import float_array
from transforms.params import EDGES, MonitorParams
from transforms.points import DEFAULT_SIGNALS, EDGE_PORT, EDGE_SIGN, Signals, edge_dp_expr

__all__ = [
    "RULES",
    "STATS_COLUMNS",
    "add_selection_flags",
    "rule_exprs",
    "SELECTED_CODE",
    "selected_column",
    "selection_codes",
    "selection_stats",
    "stats_frame",
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


# --------------------------------------------------------------------------------------------
# compiled path (same rules, one pass; used by transforms.monitor for throughput)
# --------------------------------------------------------------------------------------------

SELECTED_CODE = len(RULES)
"""Code of a selected sample in :func:`selection_codes` (rules are coded 0 … len(RULES) − 1)."""


def _constants(params: MonitorParams) -> np.ndarray:
    return np.array(
        [
            params.standstill_velocity_m_s,
            params.peak_dpdt_pa_s,
            params.compressibility_ratio_max,
            params.bulk_modulus_pa,
            params.piston_area_m2,
            params.annulus_area_m2,
            params.v01_m3,
            params.v02_m3,
            params.spool_limit_m("s1"),
            params.spool_limit_m("1r"),
            params.min_dp_pa,
        ],
        dtype=np.float64,
    )


@numba.njit(cache=True)
def _selection_kernel(win, n_windows, valid, ps, pr, p1, p2, x, xc, dp1, dp2, v, c):
    """One pass over the rows. Rules shared by edges (no_derivative, standstill, the pressure
    peaks of a port, the spool range of a side) are counted once per row, in per-window
    counters that are added to the tables whenever the window changes."""
    vmin, pmax, kr, beta, a1, a2, v01, v02, lim_pos, lim_neg, min_dp = (
        c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10])
    n = x.shape[0]
    codes = np.empty((n, 4), dtype=np.uint8)
    flagged = np.zeros((n_windows, 4, 5), dtype=np.int64)
    removed = np.zeros((n_windows, 4, 5), dtype=np.int64)
    selected = np.zeros((n_windows, 4), dtype=np.int64)
    n_samples = np.zeros(n_windows, dtype=np.int64)
    # per window: [no_derivative, standstill, peak port 1, peak port 2, spool x < limit,
    # spool x > −limit, small_dp s1, 1r, s2, 2r, rows]; per edge and code
    shared = np.zeros(11, dtype=np.int64)
    by_code = np.zeros((4, 6), dtype=np.int64)
    if n == 0:
        return codes, flagged, removed, selected, n_samples
    w = win[0]
    for i in range(n + 1):
        if i == n or win[i] != w:
            n_samples[w] += shared[10]
            for e in range(4):
                port = 2 if e < 2 else 3
                side = 4 if e == 0 or e == 3 else 5
                flagged[w, e, 0] += shared[0]
                flagged[w, e, 1] += shared[1]
                flagged[w, e, 2] += shared[port]
                flagged[w, e, 3] += shared[side]
                flagged[w, e, 4] += shared[6 + e]
                for k in range(5):
                    removed[w, e, k] += by_code[e, k]
                selected[w, e] += by_code[e, 5]
            shared[:] = 0
            by_code[:, :] = 0
            if i == n:
                break
            w = win[i]
        # the Savitzky–Golay values of an invalid stencil count as missing (like nulls)
        if valid[i]:
            p1i, p2i, dp1i, dp2i, vi = p1[i], p2[i], dp1[i], dp2[i], v[i]
        else:
            p1i = p2i = dp1i = dp2i = vi = np.nan
        xi, xci, psi, pri = x[i], xc[i], ps[i], pr[i]
        nd = (np.isnan(psi) or np.isnan(pri) or np.isnan(p1i) or np.isnan(p2i) or np.isnan(xi)
              or np.isnan(xci) or np.isnan(dp1i) or np.isnan(dp2i) or np.isnan(vi))
        av = abs(vi)
        ss = av < vmin
        absp = abs(dp1i) > pmax or abs(dp2i) > pmax
        pk1 = absp or abs(dp1i * (v01 + a1 * xci)) > (kr * beta * a1) * av
        pk2 = absp or abs(dp2i * (v02 - a2 * xci)) > (kr * beta * a2) * av
        sp_pos = xi < lim_pos
        sp_neg = xi > -lim_neg
        sd0 = abs(psi - p1i) < min_dp
        sd1 = abs(pri - p1i) < min_dp
        sd2 = abs(p2i - psi) < min_dp
        sd3 = abs(p2i - pri) < min_dp
        shared[0] += nd
        shared[1] += ss
        shared[2] += pk1
        shared[3] += pk2
        shared[4] += sp_pos
        shared[5] += sp_neg
        shared[6] += sd0
        shared[7] += sd1
        shared[8] += sd2
        shared[9] += sd3
        shared[10] += 1
        # the first rule that removes the sample (5: selected)
        if nd:
            c0 = c1 = c2 = c3 = 0
        elif ss:
            c0 = c1 = c2 = c3 = 1
        else:
            c0 = 2 if pk1 else (3 if sp_pos else (4 if sd0 else 5))
            c1 = 2 if pk1 else (3 if sp_neg else (4 if sd1 else 5))
            c2 = 2 if pk2 else (3 if sp_neg else (4 if sd2 else 5))
            c3 = 2 if pk2 else (3 if sp_pos else (4 if sd3 else 5))
        by_code[0, c0] += 1
        by_code[1, c1] += 1
        by_code[2, c2] += 1
        by_code[3, c3] += 1
        codes[i, 0] = c0
        codes[i, 1] = c1
        codes[i, 2] = c2
        codes[i, 3] = c3
    return codes, flagged, removed, selected, n_samples


def selection_codes(
    arrays: dict[str, np.ndarray],
    window_id: np.ndarray,
    n_windows: int,
    params: MonitorParams,
    *,
    valid: np.ndarray | None = None,
):
    """The rules of :func:`rule_exprs` in one compiled pass over numpy arrays.

    ``arrays`` holds float64 arrays (NaN = missing) under the :class:`Signals` default names
    (``ps_pa``, ``pr_pa``, ``p1_smooth_pa``, ``p2_smooth_pa``, ``x_spool_m``, ``x_cyl_m``,
    ``dp1_dt_pa_s``, ``dp2_dt_pa_s``, ``v_cyl_m_s``); ``window_id`` in 0 … n_windows − 1.
    ``valid`` (bool, optional): False where the Savitzky–Golay values do not count (counted as
    ``no_derivative``, like a null).

    Returns ``codes`` (uint8, shape (n, 4): the first rule that removes the sample for each edge
    in :data:`EDGES` order, :data:`SELECTED_CODE` if none) and per window the counts
    ``flagged`` and ``removed`` (n_windows, 4, len(RULES)), ``selected`` (n_windows, 4),
    ``n_samples`` (n_windows,).
    """
    s = DEFAULT_SIGNALS
    n = np.asarray(window_id).shape[0]
    valid = np.ones(n, dtype=np.bool_) if valid is None else np.ascontiguousarray(valid, dtype=np.bool_)
    return _selection_kernel(
        np.ascontiguousarray(window_id, dtype=np.int64), int(n_windows), valid,
        *(float_array(arrays[k]) for k in (
            s.ps, s.pr, s.p1, s.p2, s.x_spool, s.x_cyl, s.dp1_dt, s.dp2_dt, s.v_cyl)),
        _constants(params),
    )


def stats_frame(
    valve_id: str,
    windows: pl.DataFrame,
    flagged: np.ndarray,
    removed: np.ndarray,
    selected: np.ndarray,
) -> pl.DataFrame:
    """Tidy :data:`STATS_COLUMNS` frame from the counts of :func:`selection_codes`;
    ``windows`` (``window_id, window_start, window_end, n_samples``) in window-id order."""
    n_w, n_e, n_r = flagged.shape
    rep = n_e * n_r
    wi = np.repeat(np.arange(n_w), rep)
    return pl.DataFrame(
        {
            "valve_id": pl.repeat(valve_id, n_w * rep, eager=True, dtype=pl.Utf8),
            "window_id": windows["window_id"].gather(wi),
            "window_start": windows["window_start"].gather(wi),
            "window_end": windows["window_end"].gather(wi),
            "edge": pl.Series(np.tile(np.repeat(np.array(EDGES, dtype=object), n_r), n_w), dtype=pl.Utf8),
            "rule": pl.Series(np.tile(np.array(RULES, dtype=object), n_w * n_e), dtype=pl.Utf8),
            "n_samples": windows["n_samples"].cast(pl.Int64).gather(wi),
            "n_flagged": flagged.reshape(-1),
            "n_removed": removed.reshape(-1),
            "n_selected": np.repeat(selected.reshape(-1), n_r),
        }
    )

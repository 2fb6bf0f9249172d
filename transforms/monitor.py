"""Steps 2–4b composed: lake rows → opening-area points, selection statistics, fits.

Pure: frames and parameters in, frames out. Per valve (a Python loop over valves only):

1. windows and Savitzky–Golay values as one lazy polars query (:mod:`transforms.windows`,
   :mod:`transforms.derivatives`);
2. step 3 and Eq. 7 either as polars expressions (``engine="polars"``: :mod:`transforms.selection`
   and :mod:`transforms.points` expressions, the reference) or as two compiled passes over the
   columns (``engine="numba"``, the default: the same rules and formulas, without the ~45
   intermediate boolean columns per row; the tests hold both engines to the same points and
   counts).

Then the points of all valves are fitted in one compiled batch (:func:`transforms.fit.fit_groups`),
optionally with the closed-edge leakage correction that follows each window's own estimates
(:func:`monitor`'s ``leakage``). :func:`commissioning_baseline` is steps 2–4a and 5a on a
commissioning window. docs/monitoring.md describes the whole.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numba
import numpy as np
import polars as pl

from transforms.baseline import (
    EDGE_LAWS,
    Plausibility,
    carrier_fit,
    choose_knots,
    fit_characteristic,
    leak_scale_lstsq,
    plausibility,
    recognise_edge_law,
)
from transforms.characteristic import Characteristic, scaled_shifted
from transforms.arrays import read_only
from transforms.derivatives import add_savgol, box_mean_at, box_mean_expr, savgol_arrays, savgol_at, savgol_exprs
from transforms.fit import fit_arrays, fit_groups, sorted_fits, walk_segment
from transforms.leakage import LEAK_RESOLUTION, closed_leakage, effective_scale, inflation, leak_columns, leak_scale_step
from transforms.params import EDGES, MonitorParams
from transforms.points import (
    DEFAULT_SIGNALS,
    OPPOSITE_EDGE,
    POINT_COLUMNS,
    opening_area_points,
    points_arrays,
)
from transforms.selection import (
    SELECTED_CODE,
    add_selection_flags,
    selected_column,
    selection_codes,
    selection_stats,
    stats_frame,
)
from transforms.windows import UnsortedTimes, WindowLayout, assign_windows, infer_sample_period_s, window_layout, window_table

__all__ = [
    "LAKE_COLUMNS",
    "BaselineFit",
    "MonitorResult",
    "commissioning_baseline",
    "monitor",
    "monitor_points",
    "prepare_samples",
]

LAKE_COLUMNS = ("valve_id", "timestamp_utc", "ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")
"""Lake columns the algorithm reads (others are ignored)."""

# smoothed p1, p2 for the pressure differences; X only differentiated (its noise is irrelevant in V)
_SG_OUTPUTS = {
    "p1_pa": ("p1_smooth_pa", "dp1_dt_pa_s"),
    "p2_pa": ("p2_smooth_pa", "dp2_dt_pa_s"),
    "x_cyl_m": (None, "v_cyl_m_s"),
}
_SIGNAL_COLUMNS = tuple(
    dict.fromkeys(
        (DEFAULT_SIGNALS.ps, DEFAULT_SIGNALS.pr, DEFAULT_SIGNALS.p1, DEFAULT_SIGNALS.p2, DEFAULT_SIGNALS.x_spool,
         DEFAULT_SIGNALS.x_cyl, DEFAULT_SIGNALS.dp1_dt, DEFAULT_SIGNALS.dp2_dt, DEFAULT_SIGNALS.v_cyl)
    )
)
_UTC_US = pl.Datetime("us", "UTC")


@dataclass(frozen=True)
class MonitorResult:
    points: pl.DataFrame
    """valve_id, window_id, window_start, timestamp_utc, edge, u_m, area_m2 (selected points);
    per valve grouped by edge (EDGES order), in time order within an edge."""
    selection: pl.DataFrame
    """Tidy step-3 counts per window, edge and rule (:data:`transforms.selection.STATS_COLUMNS`)."""
    fits: pl.DataFrame
    """One row per window and edge (:data:`transforms.fit.FIT_COLUMNS`); empty from :func:`monitor_points`."""
    windows: pl.DataFrame
    """valve_id, window_id, window_start, window_end, n_samples."""


def _params_for(params: Mapping[str, MonitorParams] | MonitorParams, valve_id: str) -> MonitorParams:
    if isinstance(params, MonitorParams):
        return params
    try:
        return params[valve_id]
    except KeyError:
        raise KeyError(f"no MonitorParams for valve {valve_id!r}") from None


def _framed(lake_one_valve: pl.DataFrame, params: MonitorParams, sample_period_s: float | None) -> pl.LazyFrame:
    dt = sample_period_s or params.sample_period_s or infer_sample_period_s(lake_one_valve)
    lf = lake_one_valve.lazy().select(LAKE_COLUMNS)
    lf = assign_windows(
        lf,
        sample_period_s=dt,
        gap_limit_s=params.gap_limit_periods * dt,
        step_tolerance=params.step_tolerance,
        window_s=params.window_s,
    )
    return add_savgol(lf, window=params.savgol_window, order=params.savgol_order, sample_period_s=dt, outputs=_SG_OUTPUTS)


def prepare_samples(
    lake_one_valve: pl.DataFrame, params: MonitorParams, *, sample_period_s: float | None = None
) -> pl.DataFrame:
    """One valve's rows (sorted by time) with window columns, Savitzky–Golay values and the step-3
    flags (``selected_<edge>`` and the internal ``_flag_*``/``_removed_*`` columns), as polars
    expressions.

    The sample period is ``sample_period_s``, else ``params.sample_period_s``, else the median
    time step of the rows."""
    return add_selection_flags(_framed(lake_one_valve, params, sample_period_s), params, signals=DEFAULT_SIGNALS).collect()


def _valve_slices(lake: pl.DataFrame) -> tuple[pl.DataFrame, list[tuple[str, int, int]]]:
    """Each valve's rows as one contiguous slice: (frame, [(valve_id, offset, length)]).

    Rows are regrouped (sorted by valve and time) only if a valve's rows are not contiguous;
    time order within a slice is checked per valve (:func:`_time_sorted`)."""
    rle = lake.select(pl.col("valve_id").rle()).unnest("valve_id")
    if rle["value"].is_duplicated().any():
        lake = lake.sort("valve_id", "timestamp_utc", maintain_order=True)
        rle = lake.select(pl.col("valve_id").rle()).unnest("valve_id")
    out, off = [], 0
    for length, value in zip(rle["len"].to_list(), rle["value"].to_list(), strict=True):
        out.append((value, off, length))
        off += length
    return lake, out


def _time_sorted(lake_v: pl.DataFrame) -> pl.DataFrame:
    ts = lake_v["timestamp_utc"].to_physical().to_numpy()
    if ts.shape[0] > 1 and bool(np.any(ts[1:] < ts[:-1])):
        return lake_v.sort("timestamp_utc", maintain_order=True)
    return lake_v


@dataclass
class _ValvePoints:
    """One valve's steps 2–3 and Eq. 7: the point arrays in fit layout, the frames around them."""

    u: np.ndarray
    area: np.ndarray
    ratio: np.ndarray | None
    """:func:`transforms.points.leak_ratio_expr` per point (when asked for)."""
    points: pl.DataFrame | None
    """:data:`POINT_COLUMNS` (when asked for; the arrays above are its ``u_m``, ``area_m2``)."""
    stats: pl.DataFrame
    windows: pl.DataFrame
    groups: pl.DataFrame
    """valve_id, window_id, window_start, window_end, edge: the populations, edge-major, windows in
    time order; population g owns ``sizes[g]`` consecutive points."""
    sizes: np.ndarray
    strides: np.ndarray
    """Each population's stride k: its points are every k-th row's (:data:`THIN_MARGIN`)."""


def _groups(windows: pl.DataFrame) -> pl.DataFrame:
    return pl.concat(
        [windows.select("valve_id", "window_id", "window_start", "window_end", pl.lit(edge).alias("edge")) for edge in EDGES]
    )


def _valve_polars(lake_v, valve_id, p, leakage, with_ratio, want_points):
    framed = prepare_samples(_time_sorted(lake_v), p)
    windows = window_table(framed)
    groups = _groups(windows)
    strides = pl.Series(np.ones(groups.height, dtype=np.int64))
    evaluated = framed
    if p.window_rows is not None:  # every k-th row of a long window (MonitorParams.window_rows, THIN_MARGIN)
        stride = windows.select("window_id", (pl.col("n_samples") // p.window_rows).clip(lower_bound=1).alias("_k"))
        for dense in (None, True):
            if dense is not None:  # the windows short of information: every row
                thin = _polars_points(evaluated, p, leakage, valve_id, False)
                sel = _sizes(groups, thin).reshape(len(EDGES), -1).T
                dense = thinning_short(stride["_k"].to_numpy(), sel, thin["u_m"].to_numpy(), p)
                stride = stride.with_columns(pl.when(pl.Series(dense)).then(1).otherwise(pl.col("_k")).alias("_k"))
            evaluated = _thinned(framed, stride, p)
        strides = groups.join(stride, on="window_id", how="left", maintain_order="left")["_k"]
    points = _polars_points(evaluated, p, leakage, valve_id, with_ratio)
    ratio = None
    if with_ratio:
        ratio = points["leak_ratio"].to_numpy()
        points = points.drop("leak_ratio")
    # the populations in the order of `points` (edge-major, windows in time order), as the
    # compiled path lays them out
    return _ValvePoints(
        points["u_m"].to_numpy(), points["area_m2"].to_numpy(), ratio, points.select(POINT_COLUMNS),
        selection_stats(evaluated), windows, groups, _sizes(groups, points), strides.to_numpy().astype(np.int64),
    )  # fmt: skip


def _thinned(framed: pl.DataFrame, stride: pl.DataFrame, p: MonitorParams) -> pl.DataFrame:
    """The rows of :func:`prepare_samples` that a window of stride k (``stride``: window_id, _k)
    is evaluated on, every k-th from its first, each the mean of the k rows it stands for (as
    :func:`_averaged`): its signals averaged, step 3 applied to them."""
    dt = p.sample_period_s or infer_sample_period_s(framed)
    lf = framed.lazy().join(stride.lazy(), on="window_id", how="left", maintain_order="left")
    signals: dict[str, pl.Expr] = {}
    for box in sorted(set(stride["_k"].to_list()) - {1}):
        exprs = [box_mean_expr(c, box).alias(c) for c in _GATHERED]
        for column, (smooth_name, deriv_name) in _SG_OUTPUTS.items():
            exprs += savgol_exprs(column, window=p.savgol_window, order=p.savgol_order, sample_period_s=dt,
                                  smooth_name=smooth_name, deriv_name=deriv_name, box=box)  # fmt: skip
        for e in exprs:
            name = e.meta.output_name()
            signals[name] = pl.when(pl.col("_k") == box).then(e).otherwise(signals.get(name, pl.col(name))).alias(name)
    if signals:
        lf = add_selection_flags(lf.with_columns(list(signals.values())), p, signals=DEFAULT_SIGNALS)
    return lf.filter(pl.int_range(pl.len()).over("window_id") % pl.col("_k") == 0).drop("_k").collect()


def _sizes(groups: pl.DataFrame, points: pl.DataFrame) -> np.ndarray:
    """Points per population of ``groups`` (edge-major, windows in time order)."""
    counts = points.group_by("edge", "window_id").len()
    return groups.join(counts, on=["edge", "window_id"], how="left", maintain_order="left")["len"].fill_null(0).to_numpy().astype(np.int64)


def _polars_points(framed, p, leakage, valve_id, with_ratio):
    return opening_area_points(
        framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES},
        leakage=None if leakage is None else leakage.get(valve_id), with_ratio=with_ratio,
    )  # fmt: skip


_SIGNALS_F64 = ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")
_GATHERED = ("ps_pa", "pr_pa", "x_spool_m", "x_cyl_m")
"""The raw signals steps 3 and Eq. 7 read at the evaluated rows (p1, p2 enter smoothed)."""


def _float_series(col: pl.Series) -> pl.Series:
    """A signal as a float series, nulls as NaN: a float32 lake column stays float32 (no copy;
    the kernels compute in float64), anything else becomes float64."""
    if col.null_count():
        col = col.cast(pl.Float64).fill_null(float("nan"))
    if col.dtype not in (pl.Float32, pl.Float64):
        col = col.cast(pl.Float64)
    return col


def _float_chunks(col: pl.Series) -> list[np.ndarray]:
    """:func:`_float_series` as its chunks, each a view."""
    return [c.to_numpy() for c in _float_series(col).get_chunks()]


def _float64(col: pl.Series) -> np.ndarray:
    """:func:`_float_series` as one array: the chunks joined in one copy (polars' own rechunk is
    ~2x slower), a single chunk as a view."""
    chunks = _float_chunks(col)
    return chunks[0] if len(chunks) == 1 else np.concatenate(chunks)


def _layout(lake_v: pl.DataFrame, p: MonitorParams, dense: np.ndarray | None = None) -> tuple[pl.DataFrame, float, np.ndarray, WindowLayout]:
    """The valve's rows (sorted by time if they were not), sample period, time stamps (µs) and
    :func:`transforms.windows.window_layout` (which checks the order in its pass; ``dense``: the
    windows evaluated at every row)."""
    dt = p.sample_period_s or infer_sample_period_s(lake_v)
    for _ in range(2):
        ts = read_only(lake_v["timestamp_utc"].cast(_UTC_US).to_physical().to_numpy())  # (a view, or a copy of several chunks)
        try:
            lay = window_layout(ts, sample_period_s=dt, gap_limit_s=p.gap_limit_periods * dt, step_tolerance=p.step_tolerance,
                                half_window=p.half_window, window_s=p.window_s, window_rows=p.window_rows, dense=dense)  # fmt: skip
            return lake_v, dt, ts, lay
        except UnsortedTimes:
            lake_v = lake_v.sort("timestamp_utc", maintain_order=True)
    raise AssertionError("unreachable: sorted rows")


def _evaluate(lake_v, dt, lay, p, leakage, with_ratio):
    """Steps 2–3 and Eq. 7 at the rows of ``lay``: the signals as float arrays (float32 from the
    lake as it is; nulls become NaN), then Savitzky–Golay as plain weighted sums in one compiled
    pass per signal (the validity comes from the layout and is applied in the selection kernel).
    A thinned window (stride k > 1) is evaluated on every k-th row, each the mean of the k rows
    it stands for (:func:`_averaged`). Returns (rows or None, win, selection
    counts, points arrays)."""
    rows = None if lay.every_row else lay.rows
    if rows is None:
        arrays = {c: _float64(lake_v[c]) for c in _SIGNALS_F64}
        for column, (smooth_name, deriv_name) in _SG_OUTPUTS.items():
            sm, de = savgol_arrays(arrays[column], window=p.savgol_window, order=p.savgol_order, sample_period_s=dt, smooth=smooth_name is not None)
            arrays.update(_named(smooth_name, sm, deriv_name, de))
    else:  # the columns' chunks as they are (not joined): read at the rows only
        arrays = _averaged({c: _float_chunks(lake_v[c]) for c in _SIGNALS_F64}, rows, lay.window, lay.stride, p, dt)
    win = lay.window
    codes, flagged, removed, selected, n_evaluated = selection_codes(arrays, win, lay.n_windows, p, valid=lay.valid)
    pts = points_arrays(arrays, codes, SELECTED_CODE, selected.sum(axis=0), p, leakage=leakage, with_ratio=with_ratio)
    return rows, (flagged, removed, selected, n_evaluated), pts


def _named(smooth_name, sm, deriv_name, de) -> dict[str, np.ndarray]:
    return {deriv_name: de} if smooth_name is None else {smooth_name: sm, deriv_name: de}


def _averaged(chunks: dict[str, list[np.ndarray]], rows: np.ndarray, window: np.ndarray, stride: np.ndarray, p: MonitorParams,
              dt: float) -> dict[str, np.ndarray]:  # fmt: skip
    """The signals of steps 2–3 at the evaluated ``rows`` (of the windows ``window``), each row's the
    mean of the k rows it stands for (k: its window's ``stride``): the Savitzky–Golay values
    on their stencil convolved with a k-row box, the raw signals read there averaged alike
    (:func:`transforms.derivatives.savgol_at`'s ``box``). Every row's values carry independent
    position noise (a cylinder transmitter's steps): their mean keeps the information of the k
    rows that a single row would drop. Rows of the same stride are summed together."""
    out: dict[str, np.ndarray] = {}
    boxes = np.unique(stride)
    for box in boxes:
        at = None if boxes.shape[0] == 1 else np.flatnonzero((stride == box)[window])  # None: all rows
        r = rows if at is None else rows[at]
        parts = {c: box_mean_at(chunks[c], r, int(box)) for c in _GATHERED}
        for column, (smooth_name, deriv_name) in _SG_OUTPUTS.items():
            sm, de = savgol_at(chunks[column], r, window=p.savgol_window, order=p.savgol_order, sample_period_s=dt,
                               smooth=smooth_name is not None, box=int(box))  # fmt: skip
            parts.update(_named(smooth_name, sm, deriv_name, de))
        for name, v in parts.items():
            if at is None:
                out[name] = v
            else:
                out.setdefault(name, np.empty(rows.shape[0]))[at] = v
    return out


def _valve_numba(lake_v, valve_id, p, leakage, with_ratio, want_points):
    lake_v, dt, ts, lay = _layout(lake_v, p)
    leak = None if leakage is None else leakage.get(valve_id)
    rows, counts, pts = _evaluate(lake_v, dt, lay, p, leak, with_ratio)
    if not lay.every_row:  # a thinned window short of information is evaluated again at every row
        dense = thinning_short(lay.stride, counts[2], pts[4], p)
        if dense.any():
            lake_v, dt, ts, lay = _layout(lake_v, p, dense)
            rows, counts, pts = _evaluate(lake_v, dt, lay, p, leak, with_ratio)
    flagged, removed, selected, n_evaluated = counts
    idx, area, offs, ratio, u = pts
    n_windows, first, win = lay.n_windows, lay.first, lay.window
    last = first + lay.count - 1
    windows = pl.DataFrame(
        {
            "valve_id": pl.repeat(valve_id, n_windows, eager=True, dtype=pl.Utf8),
            "window_id": pl.Series(np.arange(n_windows), dtype=pl.UInt32),
            "window_start": pl.Series(ts[first]).cast(_UTC_US),
            "window_end": pl.Series(ts[last]).cast(_UTC_US),
            "n_samples": pl.Series(lay.count, dtype=pl.Int64),
        }
    )
    # the counts are those of the evaluated rows (n_samples too, so removed + selected = n_samples)
    stats = stats_frame(valve_id, windows if rows is None else windows.with_columns(n_samples=n_evaluated), flagged, removed, selected)
    points = None
    if want_points:
        pw = win[idx]  # windows of the points
        if rows is not None:
            idx = rows[idx]  # lake rows of the points
        points = pl.DataFrame(
            {
                "valve_id": pl.repeat(valve_id, idx.shape[0], eager=True, dtype=pl.Utf8),
                "window_id": pl.Series(pw, dtype=pl.UInt32),
                "window_start": pl.Series(ts[first][pw]).cast(_UTC_US),
                "timestamp_utc": pl.Series(ts[idx]).cast(_UTC_US),
                "edge": pl.concat(
                    [pl.repeat(edge, int(offs[e + 1] - offs[e]), eager=True, dtype=pl.Utf8) for e, edge in enumerate(EDGES)]
                ),
                "u_m": u,
                "area_m2": area,
            }
        )
    # the fit populations in the order of the points: edge-major, windows in time order
    return _ValvePoints(u, area, ratio if with_ratio else None, points, stats, windows, _groups(windows),
                        selected.T.reshape(-1).astype(np.int64), np.tile(lay.stride, len(EDGES)))  # fmt: skip


THIN_MARGIN = 2.0
"""A window is evaluated on every k-th row (``MonitorParams.window_rows``) only where that leaves
each of its populations clear of every threshold of the fit by this factor: at least
``THIN_MARGIN`` × ``min_points`` samples (k samples per evaluated point) and ``THIN_MARGIN`` ×
``min_coverage_m`` of u. Elsewhere — a window of sparse motion, an edge barely used — every row
is evaluated, so that a window's verdict is the one it has at every row. The thresholds count
samples at the sample rate, i.e. information: a thinned point is the mean of the k rows it
stands for (:func:`_averaged`), so it carries what they do; k · points is the population's size
in samples. Thinning moves that count by up to k per
run of selected rows, and the span of u by what the spool travels in k samples at its ends; a
factor of 2 leaves both far inside the margin."""


def thinning_short(stride: np.ndarray, selected: np.ndarray, u: np.ndarray, p: MonitorParams) -> np.ndarray:
    """Per window, whether its thinned populations fall short of :data:`THIN_MARGIN` × a threshold
    (and so it must be evaluated at every row): ``stride`` per window, ``selected`` (n_windows, 4)
    points per window and edge, ``u`` the points' opening coordinates, edge-major, windows in time
    order within an edge (as :func:`transforms.points.points_arrays` lays them out)."""
    sizes = selected.T.reshape(-1)
    span = _spans(u, sizes).reshape(len(EDGES), -1).T
    k = stride[:, None]
    short = (selected > 0) & ((k * selected < THIN_MARGIN * p.min_points) | (span < THIN_MARGIN * p.min_coverage_m))
    return (stride > 1) & short.any(axis=1)


def _spans(u: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """max − min of u over each run of ``sizes`` consecutive points (NaN for an empty run)."""
    out = np.full(sizes.shape[0], np.nan)
    some = sizes > 0
    if some.any():
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])[some]
        out[some] = np.maximum.reduceat(u, starts) - np.minimum.reduceat(u, starts)
    return out


@dataclass
class _Points:
    """All valves' :class:`_ValvePoints` concatenated, with the fit layout."""

    result: MonitorResult
    u: np.ndarray
    area: np.ndarray
    ratio: np.ndarray | None
    groups: pl.DataFrame
    offsets: np.ndarray
    strides: np.ndarray
    """Each population's stride (:data:`THIN_MARGIN`)."""


def _monitor_points(lake, params, leakage, engine, with_ratio=False, want_points=True) -> _Points:
    if engine not in ("numba", "polars"):
        raise ValueError(f"engine must be 'numba' or 'polars', got {engine!r}")
    missing = [c for c in LAKE_COLUMNS if c not in lake.columns]
    if missing:
        raise ValueError(f"lake frame lacks columns {missing}")
    lake, slices = _valve_slices(lake)
    run = _valve_numba if engine == "numba" else _valve_polars
    parts = [run(lake.slice(off, length), vid, _params_for(params, vid), leakage, with_ratio, want_points) for vid, off, length in slices]
    if not parts:  # no rows: empty frames with the right schemas
        p = params if isinstance(params, MonitorParams) else next(iter(params.values()), None)
        if p is None:
            raise ValueError("empty lake frame and no MonitorParams")
        framed = prepare_samples(lake.head(0), p, sample_period_s=p.sample_period_s or 1e-3)
        empty = opening_area_points(framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES}).select(POINT_COLUMNS)
        windows = window_table(framed)
        parts = [_ValvePoints(np.zeros(0), np.zeros(0), np.zeros(0) if with_ratio else None, empty, selection_stats(framed),
                              windows, _groups(windows), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))]  # fmt: skip
    if want_points:
        points = pl.concat([q.points for q in parts], how="vertical")
    else:
        points = pl.DataFrame(schema={"valve_id": pl.Utf8, "window_id": pl.UInt32, "window_start": _UTC_US,
                                      "timestamp_utc": _UTC_US, "edge": pl.Utf8, "u_m": pl.Float64, "area_m2": pl.Float64})  # fmt: skip
    res = MonitorResult(
        points=points,
        selection=pl.concat([q.stats for q in parts], how="vertical"),
        fits=pl.DataFrame(),
        windows=pl.concat([q.windows for q in parts], how="vertical"),
    )
    sizes = np.concatenate([q.sizes for q in parts]).astype(np.int64)

    def joined(arrays):  # one valve (what the flows pass): its arrays as they are
        return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)

    return _Points(
        res,
        joined([q.u for q in parts]),
        joined([q.area for q in parts]),
        joined([q.ratio for q in parts]) if with_ratio else None,
        pl.concat([q.groups for q in parts], how="vertical"),
        np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        np.concatenate([q.strides for q in parts]).astype(np.int64),
    )


def monitor_points(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
    engine: str = "numba",
) -> MonitorResult:
    """Steps 2–3 and Eq. 7 for a lake frame of one or more valves (no fit; ``fits`` is empty).

    Use it for the commissioning window, whose points feed step 4a
    (:func:`transforms.baseline.fit_characteristic`). ``leakage[valve][edge]``: nominal
    α·A per edge; when given, Eq. 7 subtracts the closed edge's flow
    (:func:`transforms.points.area_expr`) for that valve. ``engine``: ``"numba"`` (default) or
    ``"polars"`` (module docstring).
    """
    return _monitor_points(lake, params, leakage, engine).result


def monitor(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    baselines: Mapping[str, Mapping[str, Characteristic]],
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
    leak_scale: Mapping[str, Mapping[str, float]] | None = None,
    leak_reference: Mapping[str, Mapping[str, Characteristic]] | None = None,
    leakage_passes: int | None = None,
    engine: str = "numba",
    points: bool = True,
) -> MonitorResult:
    """Steps 2–4b: lake rows of one or more valves → points, selection statistics and fits.

    ``params``: one :class:`MonitorParams` per valve (or one for all); ``baselines[valve][edge]``:
    Â per edge (the commissioning fit or the nominal characteristic). A window/edge without a
    usable population still gets a fit row with its status. ``engine``: as in
    :func:`monitor_points`. ``points=False`` skips building the points frame (``points`` is then
    empty; the fits are the same): what the flows do, which store only fits and counts.

    ``leakage[valve][edge]``: α·A of each edge *at its baseline state* over the whole stroke
    (closed branch included: the nominal Eq. 3 characteristic for a nominal baseline, the
    identified leakage for a commissioning baseline, :class:`BaselineFit` ``leakage``). When
    given, every point is corrected for the flow through the closed edge o of its port
    (:mod:`transforms.points`) by that characteristic's closed branch, and the
    correction follows each window's own state of o (:mod:`transforms.leakage`): after a first
    fit with o at its baseline state, o's leakage is rebuilt from o's estimate in the same
    window, α̂_o·L_o(u + x̂_o) (a fit that is not ``ok`` but has ≥ 50 points gives a scale-only
    estimate, none the baseline state), and the window is fitted again, warm-started;
    ``leakage_passes`` times (default: the largest ``leakage_passes`` of the valves' params).
    Each fit row carries its edge's own leakage in the window and its interval (``leak_scale*``,
    identified from the other edge of the port, :func:`_leak_columns`; reported, not used): the
    commissioning value ``leak_scale[valve][edge]`` (default 1) plus the scale of an extra
    Eq. 3-shaped leakage ``leak_reference[valve][edge]`` (Eq. 3's branch at the baseline state;
    default ``leakage``) that the window asks for. The returned points carry the
    corrected areas. The baselines must have been built with the same correction
    (:func:`commissioning_baseline`).
    """
    pts = _monitor_points(lake, params, None, engine, with_ratio=leakage is not None, want_points=points)
    res, groups, offsets, u, plain = pts.result, pts.groups, pts.offsets, pts.u, pts.area
    pmap = {v: _params_for(params, v) for v in res.windows["valve_id"].unique().to_list()}
    strides = pts.strides
    if leakage is None:
        fits = fit_groups(groups, u, plain, offsets, baselines, pmap, strides=strides)
        return MonitorResult(points=res.points, selection=res.selection, fits=fits, windows=res.windows)

    ratio = pts.ratio
    if leakage_passes is None:
        leakage_passes = max((p.leakage_passes for p in pmap.values()), default=1)
    g_n = groups.height
    valve_ids = groups["valve_id"].to_list()
    edge_ids = groups["edge"].to_list()
    # the characteristic each population's closed edge leaks through, and that edge's population
    chars = [leakage.get(v, {}).get(OPPOSITE_EDGE[e]) for v, e in zip(valve_ids, edge_ids, strict=True)]
    opposite = _opposite_groups(groups)
    packed = _LeakPacked(chars)
    lk = (packed.kstart, packed.kend, packed.kn, packed.kv, packed.ks)
    base = _LeakPacked([baselines.get(v, {}).get(e) for v, e in zip(valve_ids, edge_ids, strict=True)])
    bk = (base.kstart, base.kend, base.kn, base.kv, base.ks)
    # the leakage is the commissioning one (the leakage characteristics); the window's own is
    # reported, not used (a window rarely identifies it well enough, transforms.leakage)
    lam_b = np.array([(leak_scale or {}).get(v, {}).get(OPPOSITE_EDGE[e], 1.0) for v, e in zip(valve_ids, edge_ids, strict=True)])
    scale = np.ones(g_n)
    shift = np.zeros(g_n)
    x0 = None
    passes = int(leakage_passes)
    if passes:
        # first estimates of every edge's state in every window from every FIRST_FIT_STRIDE-th
        # point (the leakage needs them to a few per cent; the final fit uses all points)
        idx, sub_off = _strided(offsets, FIRST_FIT_STRIDE)
        su, splain, sratio = u[idx], plain[idx], ratio[idx]
        sarea = np.empty_like(splain)
        for _ in range(passes):
            _leak_correct(su, splain, sratio, sub_off, scale, shift, *lk, sarea, _NO_LEAK)
            status, alpha, xhat = _quick_fit(su, sarea, sub_off, baselines, pmap, valve_ids, edge_ids, strides)
            own_a, own_x = _edge_states(status, alpha, xhat, su, sarea, sub_off, baselines, valve_ids, edge_ids, strides)
            scale, shift = own_a[opposite], own_x[opposite]
            x0 = xhat
    area = np.empty_like(plain)
    _leak_correct(u, plain, ratio, offsets, scale, shift, *lk, area, _NO_LEAK)
    fits = fit_groups(groups, u, area, offsets, baselines, pmap, x_start_m=x0, sort=False, strides=strides)
    # the windows' own leakage, on every FIRST_FIT_STRIDE-th point (a report, at 1/8 of a pass):
    # the points as corrected, and the regressor, Eq. 3's branch at o's state in the window
    if not passes:
        idx, sub_off = _strided(offsets, FIRST_FIT_STRIDE)
        su, splain, sratio = u[idx], plain[idx], ratio[idx]
    sarea = np.empty_like(splain)
    sleak = np.empty_like(splain)
    _leak_correct(su, splain, sratio, sub_off, scale, shift, *lk, sarea, sleak)
    if leak_reference is not None:
        ref = _LeakPacked([leak_reference.get(v, {}).get(OPPOSITE_EDGE[e]) for v, e in zip(valve_ids, edge_ids, strict=True)])
        _leak_correct(su, splain, sratio, sub_off, scale, shift, ref.kstart, ref.kend, ref.kn, ref.kv, ref.ks, np.empty_like(splain), sleak)
    fits = fits.with_columns(_leak_columns(fits, su, sarea, sleak, sub_off, lam_b, opposite, bk, pmap, valve_ids, strides))
    out_points = res.points.with_columns(pl.Series("area_m2", area)) if points else res.points
    return MonitorResult(points=out_points, selection=res.selection, fits=sorted_fits(fits), windows=res.windows)


def _leak_columns(fits, u, area, leak, offsets, lam_b, opposite, bk, pmap, valve_ids, strides) -> list[pl.Series]:
    """Each row's edge's leakage in the window: its commissioning λ_eff plus the scale of the
    Eq. 3-shaped regressor ``leak`` that the port's other population's final fit asks for (one
    Gauss–Newton step on block means of the strided points ``u``, ``area`` in ``offsets``: the
    same 50 ms per block, whatever the population's stride), clipped to ≥ 0, and its interval
    (Student's t, the serial-correlation factor); NaN where that fit is not ``ok``. Where the
    interval is wider than :data:`transforms.leakage.LEAK_RESOLUTION` (or there is none) the
    window cannot tell its leakage: ``leak_scale`` is the commissioning's, ``leak_scale_held``
    true (the interval stays the window's own)."""
    ok = (fits["status"] == "ok").to_numpy()
    alpha = fits["alpha_hat"].to_numpy()
    xhat = fits["x_hat_m"].to_numpy()
    # the same span of time on the strided points: every (FIRST_FIT_STRIDE · stride)-th row
    block = np.array([pmap[v].leak_block_points for v in valve_ids], dtype=np.int64)
    block = np.maximum(1, -(-block // (FIRST_FIT_STRIDE * strides)))
    step, info, sigma2, rho = leak_scale_step(u, area, leak, offsets, ok, alpha, xhat, *bk, block)
    se = np.sqrt(sigma2 / info) * inflation(rho)
    lam = np.maximum(lam_b + step, 0.0)
    m = np.diff(offsets) // block  # block means
    levels = np.array([pmap[v].ci_level for v in valve_ids]) if len(valve_ids) else np.zeros(0)
    from scipy.special import stdtrit  # noqa: PLC0415 - here, not at import (~0.3 s of the commands that import the monitor for its lake chunks)

    with np.errstate(invalid="ignore"):
        half = stdtrit(np.maximum(m - 3, 1), 0.5 + levels / 2) * se
    half = np.where(m > 3, half, np.nan)
    low, high = np.maximum(lam - half, 0.0), lam + half
    estimated = np.isfinite(step)
    held = estimated & ~(high - low < LEAK_RESOLUTION)
    lam = np.where(held, lam_b, lam)
    o = opposite
    return [
        pl.Series("leak_scale", lam[o]),
        pl.Series("leak_scale_ci_low", low[o]),
        pl.Series("leak_scale_ci_high", high[o]),
        pl.Series("leak_scale_held", held[o]).scatter(np.flatnonzero(~estimated[o]), None),
    ]


# --------------------------------------------------------------------------------------------
# closed-edge leakage that follows each window's estimates
# --------------------------------------------------------------------------------------------

SCALE_ONLY_MIN_POINTS = 50
"""A population whose fit is not ``ok`` but has at least this many points (in the strided
subsample: this over :data:`FIRST_FIT_STRIDE`) still gives its edge's
leakage a scale-only estimate (Σ A Â / Σ Â² at x̂ = 0). Near the closed branch this is nearly
as good as the full estimate: a narrow population confounds α̂ and x̂ along α̂·(u + x̂ + const)
≈ const, and the leakage ∝ α/(|u| − x) is nearly invariant along that line."""


def _opposite_groups(groups: pl.DataFrame) -> np.ndarray:
    """Row of the population of the same valve and window whose edge is the closed edge of the
    same port (every window has a row per edge)."""
    g = groups.select("valve_id", "window_id", "edge").with_row_index("_g")
    other = g.with_columns(pl.col("edge").replace_strict(OPPOSITE_EDGE, return_dtype=pl.Utf8))
    joined = other.join(g, on=["valve_id", "window_id", "edge"], how="left", maintain_order="left")
    return joined["_g_right"].to_numpy().astype(np.int64)


class _LeakPacked:
    """Per-population leakage characteristics concatenated (None = no correction: zero)."""

    def __init__(self, chars):
        index: dict[int, int] = {}
        kn, kv, starts, ends = [], [], [], []
        pos = 0
        g_n = len(chars)
        self.kstart = np.zeros(g_n, dtype=np.int64)
        self.kend = np.zeros(g_n, dtype=np.int64)
        zero = Characteristic(np.array([-1.0, 1.0]), np.zeros(2))
        for gi, c in enumerate(chars):
            c = zero if c is None else c
            key = id(c)
            if key not in index:
                index[key] = len(starts)
                kn.append(c.knots_u_m)
                kv.append(c.values_m2)
                starts.append(pos)
                pos += c.knots_u_m.shape[0]
                ends.append(pos)
            ci = index[key]
            self.kstart[gi], self.kend[gi] = starts[ci], ends[ci]
        self.kn = np.concatenate(kn) if kn else np.array([-1.0, 1.0])
        self.kv = np.concatenate(kv) if kv else np.zeros(2)
        self.ks = np.zeros_like(self.kn)
        for s0, s1 in zip(starts, ends, strict=True):
            d = np.diff(self.kv[s0:s1]) / np.diff(self.kn[s0:s1])
            self.ks[s0 : s1 - 1] = d
            self.ks[s1 - 1] = d[-1]


_NO_LEAK = np.zeros(0)
"""``leak`` of :func:`_leak_correct` when only the corrected points are wanted."""


@numba.njit(cache=True)
def _leak_correct(u, plain, ratio, offsets, scale, shift, kstart, kend, kn, kv, ks, out, leak):
    """leak_i = a_g·L_g(−u_i + x_g)·ratio_i (unless ``leak`` is empty) and out_i = plain_i −
    leak_i for the points of each population g, L_g piecewise linear (linear beyond its end
    knots); the segment is walked from the previous point's (points are in time order, so the
    walk is 0–1 steps)."""
    keep = leak.shape[0] > 0
    for g in range(offsets.shape[0] - 1):
        s = offsets[g]
        e = offsets[g + 1]
        if e == s:
            continue
        k0 = kstart[g]
        k1 = kend[g]
        a = scale[g]
        x = shift[g]
        j = k0
        for i in range(s, e):
            t = x - u[i]
            j = walk_segment(kn, k0, k1, j, t)
            lk = a * (kv[j] + ks[j] * (t - kn[j])) * ratio[i]
            if keep:
                leak[i] = lk
            out[i] = plain[i] - lk


FIRST_FIT_STRIDE = 8
"""The first estimate of each population (for the leakage and as the final fit's warm start)
uses every 8th point: a population's points are serially correlated over the 21-sample
Savitzky–Golay stencil, so 1/8 of them carry most of the information, at 1/8 of the cost."""


def _strided(offsets: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th point of each population: (indices, offsets of the subsample)."""
    n = np.diff(offsets)
    m = (n + k - 1) // k
    sub_off = np.concatenate([[0], np.cumsum(m)]).astype(np.int64)
    idx = np.repeat(offsets[:-1] - sub_off[:-1] * k, m) + k * np.arange(sub_off[-1])
    return idx, sub_off


def _quick_fit(u, area, offsets, baselines, pmap, valve_ids, edge_ids, strides):
    """(status, α̂, x̂) per population of a :func:`_strided` subsample, to 0.1 µm, without the
    residual pass; the point thresholds scaled by the strides (the subsample's and the rows')."""
    k = FIRST_FIT_STRIDE * strides
    res = fit_arrays(
        u, area, offsets, [baselines.get(v, {}).get(e) for v, e in zip(valve_ids, edge_ids, strict=True)],
        x_bound_m=np.array([pmap[v].x_hat_bound_m for v in valve_ids]),
        min_points=np.maximum(3, np.array([pmap[v].min_points for v in valve_ids], dtype=np.int64) // k),
        min_coverage_m=np.array([pmap[v].min_coverage_m for v in valve_ids]),
        xtol_m=1e-7, residuals=False,
    )  # fmt: skip
    return res["status"], res["alpha_hat"], res["x_hat_m"]


def _edge_states(status, alpha, xhat, u, area, offsets, baselines, valve_ids, edge_ids, strides):
    """Each population's own state relative to its baseline, (scale, shift): the fit where it is
    ``ok``, else a scale-only estimate (:data:`SCALE_ONLY_MIN_POINTS`), else (1, 0)."""
    a = np.array(alpha, dtype=np.float64)
    x = np.array(xhat, dtype=np.float64)
    ok = (status == "ok") & np.isfinite(a) & np.isfinite(x)
    a[~ok] = 1.0
    x[~ok] = 0.0
    n = np.diff(offsets)
    for g in np.flatnonzero(~ok & (n >= -(-SCALE_ONLY_MIN_POINTS // (FIRST_FIT_STRIDE * strides)))):
        base = baselines.get(valve_ids[g], {}).get(edge_ids[g])
        if base is None:
            continue
        b = base.evaluate(u[offsets[g] : offsets[g + 1]])
        bb = float(b @ b)
        s = float(area[offsets[g] : offsets[g + 1]] @ b) / bb if bb > 0 else float("nan")
        if np.isfinite(s) and s > 0:
            a[g] = s
    return a, x


# --------------------------------------------------------------------------------------------
# step 4a + 5a on a commissioning window
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BaselineFit:
    """Step 4a/5a result for one edge of a commissioning window."""

    edge: str
    characteristic: Characteristic | None
    """Â (None: fewer than ``min_points`` points or too narrow to place two knots); below the
    underlap it is the identified leakage (``leakage``), so it is never negative."""
    n_points: int
    u_range_m: tuple[float, float]
    """Range of the points' u (NaN without points)."""
    alpha_vs_nominal: float
    x_vs_nominal_m: float
    """Eq. 8 of the points onto the nominal characteristic: the edge's commissioning state."""
    leakage: Characteristic
    """α·A of this edge over the whole stroke at commissioning, α_b·nominal(u + x_b), its closed
    branch that of the identified leakage (λ₁, λ₂, :func:`transforms.leakage.closed_leakage`):
    what the other edge of its port sees leaking (the ``leakage`` argument of :func:`monitor`)."""
    plausibility: Plausibility | None
    """Step 5a against the nominal characteristic over ``u_range_m``."""
    leak_coefficients: tuple[float, float] = (1.0, 0.0)
    """(λ₁, λ₂) ≥ 0 of this edge's closed-edge leakage (:func:`transforms.leakage.closed_leakage`;
    (1, 0) = Eq. 3's), identified with the other edge's characteristic."""
    leak_scale: float = 1.0
    """λ_eff: the identified leakage over Eq. 3's 1 mm inside the closed edge
    (:func:`transforms.leakage.effective_scale`; the ``leak_scale`` argument of :func:`monitor`)."""
    leak_scale_se: float = float("nan")
    """Standard error of λ_eff (with the serial-correlation factor); NaN: not identified (too
    few points on the other edge: Eq. 3's leakage kept)."""
    leak_reference: Characteristic | None = None
    """α_b·nominal(u + x_b): Eq. 3's leakage at the commissioning state, the unit in which the
    windows report theirs (the ``leak_reference`` argument of :func:`monitor`)."""
    edge_law: str = "eq3"
    """The edge law Â's carrier follows: the configured one, or the one the commissioning points
    show (:func:`transforms.baseline.recognise_edge_law`; the same for the valve's four edges)."""
    edge_law_note: str = ""
    """Why the edge law is not the configured one (empty when it is)."""


LEAK_ITERATIONS = 3
"""Rounds of (state, leakage) at commissioning: each edge's state (α_b, x_b) and the closed edge's
leakage are fitted with the other edge's previous round (stable after 3)."""


def commissioning_baseline(
    lake: pl.DataFrame,
    params: MonitorParams,
    nominal: Mapping[str, Characteristic],
    *,
    leakage: bool = True,
    leakage_passes: int | None = None,
    engine: str = "numba",
    law: str = "eq3",
    laws: Mapping[str, Mapping[str, Characteristic]] | None = None,
) -> dict[str, BaselineFit]:
    """Steps 2–4a and 5a on one valve's commissioning rows: Â per edge and its plausibility.

    Â is :func:`transforms.baseline.fit_characteristic` with the nominal characteristic as
    carrier (the points' knots, sampled every ``params.baseline_grid_m``, widened by the fit's
    search bound). ``nominal`` is Eq. 3's (the edges' states and the leakage are in its units);
    ``laws[name]`` are the nominal characteristics of the other edge laws (``area_law`` names,
    e.g. ``"sharp"``) the valve may have, ``law`` the configured one: Â's carrier is the
    configured law's, unless the corrected points of the four edges follow another one clearly
    better (:func:`transforms.baseline.recognise_edge_law`); every :class:`BaselineFit` says
    which (``edge_law``, ``edge_law_note``). The carrier carries the shape beyond and between
    the knots, so a wrong one biases x̂ in proportion to the shift (docs/monitoring.md, "x̂ on
    any edge law"). With ``leakage`` (the default, and what :func:`monitor` then must use too)
    the points are corrected for the closed edge's flow: its nominal branch at the state that
    edge's own points give (Eq. 8 onto the nominal: α_b, x_b), scaled by λ₁, plus λ₂ times the
    same with worn lands (:func:`transforms.leakage.closed_leakage`), (λ₁, λ₂) ≥ 0 identified with
    the characteristic (:func:`transforms.baseline.leak_scale_lstsq`: means of
    ``leak_block_points`` points, prior N((1, 0), ``leak_scale_prior_sd``²) about Eq. 3's; only
    from ≥ ``leak_min_points`` points of the other edge, else Eq. 3's is kept); first
    at the nominal state and Eq. 3's leakage, then ``max(leakage_passes, LEAK_ITERATIONS − 1)``
    more rounds (default ``params.leakage_passes``); Â then runs down to −x_max along the
    identified leakage. The points of all windows are pooled, so the rows are taken as whole runs
    (``params.window_s`` and ``params.window_rows`` are not applied: a baseline does not depend on
    the window length, and it uses every row).
    """
    params = dataclasses.replace(params, window_s=None, window_rows=None)
    valve_ids = lake["valve_id"].unique().to_list()
    if len(valve_ids) != 1:
        raise ValueError(f"commissioning_baseline needs the rows of one valve, got {len(valve_ids)}")
    passes = params.leakage_passes if leakage_passes is None else int(leakage_passes)
    pts = _monitor_points(lake, params, None, engine, with_ratio=leakage)
    edge_col = pts.result.points["edge"].to_numpy()
    cols = {e: np.flatnonzero(edge_col == e) for e in EDGES}
    u = {e: pts.u[cols[e]] for e in EDGES}
    plain = {e: pts.area[cols[e]] for e in EDGES}
    state = {e: (1.0, 0.0) for e in EDGES}
    lam = {e: np.array([1.0, 0.0]) for e in EDGES}
    cov = {e: np.full((2, 2), np.nan) for e in EDGES}

    def closing(e):  # the closing point of edge e at its state, in its own u
        return -params.underlap(e) - state[e][1]

    def leak_char(e):
        return closed_leakage(scaled_shifted(nominal[e], *state[e]), closing(e), lam[e])

    rounds = 1 + (max(passes, LEAK_ITERATIONS - 1) if leakage else 0)
    for it in range(rounds):
        area = {e: plain[e] - leak_char(OPPOSITE_EDGE[e]).evaluate(-u[e]) * pts.ratio[cols[e]] if leakage else plain[e] for e in EDGES}
        if it == rounds - 1:
            break
        cols_o = {e: leak_columns(scaled_shifted(nominal[OPPOSITE_EDGE[e]], *state[OPPOSITE_EDGE[e]]), closing(OPPOSITE_EDGE[e]), u[e],
                                  pts.ratio[cols[e]]) for e in EDGES}  # fmt: skip
        new_lam = dict(lam)
        for e in EDGES:
            n = u[e].shape[0]
            state[e] = carrier_fit(u[e], area[e], nominal[e], x_search_m=params.x_hat_bound_m) if n >= 3 else (1.0, 0.0)
            if n >= max(params.min_points, params.leak_min_points) and np.ptp(u[e]) >= params.min_knot_spacing_m:
                knots = choose_knots(u[e], max_knots=params.max_knots, min_spacing_m=params.min_knot_spacing_m,
                                     points_per_interval=params.points_per_knot_interval)  # fmt: skip
                shape = scaled_shifted(nominal[e], *state[e]).evaluate(u[e])
                o = OPPOSITE_EDGE[e]
                new_lam[o], cov[o] = leak_scale_lstsq(u[e], plain[e], cols_o[e], knots, shape, block=params.leak_block_points,
                                                      prior=np.array([1.0, 0.0]), prior_sd=params.leak_scale_prior_sd)  # fmt: skip
        lam = new_lam
    candidates = {"eq3": nominal, **(laws or {})}
    if law not in candidates:
        raise ValueError(f"configured edge law {law!r} has no nominal characteristic (laws: {sorted(candidates)})")
    edge_law, note = law, ""
    if len(candidates) > 1:
        edge_law, ssr = recognise_edge_law(u, area, candidates, law, x_search_m=params.x_hat_bound_m)
        if edge_law != law:
            note = (f"edge law: the commissioning window shows {EDGE_LAWS.get(edge_law, edge_law)} edges, not the configured "
                    f"{EDGE_LAWS.get(law, law)} ones ({1 - ssr[edge_law] / ssr[law]:.0%} less Eq. 8 residual); "
                    f"the baseline follows area_law = \"{edge_law}\"")
    carrier = candidates[edge_law]
    out: dict[str, BaselineFit] = {}
    for e in EDGES:
        ue, ae = u[e], area[e]
        n = ue.shape[0]
        rng = (float(ue.min()), float(ue.max())) if n else (float("nan"), float("nan"))
        ab, xb = carrier_fit(ue, ae, nominal[e], x_search_m=params.x_hat_bound_m) if n >= 3 else (1.0, 0.0)
        state[e] = (ab, xb)
        own = leak_char(e) if leakage else scaled_shifted(nominal[e], ab, xb)
        char = check = None
        if n >= params.min_points and rng[1] - rng[0] >= params.min_knot_spacing_m:
            char = fit_characteristic(
                ue, ae, max_knots=params.max_knots, min_spacing_m=params.min_knot_spacing_m,
                points_per_interval=params.points_per_knot_interval, carrier=carrier[e],
                extend_m=params.x_hat_bound_m, grid_step_m=params.baseline_grid_m,
                closed=(own, closing(e), -params.x_max_m) if leakage else None,
            )  # fmt: skip
            check = plausibility(char, nominal[e], u_range=rng, x_search_m=params.x_hat_bound_m)
        eff, se = effective_scale(scaled_shifted(nominal[e], ab, xb), closing(e), lam[e], cov[e]) if leakage else (1.0, float("nan"))
        out[e] = BaselineFit(e, char, n, rng, ab, xb, own, check, (float(lam[e][0]), float(lam[e][1])), eff, se,
                             scaled_shifted(nominal[e], ab, xb), edge_law, note)  # fmt: skip
    return out

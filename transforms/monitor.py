"""Steps 2–4b composed: lake rows → opening-area points, selection statistics, fits.

Pure: frames and parameters in, frames out. Per valve (a Python loop over valves only):

1. windows and Savitzky–Golay values as one lazy polars query (:mod:`transforms.windows`,
   :mod:`transforms.derivatives`);
2. step 3 and Eq. 7 either as polars expressions (``engine="polars"``: :mod:`transforms.selection`
   and :mod:`transforms.points` expressions, the reference) or as two compiled passes over the
   columns (``engine="numba"``, the default: the same rules and formulas, without the ~45
   intermediate boolean columns per row; the tests hold both engines to the same points and
   counts).

Then the points of all valves are fitted in one compiled batch (:func:`transforms.fit.fit_windows`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import polars as pl

from transforms.characteristic import Characteristic
from transforms.derivatives import add_savgol, savgol_exprs
from transforms.fit import fit_groups, fit_windows
from transforms.params import EDGES, MonitorParams
from transforms.points import DEFAULT_SIGNALS, EDGE_SIGN, POINT_COLUMNS, opening_area_points, points_arrays
from transforms.selection import (
    SELECTED_CODE,
    add_selection_flags,
    selected_column,
    selection_codes,
    selection_stats,
    stats_frame,
)
from transforms.windows import assign_windows, infer_sample_period_s, window_arrays, window_table

__all__ = ["LAKE_COLUMNS", "MonitorResult", "monitor", "monitor_points", "prepare_samples"]

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


def _valve_polars(lake_v, valve_id, p, leakage):
    framed = prepare_samples(_time_sorted(lake_v), p)
    points = opening_area_points(
        framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES},
        leakage=None if leakage is None else leakage.get(valve_id),
    )
    return points, selection_stats(framed), window_table(framed), None


def _valve_numba(lake_v, valve_id, p, leakage):
    lake_v = _time_sorted(lake_v)
    dt = p.sample_period_s or infer_sample_period_s(lake_v)
    n = lake_v.height
    ts = lake_v["timestamp_utc"].cast(_UTC_US).to_physical().to_numpy()
    win, valid, n_windows = window_arrays(
        ts, sample_period_s=dt, gap_limit_s=p.gap_limit_periods * dt, step_tolerance=p.step_tolerance,
        half_window=p.half_window,
    )
    first = np.flatnonzero(np.diff(win, prepend=-1) != 0)
    last = np.append(first[1:] - 1, n - 1) if n else first
    windows = pl.DataFrame(
        {
            "valve_id": pl.repeat(valve_id, n_windows, eager=True, dtype=pl.Utf8),
            "window_id": pl.Series(np.arange(n_windows), dtype=pl.UInt32),
            "window_start": pl.Series(ts[first]).cast(_UTC_US),
            "window_end": pl.Series(ts[last]).cast(_UTC_US),
            "n_samples": pl.Series(last - first + 1, dtype=pl.Int64),
        }
    )
    # Savitzky–Golay as weighted rolling sums over the whole column; the validity comes from
    # window_arrays and is applied in the selection kernel (no per-row masking pass here)
    sg: list[pl.Expr] = []
    for column, (smooth_name, deriv_name) in _SG_OUTPUTS.items():
        sg += savgol_exprs(column, window=p.savgol_window, order=p.savgol_order, sample_period_s=dt,
                           smooth_name=smooth_name, deriv_name=deriv_name, mask=False,
                           nulls=lake_v[column].null_count() > 0)
    # NaN in the first/last h rows (never valid anyway): null-free columns convert without a copy
    derived = lake_v.select(e.fill_null(float("nan")) for e in sg)
    arrays = {c: lake_v[c].to_numpy() for c in ("ps_pa", "pr_pa", "x_spool_m", "x_cyl_m")}
    arrays.update({c: derived[c].to_numpy() for c in derived.columns})
    codes, flagged, removed, selected, _ = selection_codes(arrays, win, n_windows, p, valid=valid)
    stats = stats_frame(valve_id, windows, flagged, removed, selected)

    idx, area, offs = points_arrays(
        arrays, codes, SELECTED_CODE, p, leakage=None if leakage is None else leakage.get(valve_id)
    )
    sign = np.concatenate([np.full(offs[e + 1] - offs[e], float(EDGE_SIGN[edge])) for e, edge in enumerate(EDGES)])
    pw = win[idx]
    points = pl.DataFrame(
        {
            "valve_id": pl.repeat(valve_id, idx.shape[0], eager=True, dtype=pl.Utf8),
            "window_id": pl.Series(pw, dtype=pl.UInt32),
            "window_start": pl.Series(ts[first][pw]).cast(_UTC_US),
            "timestamp_utc": pl.Series(ts[idx]).cast(_UTC_US),
            "edge": pl.concat(
                [pl.repeat(edge, int(offs[e + 1] - offs[e]), eager=True, dtype=pl.Utf8) for e, edge in enumerate(EDGES)]
            ),
            "u_m": sign * arrays[DEFAULT_SIGNALS.x_spool][idx],
            "area_m2": area,
        }
    )
    # the fit populations in the order of `points`: edge-major, windows in time order
    groups = pl.concat(
        [windows.select("valve_id", "window_id", "window_start", "window_end", pl.lit(edge).alias("edge")) for edge in EDGES]
    )
    return points, stats, windows, (groups, selected.T.reshape(-1))


def _monitor_points(lake, params, leakage, engine):
    if engine not in ("numba", "polars"):
        raise ValueError(f"engine must be 'numba' or 'polars', got {engine!r}")
    missing = [c for c in LAKE_COLUMNS if c not in lake.columns]
    if missing:
        raise ValueError(f"lake frame lacks columns {missing}")
    lake, slices = _valve_slices(lake)
    run = _valve_numba if engine == "numba" else _valve_polars
    points, stats, windows, layouts = [], [], [], []
    for valve_id, off, length in slices:
        pts, st, wt, layout = run(lake.slice(off, length), valve_id, _params_for(params, valve_id), leakage)
        points.append(pts)
        stats.append(st)
        windows.append(wt)
        layouts.append(layout)
    if not slices:  # no rows: empty frames with the right schemas
        p = params if isinstance(params, MonitorParams) else next(iter(params.values()), None)
        if p is None:
            raise ValueError("empty lake frame and no MonitorParams")
        framed = prepare_samples(lake.head(0), p, sample_period_s=p.sample_period_s or 1e-3)
        stats.append(selection_stats(framed))
        windows.append(window_table(framed))
        points.append(opening_area_points(framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES}))
        layouts.append(None)
    res = MonitorResult(
        points=pl.concat(points, how="vertical").select(POINT_COLUMNS),
        selection=pl.concat(stats, how="vertical"),
        fits=pl.DataFrame(),
        windows=pl.concat(windows, how="vertical"),
    )
    layout = None
    if all(lay is not None for lay in layouts):
        groups = pl.concat([lay[0] for lay in layouts], how="vertical")
        sizes = np.concatenate([lay[1] for lay in layouts]).astype(np.int64)
        layout = (groups, np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64))
    return res, layout


def monitor_points(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
    engine: str = "numba",
) -> MonitorResult:
    """Steps 2–3 and Eq. 7 for a lake frame of one or more valves (no fit; ``fits`` is empty).

    Use it for the commissioning window, whose points feed step 4a
    (:func:`transforms.characteristic.fit_characteristic`). ``leakage[valve][edge]``: nominal
    α·A per edge; when given, Eq. 7 subtracts the closed edge's flow
    (:func:`transforms.points.area_expr`) for that valve. ``engine``: ``"numba"`` (default) or
    ``"polars"`` (module docstring).
    """
    return _monitor_points(lake, params, leakage, engine)[0]


def monitor(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    baselines: Mapping[str, Mapping[str, Characteristic]],
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
    engine: str = "numba",
) -> MonitorResult:
    """Steps 2–4b: lake rows of one or more valves → points, selection statistics and fits.

    ``params``: one :class:`MonitorParams` per valve (or one for all); ``baselines[valve][edge]``:
    Â per edge (the commissioning fit or the nominal characteristic). A window/edge without a
    usable population still gets a fit row with its status. ``leakage``, ``engine``: as in
    :func:`monitor_points` (the baselines must have been built with the same ``leakage``).
    """
    res, layout = _monitor_points(lake, params, leakage, engine)
    valves = res.windows["valve_id"].unique().to_list()
    pmap = {v: _params_for(params, v) for v in valves}
    if layout is not None:  # the compiled path knows the populations' layout already
        groups, offsets = layout
        fits = fit_groups(groups, res.points["u_m"].to_numpy(), res.points["area_m2"].to_numpy(), offsets, baselines, pmap)
    else:
        fits = fit_windows(res.points, baselines, pmap, windows=res.windows)
    return MonitorResult(points=res.points, selection=res.selection, fits=fits, windows=res.windows)

"""Steps 2–4b composed: lake rows → opening-area points, selection statistics, fits.

Pure: frames and parameters in, frames out. Per valve (a Python loop over valves only) the rows
go through one lazy polars query (windows, Savitzky–Golay, step-3 flags), then the points of all
valves are fitted in one compiled batch (:func:`transforms.fit.fit_windows`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import polars as pl

from transforms.characteristic import Characteristic
from transforms.derivatives import add_savgol
from transforms.fit import fit_windows
from transforms.params import EDGES, MonitorParams
from transforms.points import DEFAULT_SIGNALS, opening_area_points
from transforms.selection import add_selection_flags, selected_column, selection_stats
from transforms.windows import assign_windows, infer_sample_period_s, window_table

__all__ = ["LAKE_COLUMNS", "MonitorResult", "monitor", "monitor_points", "prepare_samples"]

LAKE_COLUMNS = ("valve_id", "timestamp_utc", "ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")
"""Lake columns the algorithm reads (others are ignored)."""

# smoothed p1, p2 for the pressure differences; X only differentiated (its noise is irrelevant in V)
_SG_OUTPUTS = {
    "p1_pa": ("p1_smooth_pa", "dp1_dt_pa_s"),
    "p2_pa": ("p2_smooth_pa", "dp2_dt_pa_s"),
    "x_cyl_m": (None, "v_cyl_m_s"),
}


@dataclass(frozen=True)
class MonitorResult:
    points: pl.DataFrame
    """valve_id, window_id, window_start, timestamp_utc, edge, u_m, area_m2 (selected points)."""
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


def prepare_samples(
    lake_one_valve: pl.DataFrame, params: MonitorParams, *, sample_period_s: float | None = None
) -> pl.DataFrame:
    """One valve's rows (sorted by time) with window columns, Savitzky–Golay values and the step-3
    flags (``selected_<edge>`` and the internal ``_flag_*``/``_removed_*`` columns).

    The sample period is ``sample_period_s``, else ``params.sample_period_s``, else the median
    time step of the rows."""
    dt = sample_period_s or params.sample_period_s or infer_sample_period_s(lake_one_valve)
    lf = lake_one_valve.lazy().select(LAKE_COLUMNS)
    lf = assign_windows(
        lf,
        sample_period_s=dt,
        gap_limit_s=params.gap_limit_periods * dt,
        step_tolerance=params.step_tolerance,
    )
    lf = add_savgol(lf, window=params.savgol_window, order=params.savgol_order, sample_period_s=dt, outputs=_SG_OUTPUTS)
    lf = add_selection_flags(lf, params, signals=DEFAULT_SIGNALS)
    return lf.collect()


def _valve_slices(lake: pl.DataFrame) -> tuple[pl.DataFrame, list[tuple[str, int, int]]]:
    """Sort if needed and return (frame, [(valve_id, offset, length)])."""
    unsorted = lake.select(
        (
            (pl.col("valve_id") < pl.col("valve_id").shift(1))
            | (
                (pl.col("valve_id") == pl.col("valve_id").shift(1))
                & (pl.col("timestamp_utc") < pl.col("timestamp_utc").shift(1))
            )
        ).any()
    ).item()
    if unsorted:
        lake = lake.sort("valve_id", "timestamp_utc", maintain_order=True)
    rle = lake.select(pl.col("valve_id").rle()).unnest("valve_id")
    out, off = [], 0
    for length, value in zip(rle["len"].to_list(), rle["value"].to_list(), strict=True):
        out.append((value, off, length))
        off += length
    return lake, out


def monitor_points(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
) -> MonitorResult:
    """Steps 2–3 and Eq. 7 for a lake frame of one or more valves (no fit; ``fits`` is empty).

    Use it for the commissioning window, whose points feed step 4a
    (:func:`transforms.characteristic.fit_characteristic`). ``leakage[valve][edge]``: nominal
    α·A per edge; when given, Eq. 7 subtracts the closed edge's flow
    (:func:`transforms.points.area_expr`) for that valve.
    """
    missing = [c for c in LAKE_COLUMNS if c not in lake.columns]
    if missing:
        raise ValueError(f"lake frame lacks columns {missing}")
    lake, slices = _valve_slices(lake)
    points, stats, windows = [], [], []
    for valve_id, off, length in slices:
        p = _params_for(params, valve_id)
        framed = prepare_samples(lake.slice(off, length), p)
        stats.append(selection_stats(framed))
        windows.append(window_table(framed))
        points.append(
            opening_area_points(
                framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES},
                leakage=None if leakage is None else leakage.get(valve_id),
            )
        )
    if not slices:  # no rows: empty frames with the right schemas
        p = params if isinstance(params, MonitorParams) else next(iter(params.values()), None)
        if p is None:
            raise ValueError("empty lake frame and no MonitorParams")
        framed = prepare_samples(lake.head(0), p, sample_period_s=p.sample_period_s or 1e-3)
        stats.append(selection_stats(framed))
        windows.append(window_table(framed))
        points.append(opening_area_points(framed, p, selected={e: pl.col(selected_column(e)) for e in EDGES}))
    return MonitorResult(
        points=pl.concat(points, how="vertical"),
        selection=pl.concat(stats, how="vertical"),
        fits=pl.DataFrame(),
        windows=pl.concat(windows, how="vertical"),
    )


def monitor(
    lake: pl.DataFrame,
    params: Mapping[str, MonitorParams] | MonitorParams,
    baselines: Mapping[str, Mapping[str, Characteristic]],
    *,
    leakage: Mapping[str, Mapping[str, Characteristic]] | None = None,
) -> MonitorResult:
    """Steps 2–4b: lake rows of one or more valves → points, selection statistics and fits.

    ``params``: one :class:`MonitorParams` per valve (or one for all); ``baselines[valve][edge]``:
    Â per edge (the commissioning fit or the nominal characteristic). A window/edge without a
    usable population still gets a fit row with its status. ``leakage``: as in
    :func:`monitor_points` (the baselines must have been built the same way).
    """
    res = monitor_points(lake, params, leakage=leakage)
    valves = res.windows["valve_id"].unique().to_list()
    pmap = {v: _params_for(params, v) for v in valves}
    fits = fit_windows(res.points, baselines, pmap, windows=res.windows)
    return MonitorResult(points=res.points, selection=res.selection, fits=fits, windows=res.windows)

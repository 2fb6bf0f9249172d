"""Monitoring windows: contiguous runs of samples, found from the time stamps (step 1 → 2).

A frame sorted by ``valve_id, timestamp_utc`` gets

* ``window_id`` (UInt32): ordinal of the window in the frame; a new window starts at the first row,
  at every change of ``valve_id`` and after every time step longer than the gap limit;
* ``window_start``, ``window_end``: the time stamps of the window's first and last sample;
* ``run_index``, ``run_remaining`` (Int64): samples since the start and until the end of the
  *uniform run* that holds the row. A uniform run is a stretch of a window whose steps all lie
  within ``step_tolerance`` of the sample period; a Savitzky–Golay stencil is valid only where it
  stays inside one run (:mod:`transforms.derivatives`). Within a healthy window the run is the
  window itself; a dropped sample, a duplicate or a jitter spike cuts the run but not the window.

Everything is a column expression with forward/backward fills: no group-by, no Python loop.
"""

from __future__ import annotations

import polars as pl

__all__ = ["WINDOW_COLUMNS", "assign_windows", "infer_sample_period_s", "window_table"]

WINDOW_COLUMNS = ("window_id", "window_start", "window_end", "run_index", "run_remaining")


def infer_sample_period_s(frame: pl.DataFrame | pl.LazyFrame) -> float:
    """Median positive time step of the frame (seconds); meant for the rows of one valve.

    Raises ValueError if the frame has fewer than two distinct time stamps.
    """
    lf = frame.lazy() if isinstance(frame, pl.DataFrame) else frame
    step = (
        lf.select(pl.col("timestamp_utc").diff().dt.total_microseconds().alias("s"))
        .filter(pl.col("s") > 0)
        .select(pl.col("s").median())
        .collect()
        .item()
    )
    if step is None:
        raise ValueError("cannot infer the sample period: fewer than two distinct time stamps")
    return float(step) * 1e-6


def assign_windows(
    frame: pl.DataFrame | pl.LazyFrame,
    *,
    sample_period_s: float,
    gap_limit_s: float | None = None,
    step_tolerance: float = 0.1,
) -> pl.DataFrame | pl.LazyFrame:
    """Add :data:`WINDOW_COLUMNS` to a frame sorted by ``valve_id, timestamp_utc``.

    ``gap_limit_s`` defaults to 3 sample periods. A step ``> gap_limit_s`` starts a new window;
    a step outside ``[(1 - tol), (1 + tol)] * sample_period_s`` starts a new uniform run.
    Returns the same kind of frame it was given (eager or lazy).
    """
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    if gap_limit_s is None:
        gap_limit_s = 3.0 * sample_period_s
    if gap_limit_s < sample_period_s * (1.0 + step_tolerance):
        raise ValueError("gap_limit_s must exceed the sample period (plus tolerance)")
    period_us = sample_period_s * 1e6
    gap_us = gap_limit_s * 1e6
    lo_us, hi_us = period_us * (1.0 - step_tolerance), period_us * (1.0 + step_tolerance)

    ts = pl.col("timestamp_utc")
    step = ts.diff().dt.total_microseconds()
    new_valve = (pl.col("valve_id") != pl.col("valve_id").shift(1)).fill_null(True)
    new_window = (new_valve | step.is_null() | (step > gap_us)).alias("_new_window")
    new_run = (pl.col("_new_window") | (step < lo_us) | (step > hi_us)).alias("_new_run")

    idx = pl.int_range(pl.len(), dtype=pl.Int64)
    last_in_window = pl.col("_new_window").shift(-1).fill_null(True)
    last_in_run = pl.col("_new_run").shift(-1).fill_null(True)

    out = (
        frame.with_columns(new_window)
        .with_columns(new_run)
        .with_columns(
            (pl.col("_new_window").cum_sum() - 1).cast(pl.UInt32).alias("window_id"),
            pl.when(pl.col("_new_window")).then(ts).forward_fill().alias("window_start"),
            pl.when(last_in_window).then(ts).backward_fill().alias("window_end"),
            (idx - pl.when(pl.col("_new_run")).then(idx).forward_fill()).alias("run_index"),
            (pl.when(last_in_run).then(idx).backward_fill() - idx).alias("run_remaining"),
        )
        .drop("_new_window", "_new_run")
    )
    return out


def window_table(framed: pl.DataFrame | pl.LazyFrame) -> pl.DataFrame:
    """One row per window of a frame from :func:`assign_windows`:
    ``valve_id, window_id, window_start, window_end, n_samples``."""
    lf = framed.lazy() if isinstance(framed, pl.DataFrame) else framed
    return (
        lf.group_by("window_id", maintain_order=True)
        .agg(
            pl.col("valve_id").first(),
            pl.col("window_start").first(),
            pl.col("window_end").first(),
            pl.len().cast(pl.Int64).alias("n_samples"),
        )
        .select("valve_id", "window_id", "window_start", "window_end", "n_samples")
        .collect()
    )

"""Monitoring windows: contiguous runs of samples cut by the clock, found from the time stamps (step 1 → 2).

A *run* is a stretch of one valve's samples without a time step longer than the gap limit: a
snapshot (10 s every hour) is one run, a continuous recording (back-to-back samples for minutes
to hours) is one long run. With a window length ``window_s`` = L (:func:`window_flags`):

* a run whose span (last − first time stamp) is shorter than L/2 is one window, whole, wherever
  it lies on the clock (a 10 s snapshot is never cut, whatever its offset in the hour);
* a longer run is cut at every multiple of L since the UTC epoch (00:00:00 1970-01-01) inside it;
  its first and last windows may be short (a *remainder*; fitted like any other window, or
  given the status that says why not: ``too_few_points``, ``no_points``, …).

So windows never straddle a gap, a cut is at the same instant whichever file, chunk or span the
samples were read in, and any slice of whole windows is cut again into the same windows (a
slice's runs are whole runs or hold a full clock cell, whose span is ≥ L/2). Without a length
(``None``) a window is a whole run, as for snapshot archives before the rule existed.

A frame sorted by ``valve_id, timestamp_utc`` gets

* ``window_id`` (UInt32): ordinal of the window in the frame; a new window starts at the first row,
  at every change of ``valve_id``, after every time step longer than the gap limit and, in a run
  at least L/2 long, at the first sample of every clock cell [k·L, (k + 1)·L);
* ``window_start``, ``window_end``: the time stamps of the window's first and last sample;
* ``run_start`` (Boolean): True at the first sample of a *uniform run*, a stretch of a window
  whose steps all lie within ``step_tolerance`` of the sample period. A Savitzky–Golay stencil is
  valid only where it stays inside one run (:mod:`transforms.derivatives`). Within a healthy
  window the run is the window itself; a dropped sample, a duplicate or a jitter spike cuts the
  run but not the window. A window start is a uniform-run start: a stencil never reaches into
  the neighbouring window, so a window's values depend on its own samples only.

Everything is a column expression (diff, cumulative sum, forward/backward fill; the span of a run
is a ``min``/``max`` over the run): no Python loop. :func:`window_arrays` does the same for one
valve in one compiled pass over the time stamps, with the Savitzky–Golay validity (what the
monitor's fast path uses; the tests hold the two equal).
"""

from __future__ import annotations

import numba
import numpy as np
import polars as pl

__all__ = [
    "LONG_RUN_FRACTION", "WINDOW_COLUMNS", "assign_windows", "evaluated_rows", "infer_sample_period_s", "window_arrays", "window_flags",
    "window_length_us", "window_starts", "window_table",
]  # fmt: skip

WINDOW_COLUMNS = ("window_id", "window_start", "window_end", "run_start")

LONG_RUN_FRACTION = 0.5
"""A run whose span is at least this fraction of the window length is cut by the clock; a
shorter one (a snapshot) stays one window. Half a length: a slice of whole windows holding a
clock cut holds a full cell (span ≈ L), so it is classed as its run was."""


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


def window_length_us(window_s: float | None) -> int:
    """The window length in whole µs (0: no clock cut). Raises ValueError unless > 0 or None."""
    if window_s is None:
        return 0
    if not window_s > 0:
        raise ValueError(f"window_s must be > 0 (or None), got {window_s}")
    return max(1, int(round(window_s * 1e6)))


@numba.njit(cache=True)
def _flags_kernel(t_us, gap_us, length_us):
    n = t_us.shape[0]
    new = np.zeros(n, dtype=np.bool_)
    if n == 0:
        return new
    new[0] = True
    for i in range(1, n):
        new[i] = t_us[i] - t_us[i - 1] > gap_us
    if length_us <= 0:
        return new
    # runs at least LONG_RUN_FRACTION of the length long: a new window at each clock cell
    min_span = LONG_RUN_FRACTION * length_us
    a = 0
    while a < n:
        b = a + 1
        while b < n and not new[b]:
            b += 1
        if t_us[b - 1] - t_us[a] >= min_span:
            # t is sorted: t_i // L differs from t_{i-1} // L where t_i reaches the next
            # multiple of L after t_{i-1} (one division per cut, not two per sample)
            nxt = (t_us[a] // length_us + 1) * length_us
            for i in range(a + 1, b):
                if t_us[i] >= nxt:
                    new[i] = True
                    nxt = (t_us[i] // length_us + 1) * length_us
        a = b
    return new


def window_flags(t_us: np.ndarray, gap_us: float, window_s: float | None = None) -> np.ndarray:
    """Per sample of one valve's sorted time stamps (µs since the epoch, int64): True where a
    window starts (module doc): the first sample, every sample after a step longer than
    ``gap_us`` and, with a length ``window_s``, the first sample of every clock cell of a run at
    least :data:`LONG_RUN_FRACTION` · ``window_s`` long. One compiled pass."""
    return _flags_kernel(np.ascontiguousarray(t_us, dtype=np.int64), float(gap_us), window_length_us(window_s))


def window_starts(t_us: np.ndarray, gap_us: float, window_s: float | None = None) -> np.ndarray:
    """Index of the first sample of each window of one valve's sorted time stamps (µs): the rule
    of :func:`assign_windows` (:func:`window_flags`)."""
    return np.flatnonzero(window_flags(t_us, gap_us, window_s))


def assign_windows(
    frame: pl.DataFrame | pl.LazyFrame,
    *,
    sample_period_s: float,
    gap_limit_s: float | None = None,
    step_tolerance: float = 0.1,
    window_s: float | None = None,
) -> pl.DataFrame | pl.LazyFrame:
    """Add :data:`WINDOW_COLUMNS` to a frame sorted by ``valve_id, timestamp_utc``.

    ``gap_limit_s`` defaults to 3 sample periods. A step ``> gap_limit_s`` starts a new window,
    and so does a clock cut of ``window_s`` in a long run (module doc); a step outside
    ``[(1 - tol), (1 + tol)] * sample_period_s`` starts a new uniform run.
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
    length_us = window_length_us(window_s)
    new_valve = (pl.col("valve_id") != pl.col("valve_id").shift(1)).fill_null(True)
    new_window = (new_valve | step.is_null() | (step > gap_us)).alias("_new_window")
    run_start = (pl.col("_new_window") | (step < lo_us) | (step > hi_us)).alias("run_start")
    last_in_window = pl.col("_new_window").shift(-1).fill_null(True)

    frame = frame.with_columns(new_window)
    if length_us:
        t_us = ts.dt.epoch("us")
        run = pl.col("_new_window").cum_sum()
        long_run = (t_us.max() - t_us.min()).over(run) >= LONG_RUN_FRACTION * length_us
        clock_cut = long_run & (t_us // length_us != (t_us // length_us).shift(1)).fill_null(True)
        frame = frame.with_columns((pl.col("_new_window") | clock_cut).alias("_new_window"))
    return (
        frame.with_columns(
            run_start,
            (pl.col("_new_window").cum_sum() - 1).cast(pl.UInt32).alias("window_id"),
            pl.when(pl.col("_new_window")).then(ts).forward_fill().alias("window_start"),
            pl.when(last_in_window).then(ts).backward_fill().alias("window_end"),
        )
        .drop("_new_window")
    )


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


# --------------------------------------------------------------------------------------------
# compiled path (one valve; used by transforms.monitor for throughput)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _window_kernel(ts_us, lo_us, hi_us, gap_us, length_us, h):
    n = ts_us.shape[0]
    win = np.empty(n, dtype=np.int64)
    valid = np.zeros(n, dtype=np.bool_)
    run_start = np.empty(n, dtype=np.bool_)
    new = _flags_kernel(ts_us, gap_us, length_us)
    w = -1
    for i in range(n):
        new_w = new[i]
        if i == 0:
            new_r = True
        else:
            step = ts_us[i] - ts_us[i - 1]
            new_r = new_w or step < lo_us or step > hi_us
        if new_w:
            w += 1
        win[i] = w
        run_start[i] = new_r
    # valid: no run start in (i − h, i] and none in (i, i + h], i + h < n
    nxt = n
    for i in range(n - 1, -1, -1):
        if nxt - i > h:
            valid[i] = True
        if run_start[i]:
            nxt = i
    last = 0
    for i in range(n):
        if run_start[i]:
            last = i
        if i - last < h:
            valid[i] = False
    return win, valid, w + 1


def window_arrays(
    timestamp_us: np.ndarray,
    *,
    sample_period_s: float,
    gap_limit_s: float | None = None,
    step_tolerance: float = 0.1,
    half_window: int,
    window_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`assign_windows` and the Savitzky–Golay validity of
    :func:`transforms.derivatives.savgol_valid` in one compiled pass, for the sorted time stamps
    (µs since the epoch, int64) of **one valve**.

    Returns ``(window_id, valid, n_windows)``: window ids 0 … n_windows − 1 (int64) and, per row,
    whether a centred stencil of ``2·half_window + 1`` samples stays inside one uniform run.
    """
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    if gap_limit_s is None:
        gap_limit_s = 3.0 * sample_period_s
    if gap_limit_s < sample_period_s * (1.0 + step_tolerance):
        raise ValueError("gap_limit_s must exceed the sample period (plus tolerance)")
    period_us = sample_period_s * 1e6
    return _window_kernel(
        np.ascontiguousarray(timestamp_us, dtype=np.int64),
        period_us * (1.0 - step_tolerance),
        period_us * (1.0 + step_tolerance),
        float(gap_limit_s * 1e6),
        window_length_us(window_s),
        int(half_window),
    )


@numba.njit(cache=True)
def _evaluated_kernel(first, count, stride):
    total = 0
    for w in range(first.shape[0]):
        total += (count[w] + stride[w] - 1) // stride[w]
    rows = np.empty(total, dtype=np.int64)
    k = 0
    for w in range(first.shape[0]):
        for i in range(first[w], first[w] + count[w], stride[w]):
            rows[k] = i
            k += 1
    return rows


def evaluated_rows(first: np.ndarray, count: np.ndarray, window_rows: int | None) -> np.ndarray | None:
    """The rows steps 2–3 evaluate when a window of n samples is evaluated on every k-th row
    from its first, k = max(1, n // ``window_rows``) (:class:`transforms.params.MonitorParams`
    ``window_rows``): sorted int64 row indices, or None when every row is (no window has k > 1).
    ``first``, ``count``: each window's first row and number of rows, in row order."""
    if window_rows is None or count.shape[0] == 0:
        return None
    stride = np.maximum(np.asarray(count, dtype=np.int64) // int(window_rows), 1)
    if int(stride.max()) == 1:
        return None
    return _evaluated_kernel(np.ascontiguousarray(first, dtype=np.int64), np.ascontiguousarray(count, dtype=np.int64), stride)

"""Monitoring windows: contiguous runs of samples cut by the clock, found from the time stamps (step 1 → 2).

A *run* is a stretch of one valve's samples without a time step longer than the gap limit: a
snapshot (10 s every hour) is one run, a continuous recording (back-to-back samples for minutes
to hours) is one long run. With a window length ``window_s`` = L (:func:`window_starts`):

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
is a ``min``/``max`` over the run): no Python loop. :func:`window_layout` does the same for one
valve in one compiled pass over the time stamps, with the Savitzky–Golay validity (what the
monitor's fast path uses; the tests hold the two equal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import polars as pl

from transforms.arrays import read_only

__all__ = [
    "LONG_RUN_FRACTION", "WINDOW_COLUMNS", "UnsortedTimes", "WindowLayout", "assign_windows", "infer_sample_period_s", "window_layout",
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
def _steps_kernel(t_us, lo_us, hi_us, gap_us):
    """One pass over the time stamps: the rows whose step from the previous row lies outside
    [lo_us, hi_us] (row 0 included), and which of them follow a step longer than ``gap_us`` (or
    are row 0); False as the third value if a step is negative (not sorted; the rest is then
    meaningless). Sparse: the arrays are allocated for every row, but only the pages written are
    touched."""
    n = t_us.shape[0]
    pos = np.empty(n + 1, dtype=np.int64)
    gap = np.empty(n + 1, dtype=np.bool_)
    if n == 0:
        return pos[:0], gap[:0], True
    pos[0] = 0
    gap[0] = True
    m = 1
    ok = True
    prev = t_us[0]
    for i in range(1, n):
        t = t_us[i]
        step = t - prev
        prev = t
        if step < lo_us or step > hi_us:
            if step < 0:
                ok = False
            pos[m] = i
            gap[m] = step > gap_us
            m += 1
    return pos[:m], gap[:m], ok


@numba.njit(cache=True)
def _starts_kernel(t_us, gaps, length_us):
    """The window starts (sorted row indices) from the rows after a gap ``gaps`` (row 0 first):
    each run from one to the next is a window, or, at least LONG_RUN_FRACTION of the length long,
    cut at the first sample of every clock cell (found by bisection: one per cut)."""
    n = t_us.shape[0]
    if length_us <= 0 or n == 0:
        return gaps.copy()
    min_span = LONG_RUN_FRACTION * length_us
    out = np.empty(16 + 2 * gaps.shape[0], dtype=np.int64)
    m = 0
    for g in range(gaps.shape[0]):
        a = gaps[g]
        b = gaps[g + 1] if g + 1 < gaps.shape[0] else n
        if m + 1 > out.shape[0]:
            out = _grown(out, m)
        out[m] = a
        m += 1
        if t_us[b - 1] - t_us[a] < min_span:
            continue
        nxt = (t_us[a] // length_us + 1) * length_us
        i = a + 1
        while i < b:
            i = _first_at_or_after(t_us, i, b, nxt)  # the first sample at or after the next cut
            if i >= b:
                break
            if m + 1 > out.shape[0]:
                out = _grown(out, m)
            out[m] = i
            m += 1
            nxt = (t_us[i] // length_us + 1) * length_us
            i += 1
    return out[:m]


@numba.njit(cache=True)
def _first_at_or_after(t_us, lo, hi, value):
    """The first index in [lo, hi) of the sorted ``t_us`` whose value is >= ``value`` (hi if none):
    ``lo + np.searchsorted(t_us[lo:hi], value)`` by bisection, without numba's generic
    searchsorted (~1 s of the window kernel's cold compile)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if t_us[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _grown(a, m):
    b = np.empty(2 * a.shape[0], dtype=a.dtype)
    b[:m] = a[:m]
    return b


def window_starts(t_us: np.ndarray, gap_us: float, window_s: float | None = None) -> np.ndarray:
    """Index of the first sample of each window of one valve's sorted time stamps (µs since the
    epoch, int64), the rule of :func:`assign_windows` (module doc): the first sample, every
    sample after a step longer than ``gap_us`` and, with a length ``window_s``, the first sample
    of every clock cell of a run at least :data:`LONG_RUN_FRACTION` · ``window_s`` long. One
    compiled pass over the time stamps, one bisection per clock cut."""
    t_us = read_only(np.ascontiguousarray(t_us, dtype=np.int64))
    length_us = window_length_us(window_s)
    _, gaps = _gap_rows(t_us, -np.inf, float(gap_us), float(gap_us))
    return _starts_kernel(t_us, gaps, length_us)


def _gap_rows(t_us: np.ndarray, lo_us: float, hi_us: float, gap_us: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows after a step outside [lo_us, hi_us], rows after a gap) of :func:`_steps_kernel`;
    :class:`UnsortedTimes` if a step is negative and below ``lo_us``."""
    pos, gap, ok = _steps_kernel(t_us, lo_us, hi_us, gap_us)
    if not ok:
        raise UnsortedTimes("time stamps are not sorted")
    return pos, pos[gap]


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
def _layout_kernel(n, starts, irregular, h, window_rows, dense):
    """Windows ``starts`` (sorted rows) of n rows → each window's first row, length and stride k,
    the evaluated rows (every k-th of a window from its first, k = max(1, length // window_rows);
    window_rows 0 or ``dense[w]``: every row), their window and their Savitzky–Golay validity: no
    uniform-run start (a window start or an ``irregular`` step's row) in (i − h, i] nor in
    (i, i + k − 1 + h], and i + k − 1 + h < n (a row of a thinned window stands for the k rows
    from it on, their stencils averaged: :func:`transforms.derivatives.savgol_at`'s ``box``). ``dense`` is empty or one flag per window."""
    nw = starts.shape[0]
    count = np.empty(nw, dtype=np.int64)
    stride = np.empty(nw, dtype=np.int64)
    total = 0
    for w in range(nw):
        count[w] = (starts[w + 1] if w + 1 < nw else n) - starts[w]
        k = max(1, count[w] // window_rows) if window_rows > 0 else 1
        if dense.shape[0] > 0 and dense[w]:
            k = 1
        stride[w] = k
        total += (count[w] + k - 1) // k
    # the uniform-run starts: both sorted lists merged
    runs = np.empty(nw + irregular.shape[0], dtype=np.int64)
    m = 0
    a = 0
    b = 0
    while a < nw or b < irregular.shape[0]:
        if b >= irregular.shape[0] or (a < nw and starts[a] <= irregular[b]):
            v = starts[a]
            a += 1
        else:
            v = irregular[b]
            b += 1
        if m == 0 or runs[m - 1] != v:
            runs[m] = v
            m += 1
    rows = np.empty(total, dtype=np.int64)
    win = np.empty(total, dtype=np.int64)
    valid = np.empty(total, dtype=np.bool_)
    j = 0  # runs[j]: the last run start at or before the row
    r = 0
    for w in range(nw):
        for i in range(starts[w], starts[w] + count[w], stride[w]):
            while j + 1 < m and runs[j + 1] <= i:
                j += 1
            nxt = runs[j + 1] if j + 1 < m else n
            rows[r] = i
            win[r] = w
            valid[r] = nxt - i > h + stride[w] - 1 and i - runs[j] >= h
            r += 1
    return count, stride, rows, win, valid


class UnsortedTimes(ValueError):
    """The time stamps are not sorted."""


@dataclass(frozen=True)
class WindowLayout:
    """One valve's windows and the rows steps 2–3 evaluate (:func:`window_layout`)."""

    first: np.ndarray
    """Each window's first row (int64, sorted)."""
    count: np.ndarray
    """Each window's number of rows (int64)."""
    stride: np.ndarray
    """Each window's stride k (int64): every k-th row of it is evaluated."""
    rows: np.ndarray
    """The evaluated rows, sorted (int64): every k-th row of each window from its first (each
    standing for the k rows from it on)."""
    window: np.ndarray
    """The window (0 … n_windows − 1) of each evaluated row (int64)."""
    valid: np.ndarray
    """Per evaluated row: whether its Savitzky–Golay stencil stays inside one uniform run (at a
    stride k, the stencils of the k rows from it on)."""

    @property
    def n_windows(self) -> int:
        return int(self.first.shape[0])

    @property
    def every_row(self) -> bool:
        """Whether every row is evaluated (``rows`` is 0 … n − 1)."""
        return int(self.rows.shape[0]) == int(self.count.sum())


def window_layout(
    timestamp_us: np.ndarray,
    *,
    sample_period_s: float,
    gap_limit_s: float | None = None,
    step_tolerance: float = 0.1,
    half_window: int,
    window_s: float | None = None,
    window_rows: int | None = None,
    dense: np.ndarray | None = None,
) -> WindowLayout:
    """:func:`assign_windows` and the Savitzky–Golay validity of
    :func:`transforms.derivatives.savgol_valid` for the time stamps (µs since the epoch, int64) of
    **one valve**, at the rows a window of n samples is evaluated on: every k-th row from its
    first, k = max(1, n // ``window_rows``) (:class:`transforms.params.MonitorParams`
    ``window_rows``; None: every row), every row of the windows ``dense`` flags (one bool per
    window; :func:`transforms.monitor.thinning_short`). One compiled pass over the time stamps
    (which also checks their order: :class:`UnsortedTimes` if they are not sorted), the rest over
    the evaluated rows.
    """
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    if gap_limit_s is None:
        gap_limit_s = 3.0 * sample_period_s
    if gap_limit_s < sample_period_s * (1.0 + step_tolerance):
        raise ValueError("gap_limit_s must exceed the sample period (plus tolerance)")
    period_us = sample_period_s * 1e6
    t_us = read_only(np.ascontiguousarray(timestamp_us, dtype=np.int64))
    irregular, gaps = _gap_rows(t_us, period_us * (1.0 - step_tolerance), period_us * (1.0 + step_tolerance), float(gap_limit_s * 1e6))
    starts = _starts_kernel(t_us, gaps, window_length_us(window_s))
    flags = np.zeros(0, dtype=np.bool_) if dense is None else np.ascontiguousarray(dense, dtype=np.bool_)
    count, stride, rows, win, valid = _layout_kernel(t_us.shape[0], starts, irregular, int(half_window), int(window_rows or 0), flags)
    return WindowLayout(starts, count, stride, rows, win, valid)

"""One tag's samples → sorted, de-duplicated, gaps found, and put on the lake's uniform grid.

Order of operations for each tag (:func:`prepare_tag`):

1. **Sort** by time (stable, so rows with the same time keep their file order).
2. **Duplicates.** Rows with the same time *and* value are exact duplicates: one is kept,
   the others counted in ``duplicates``. Rows with the same time and different values are
   *conflicts*, resolved by ``export.duplicate_rule``: ``"last"`` keeps the value of the last
   such row in file order, ``"first"`` the first, ``"error"`` refuses the export naming the
   tag, the time and the lines. Every value that loses is counted in ``conflicts``.
3. **Gaps.** Consecutive samples further apart than ``export.max_gap_s`` are a gap: it is
   recorded (last sample before, first sample after) and splits the tag into *segments*.
4. **Grid** (:func:`to_grid`). The lake's grid is every whole multiple of the sample period
   ``T = 1 / export.sample_rate_hz`` since the Unix epoch (UTC), in µs. Each segment yields
   the grid instants within ``[first sample, last sample]``; the value at a grid instant ``g``
   is the sample's own value if one lies exactly at ``g`` (so an exactly gridded export comes
   out bit-identical), else the linear interpolation in time between the two samples that
   bracket ``g`` (both in the same segment, so never across a gap). Nothing is extrapolated:
   grid instants before a segment's first or after its last sample are not produced.

Times are int64 nanoseconds (UTC) throughout, so the 100 ns resolution of PI timestamps is kept
until the grid; interpolation weights are formed from integer differences.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone

import numba
import numpy as np

from transforms.ingest.errors import IngestError

NS_PER_US = 1_000


@dataclass(frozen=True)
class Grid:
    """The lake's uniform time grid and the gap limit."""

    period_us: int
    """Sample period, a whole number of microseconds."""
    max_gap_ns: int
    """Samples further apart than this are a gap."""

    @classmethod
    def from_export(cls, sample_rate_hz: float, max_gap_s: float) -> Grid:
        """Grid of ``export.sample_rate_hz`` and ``export.max_gap_s``.

        Raises
        ------
        IngestError
            If the sample period is not a whole number of microseconds (the lake's timestamps
            are µs, so such a grid could not be uniform).
        """
        period = 1e6 / sample_rate_hz
        period_us = round(period)
        if period_us < 1 or abs(period - period_us) > 1e-6 * period:
            raise IngestError(
                f"export.sample_rate_hz = {sample_rate_hz:g} Hz gives a sample period of {period:g} µs; "
                "the lake's grid needs a whole number of microseconds (e.g. 1000, 2000, 2500, 4000, 5000 Hz)"
            )
        return cls(period_us, int(round(max_gap_s * 1e9)))

    @property
    def period_ns(self) -> int:
        return self.period_us * NS_PER_US


@dataclass
class TagSeries:
    """One tag's accepted samples, sorted by time and without duplicate times."""

    t_ns: np.ndarray
    values: np.ndarray
    duplicates: int
    conflicts: int


def _iso(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S") + f".{t_ns % 1_000_000_000:09d}Z"


_INCREASING, _NONDECREASING, _UNSORTED = 0, 1, 2


@numba.njit(cache=True, nogil=True)
def _order_state(t_ns: np.ndarray) -> int:
    """Whether the times strictly increase, never decrease (some repeat), or are out of order;
    one pass."""
    state = _INCREASING
    for i in range(1, len(t_ns)):
        if t_ns[i] < t_ns[i - 1]:
            return _UNSORTED
        if t_ns[i] == t_ns[i - 1]:
            state = _NONDECREASING
    return state


@numba.njit(cache=True, nogil=True)
def _grid_scan(t_ns: np.ndarray, period_ns: int, max_gap_ns: int) -> tuple[np.ndarray, int, bool]:
    """One pass over sorted, unique times: the times in µs, the number of gaps, and whether every
    time is a grid instant with no grid instant missing inside a segment."""
    n = len(t_ns)
    t_us = np.empty(n, dtype=np.int64)
    n_breaks = 0
    gridded = t_ns[0] % period_ns == 0
    t_us[0] = t_ns[0] // NS_PER_US
    for i in range(1, n):
        t_us[i] = t_ns[i] // NS_PER_US
        d = t_ns[i] - t_ns[i - 1]
        if d > max_gap_ns:
            n_breaks += 1
            if t_ns[i] % period_ns != 0:
                gridded = False
        elif d != period_ns:
            gridded = False
    return t_us, n_breaks, gridded


def prepare_tag(t_ns: np.ndarray, values: np.ndarray, lines, rule: str, tag: str = "") -> TagSeries:
    """Sort one tag's samples by time and resolve samples at the same time (module doc, 1–2).

    Parameters
    ----------
    t_ns, values : ndarray
        Times (int64 ns, UTC) and SI values, in file order.
    lines : ndarray or callable
        Source line of each sample, or a function returning them (called only when needed).
    rule : str
        ``export.duplicate_rule``: ``"last"``, ``"first"`` or ``"error"``.
    tag : str
        The tag's name, for the error message.
    """
    order = None
    state = _order_state(t_ns)
    if state == _UNSORTED:
        order = np.argsort(t_ns, kind="stable")
        t_ns, values = t_ns[order], values[order]
    if state == _INCREASING:
        return TagSeries(t_ns, values, 0, 0)
    same = t_ns[1:] == t_ns[:-1]
    if not same.any():
        return TagSeries(t_ns, values, 0, 0)
    # runs of equal times: run id per sample; only the samples in runs of length > 1 need work
    starts = np.flatnonzero(np.r_[True, ~same])
    run = np.cumsum(np.r_[True, ~same]) - 1
    run_len = np.diff(np.r_[starts, len(t_ns)])
    in_multi = run_len[run] > 1
    idx = np.flatnonzero(in_multi)
    r, v = run[idx], values[idx]
    # exact duplicates: same run and same value as an earlier sample of the run
    by_value = np.lexsort((idx, v, r))
    rv, vv = r[by_value], v[by_value]
    dup_sorted = np.r_[False, (rv[1:] == rv[:-1]) & (vv[1:] == vv[:-1])]
    duplicates = int(dup_sorted.sum())
    # distinct values per run: runs with more than one are conflicts
    distinct_per_run = np.bincount(rv[~dup_sorted], minlength=len(starts))
    conflicts = int(np.maximum(distinct_per_run - 1, 0).sum())
    if conflicts and rule == "error":
        lines = np.asarray(lines() if callable(lines) else lines)
        lines = lines if order is None else lines[order]
        bad_run = int(np.flatnonzero(distinct_per_run > 1)[0])
        members = np.flatnonzero(run == bad_run)
        shown = ", ".join(f"line {int(lines[m])} = {float(values[m])!r}" for m in members[:4])
        raise IngestError(
            f"{_iso(int(t_ns[members[0]]))} has different values ({shown}); export.duplicate_rule is 'error'",
            line=int(lines[members[0]]),
            tag=tag or None,
        )
    # keep one sample per run: the last (or first) in file order; after the stable sort the
    # samples of a run are in file order, so that is the run's last (or first) element
    if rule == "first":
        keep = starts
    else:
        keep = np.r_[starts[1:] - 1, len(t_ns) - 1]
    return TagSeries(t_ns[keep], values[keep], duplicates, conflicts)


@dataclass
class Gridded:
    """One tag on the grid."""

    t_us: np.ndarray
    """Grid instants, int64 µs since the epoch (UTC), increasing."""
    values: np.ndarray
    gap_start_ns: np.ndarray
    """Last sample before each gap."""
    gap_end_ns: np.ndarray
    """First sample after each gap."""


@dataclass
class GridTimes:
    """What the grid makes of one tag's times, whatever its values: :func:`grid_times`."""

    t_ns: np.ndarray
    t_us: np.ndarray
    gridded: bool
    """Every time is a grid instant and none is missing inside a segment: the samples are the grid."""
    breaks: np.ndarray
    """The samples after which a gap begins."""

    def same_times(self, t_ns: np.ndarray) -> bool:
        """Whether ``t_ns`` are these times (the tags of a wide export share them)."""
        return len(t_ns) == len(self.t_ns) and np.array_equal(t_ns, self.t_ns)


def grid_times(t_ns: np.ndarray, grid: Grid) -> GridTimes:
    """The grid's one pass over a tag's sorted, unique, non-empty times (module doc, 3)."""
    t_us, n_breaks, gridded = _grid_scan(t_ns, grid.period_ns, grid.max_gap_ns)
    breaks = np.flatnonzero(np.diff(t_ns) > grid.max_gap_ns) if n_breaks else np.zeros(0, dtype=np.int64)
    return GridTimes(t_ns, t_us, gridded, breaks)


def to_grid(t_ns: np.ndarray, values: np.ndarray, grid: Grid, times: GridTimes | None = None) -> Gridded:
    """Put one tag's sorted, unique samples on the grid (module doc, 3–4); ``times``: their
    :func:`grid_times`, when the caller has it already (another tag's at the same times)."""
    n = len(t_ns)
    if n == 0:
        e = np.zeros(0, dtype=np.int64)
        return Gridded(e, np.zeros(0), e, e)
    P = grid.period_ns
    times = times or grid_times(t_ns, grid)
    breaks = times.breaks
    gap_start, gap_end = t_ns[breaks], t_ns[breaks + 1]
    if times.gridded:  # exactly gridded and nothing missing inside a segment: the samples are the grid
        return Gridded(times.t_us, values, gap_start, gap_end)
    seg_first = np.r_[0, breaks + 1]
    seg_last = np.r_[breaks, n - 1]
    k_lo = -((-t_ns[seg_first]) // P)  # ceil: first grid instant at or after the segment's start
    k_hi = t_ns[seg_last] // P  # floor: last grid instant at or before its end
    counts = np.maximum(k_hi - k_lo + 1, 0)
    total = int(counts.sum())
    if total == 0:
        e = np.zeros(0, dtype=np.int64)
        return Gridded(e, np.zeros(0), gap_start, gap_end)
    # all grid indices of all segments, vectorised: k = k_lo[seg] + (position within segment)
    seg_of = np.repeat(np.arange(len(counts)), counts)
    offset = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    g = (k_lo[seg_of] + offset) * P
    i = np.searchsorted(t_ns, g, side="right") - 1  # t[i] <= g < t[i+1]
    hit = t_ns[i] == g
    out = values[i].copy()
    miss = np.flatnonzero(~hit)
    if len(miss):
        a = i[miss]
        t0, t1 = t_ns[a], t_ns[a + 1]
        w = (g[miss] - t0).astype(np.float64) / (t1 - t0).astype(np.float64)
        v0, v1 = values[a], values[a + 1]
        out[miss] = v0 + w * (v1 - v0)
    return Gridded(g // NS_PER_US, out, gap_start, gap_end)

"""Raw-data retention: which lake partition may be thinned or dropped, and what thinning keeps.

Pure decisions on numbers the flow (:mod:`flows.retention.flow`) reads from the lake and the
warehouse; ``docs/warehouse.md``, "Retention", gives the reasons. A partition (one valve, one UTC
date) is acted on only when all of these hold, checked in this order (the first that fails is
the reason it is kept):

1. it is older than ``keep_days``: ``(as_of − date) > keep_days`` days;
2. its date does not touch the valve's commissioning ``baseline_window`` (the baseline is fitted
   from that data; a changed baseline definition refits it);
3. every sample lies inside a window the monitor has fitted (a row of ``edge_fits``,
   ``window_start <= t <= window_end``): "once their fits exist", checked sample by sample, so
   it holds whatever the monitor's window rule (:func:`uncovered_samples`);
4. the report's standstill check (Eq. 9) has read past its last sample
   (``standstill_progress.checked_through``);
5. thin mode only: thinning would remove something (a thinned partition is left alone, so
   applying retention twice is applying it once).

Thinning keeps, in every UTC hour that has data, the samples less than ``thin_keep_s_per_hour``
after the hour's first sample (:func:`thin_mask`): a continuous hour keeps its first 10 s, a
periodic 10 s snapshot stays whole wherever in the hour it was taken.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone

import numpy as np

from schemas.plant_config import RetentionSpec

HOUR_US = 3_600_000_000
"""One hour in µs (thinning works on UTC hours)."""

KEEP = "keep"

REASON_RECENT = "kept: within {keep_days} days"
REASON_COMMISSIONING = "kept: commissioning window"
REASON_NO_FITS = "kept: no fits yet"
REASON_PART_FITTED = "kept: not all windows fitted yet"
REASON_UNCHECKED = "kept: standstill check not yet run"
REASON_THINNED = "kept: already thinned"


@dataclass(frozen=True)
class Decision:
    """What retention does to one partition: ``action`` drop, thin or keep, and why."""

    action: str
    reason: str


def age_days(day: date, as_of: date) -> int:
    """Whole days from a partition's date to the reference date. [d]"""
    return (as_of - day).days


def protected_days(windows: list[tuple[datetime, datetime]]) -> frozenset[date]:
    """The UTC dates any of the windows ``[start, end)`` touches (a commissioning
    ``baseline_window``'s days: the monitor reads it as ``start <= t < end``)."""
    days: set[date] = set()
    for start, end in windows:
        d = start.astimezone(timezone.utc).date()
        last = (end.astimezone(timezone.utc) - timedelta(microseconds=1)).date()
        while d <= last:
            days.add(d)
            d += timedelta(days=1)
    return frozenset(days)


def fitted_cover(starts_us: np.ndarray, ends_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fitted windows ``[start, end]`` (µs) as sorted starts and the running maximum of their
    ends, the form :func:`uncovered_samples` searches."""
    s = np.asarray(starts_us, dtype=np.int64)
    e = np.asarray(ends_us, dtype=np.int64)
    order = np.argsort(s, kind="stable")
    return s[order], np.maximum.accumulate(e[order]) if e.size else e


def is_sorted(t: np.ndarray) -> bool:
    """Whether the time stamps never decrease (a lake file's do: it is sorted by time)."""
    return bool(np.all(t[1:] >= t[:-1]))


def uncovered_samples(t_us: np.ndarray, cover: tuple[np.ndarray, np.ndarray], *, sorted_: bool | None = None) -> int:
    """How many of the time stamps (µs, any order; ``sorted_``: whether they are sorted, None:
    look) lie in no fitted window of ``cover`` (:func:`fitted_cover`). Sorted time stamps are
    counted per run of overlapping windows by two binary searches, not looked up one by one."""
    starts, max_ends = cover
    t = np.asarray(t_us, dtype=np.int64)
    if starts.size == 0:
        return int(t.size)
    if sorted_ if sorted_ is not None else is_sorted(t):
        # windows overlapping the ones before them (start <= the running maximum of the ends) join their run
        first = np.flatnonzero(np.r_[True, starts[1:] > max_ends[:-1]])
        lo, hi = starts[first], max_ends[np.r_[first[1:] - 1, starts.size - 1]]
        return int(t.size - (np.searchsorted(t, hi, side="right") - np.searchsorted(t, lo, side="left")).sum())
    i = np.searchsorted(starts, t, side="right") - 1
    inside = (i >= 0) & (t <= max_ends[np.maximum(i, 0)])
    return int(t.size - np.count_nonzero(inside))


def hour_firsts(t_us: np.ndarray, *, sorted_: bool | None = None) -> dict[int, int]:
    """UTC hour (µs since the epoch // 1 h) → its earliest time stamp, of time stamps in any order
    (``sorted_``: whether they are sorted, None: look)."""
    t = np.asarray(t_us, dtype=np.int64)
    if t.size == 0:
        return {}
    if sorted_ if sorted_ is not None else is_sorted(t):  # the lake's files are time-sorted: a binary search per hour
        hours = np.arange(t[0] // HOUR_US, t[-1] // HOUR_US + 1)
        if hours.size <= t.size:
            at = np.searchsorted(t, hours * HOUR_US, side="left")  # < t.size: every hour starts by t[-1]
            have = t[at] // HOUR_US == hours
            return dict(zip(hours[have].tolist(), t[at[have]].tolist()))
        hours = t // HOUR_US
        at = np.r_[0, np.flatnonzero(np.diff(hours)) + 1]
        return dict(zip(hours[at].tolist(), t[at].tolist()))
    hours = t // HOUR_US
    hours, inverse = np.unique(hours, return_inverse=True)
    firsts = np.full(hours.size, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(firsts, inverse, t)
    return dict(zip(hours.tolist(), firsts.tolist()))


def merge_hour_firsts(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    """The earliest time stamp per hour of two parts of a partition."""
    out = dict(a)
    for h, t in b.items():
        out[h] = min(out.get(h, t), t)
    return out


def thin_mask(t_us: np.ndarray, firsts: dict[int, int], keep_s: float) -> np.ndarray:
    """True for the samples thinning keeps: less than ``keep_s`` after the first sample of their
    UTC hour (``firsts`` from :func:`hour_firsts` over the whole partition). [s]"""
    t = np.asarray(t_us, dtype=np.int64)
    hours = t // HOUR_US
    known = np.array(sorted(firsts), dtype=np.int64)
    first = np.array([firsts[h] for h in known.tolist()], dtype=np.int64)
    j = np.clip(np.searchsorted(known, hours), 0, max(known.size - 1, 0))
    if known.size == 0 or not np.array_equal(known[j], hours):
        raise ValueError("thin_mask: a time stamp's hour is missing from firsts")
    return t - first[j] < round(keep_s * 1e6)


def kept_ranges(t_us: np.ndarray, firsts: dict[int, int], keep_s: float) -> np.ndarray:
    """The rows :func:`thin_mask` keeps, as ``[start, stop)`` index ranges (an ``(n, 2)`` array,
    in order): for sorted time stamps one binary search per hour (at most a range an hour), for
    others the runs of the mask."""
    t = np.asarray(t_us, dtype=np.int64)
    if t.size == 0:
        return np.zeros((0, 2), np.int64)
    if not is_sorted(t):
        keep = np.r_[False, thin_mask(t, firsts, keep_s), False].astype(np.int8)
        edges = np.flatnonzero(np.diff(keep))
        return edges.reshape(-1, 2).astype(np.int64)
    hours = np.array(sorted(hour_firsts(t, sorted_=True)), dtype=np.int64)
    if any(h not in firsts for h in hours.tolist()):
        raise ValueError("kept_ranges: a time stamp's hour is missing from firsts")
    first = np.array([firsts[h] for h in hours.tolist()], dtype=np.int64)
    # an hour's samples are the partition's from its first on, so it keeps [hour start, first + keep_s) of them
    stop = np.minimum(first + round(keep_s * 1e6), (hours + 1) * HOUR_US)
    ranges = np.stack([np.searchsorted(t, hours * HOUR_US, side="left"), np.searchsorted(t, stop, side="left")], axis=1)
    return ranges[ranges[:, 1] > ranges[:, 0]]


def kept_row_groups(spans: list[tuple[int, int, int]], firsts: dict[int, int], keep_s: float) -> list[int]:
    """Indices of the row groups ``(rows, first µs, last µs)`` that can hold a sample thinning
    keeps: those whose time range meets some ``[hour's first, + keep_s)``. The others need not be
    read (a continuous hour spans ~4 row groups; its first seconds lie in one)."""
    f = np.array(sorted(firsts.values()), dtype=np.int64)
    keep_us = round(keep_s * 1e6)
    out = []
    for i, (_, lo, hi) in enumerate(spans):
        # the kept intervals are disjoint and sorted: only the last one starting by ``hi`` can reach ``lo``
        j = int(np.searchsorted(f, hi, side="right")) - 1
        if j >= 0 and f[j] + keep_us > lo:
            out.append(i)
    return out


@dataclass
class PartitionScan:
    """What a pass over one partition's time stamps found (filled batch by batch with :meth:`add`)."""

    cover: tuple[np.ndarray, np.ndarray]
    hours: bool = True
    """Track each hour's first sample (thin mode needs it, drop mode does not)."""
    rows: int = 0
    uncovered: int = 0
    last_us: int | None = None
    firsts: dict[int, int] = field(default_factory=dict)
    rows_kept: int | None = None
    """Rows thinning would keep (a second pass, :meth:`count_kept`; None until then)."""

    def add(self, t_us: np.ndarray) -> None:
        """Account for one batch of the partition's time stamps (µs)."""
        t = np.asarray(t_us, dtype=np.int64)
        if t.size == 0:
            return
        ordered = is_sorted(t)
        self.rows += int(t.size)
        self.uncovered += uncovered_samples(t, self.cover, sorted_=ordered)
        top = int(t[-1] if ordered else t.max())
        self.last_us = top if self.last_us is None else max(self.last_us, top)
        if self.hours:
            self.firsts = merge_hour_firsts(self.firsts, hour_firsts(t, sorted_=ordered))

    def count_kept(self, t_us: np.ndarray, keep_s: float) -> np.ndarray:
        """Second pass: count the rows of a batch that thinning keeps; returns them as index
        ranges into the batch (:func:`kept_ranges`)."""
        ranges = kept_ranges(t_us, self.firsts, keep_s)
        self.rows_kept = (self.rows_kept or 0) + int((ranges[:, 1] - ranges[:, 0]).sum())
        return ranges


def decide_unscanned(day: date, as_of: date, spec: RetentionSpec, protected: frozenset[date]) -> Decision | None:
    """Steps 1–2 of the module doc, which need no data: a keep decision, or None (read the partition)."""
    if age_days(day, as_of) <= spec.keep_days:
        return Decision(KEEP, REASON_RECENT.format(keep_days=spec.keep_days))
    if day in protected:
        return Decision(KEEP, REASON_COMMISSIONING)
    return None


def decide_fitted(scan: PartitionScan, checked_through_us: int | None) -> Decision | None:
    """Steps 3–4 of the module doc on a first pass's :class:`PartitionScan`: a keep decision, or
    None. ``checked_through_us`` None: the standstill check has never read this valve."""
    if scan.rows and scan.uncovered == scan.rows:
        return Decision(KEEP, REASON_NO_FITS)
    if scan.uncovered:
        return Decision(KEEP, REASON_PART_FITTED)
    if scan.last_us is not None and (checked_through_us is None or checked_through_us < scan.last_us):
        return Decision(KEEP, REASON_UNCHECKED)
    return None


def decide(day: date, as_of: date, spec: RetentionSpec, protected: frozenset[date], scan: PartitionScan | None, checked_through_us: int | None) -> Decision:
    """The decision for one partition (module doc): steps 1–2, then (``scan`` needed) 3–4, then
    (thin mode, ``scan.rows_kept`` needed) 5."""
    early = decide_unscanned(day, as_of, spec, protected)
    if early is not None:
        return early
    if scan is None:
        raise ValueError(f"partition {day}: a scan is needed to decide")
    blocked = decide_fitted(scan, checked_through_us)
    if blocked is not None:
        return blocked
    why = f"fitted, checked and older than {spec.keep_days} days"
    if spec.mode == "drop":
        return Decision("drop", f"drop: {why}")
    if scan.rows_kept is None:
        raise ValueError(f"partition {day}: thin mode needs the kept rows counted")
    if scan.rows_kept == scan.rows:
        return Decision(KEEP, REASON_THINNED)
    return Decision("thin", f"thin: {why}")

"""Eq. 9 at standstill, per monitoring window, from a valve's lake rows (table ``standstill_checks``).

Where the cylinder stands still with the spool near its centre, the paper's Eq. 9 compares
(p1 − pr)/(ps − p1) with (ps − p2)/(p2 − pr); with pr ≈ 0 this is p1 + p2 = ps. It is a quick
indicator that needs no fit: a healthy valve of Table 1 rests near a residual of −0.17 (not 0:
model.md, the radial clearance acts like unequal extra underlaps on the two ports), the paper's
broken edge 1r near −1.4. The report compares it with the value the valve's design gives at
rest (:func:`flows.report.standstill.expected_residual`) against a tolerance (``bounds.eq9_tolerance``).

A sample counts as standstill when

* the cylinder velocity, a central difference of X over ±``VELOCITY_HALF_SPAN_S``, is below
  ``STANDSTILL_VELOCITY_M_S`` in magnitude,
* the spool is within ``STANDSTILL_SPOOL_M`` of centre (Eq. 9 assumes x ≈ 0: the healthy rest
  position is −0.036 mm inside the 0.04 mm underlap, the broken one +0.01 mm),
* both conditions have held for ``SETTLE_S`` already (the chamber pressures have settled), and
* ps > p1 and p2 > pr (the ratios are defined).

A window with at least ``MIN_SAMPLES`` such samples gives one row: the medians of the pressures,
of x and of the per-sample residual. The samples are picked in one compiled pass over the
window's rows (:func:`standstill_samples`); the medians are taken over the picked samples only.
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numba
import numpy as np
import polars as pl

from schemas.fields import STANDSTILL_FIELDS, polars_schema
from transforms.windows import window_starts

STANDSTILL_VELOCITY_M_S = 1e-3
"""|dX/dt| below this is standstill (the monitor's step-3 rule uses 5 mm/s to drop data; Eq. 9
needs the cylinder truly at rest). [m/s]"""
VELOCITY_HALF_SPAN_S = 0.01
"""Half span of the central difference for dX/dt (averages position noise over 20 ms). [s]"""
STANDSTILL_SPOOL_M = 0.1e-3
"""|x| below this is "x close to 0" (paper Sec. 5.1). [m]"""
SETTLE_S = 0.2
"""How long standstill must have lasted before samples count (pressure transients decay). [s]"""
MIN_SAMPLES = 100
"""Fewest standstill samples for a window's row."""
STANDSTILL_COLUMNS: tuple[str, ...] = ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")
"""The lake columns Eq. 9 reads (besides ``timestamp_utc`` and ``valve_id``)."""


@numba.njit(cache=True)
def _standstill_kernel(t_us, starts, x_cyl, x_spool, ps, pr, p1, p2, v_max, x_max, half_span_s, settle_s, min_samples):
    """For each window [starts[w], starts[w + 1]): mark its standstill samples in ``use`` and
    set ``ok[w]`` when it has at least ``min_samples`` of them. The arithmetic is the numpy
    definition's, operation for operation (float32 signals, float64 time and velocity)."""
    n_windows = starts.size - 1
    use = np.zeros(t_us.size, np.bool_)
    ok = np.zeros(n_windows, np.bool_)
    for w in range(n_windows):
        a = starts[w]
        m = starts[w + 1] - a
        if m < min_samples:
            continue
        steps = np.empty(m - 1)
        for i in range(m - 1):
            steps[i] = t_us[a + i + 1] * 1e-6 - t_us[a + i] * 1e-6
        dt = _median(steps)
        k = max(1, int(round(half_span_s / dt)))
        if m <= 2 * k:
            continue
        age = 0
        count = 0
        for i in range(m):
            j = a + i
            still = False
            if k <= i < m - k and abs(x_spool[j]) < x_max:
                v = (x_cyl[j + k] - x_cyl[j - k]) / (t_us[j + k] * 1e-6 - t_us[j - k] * 1e-6)
                still = abs(v) < v_max
            age = age + 1 if still else 0
            if age * dt >= settle_s and ps[j] > p1[j] and p2[j] > pr[j]:
                use[j] = True
                count += 1
        ok[w] = count >= min_samples
    return use, ok


@numba.njit(cache=True)
def _select(a, k):
    """The k-th smallest of ``a`` (reordered in place: Hoare's quickselect; a small kernel that
    compiles in a fraction of numba's ``np.median``)."""
    lo, hi = 0, a.size - 1
    while hi > lo:
        pivot = a[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return a[k]
    return a[k]


@numba.njit(cache=True)
def _median(v):
    """numpy's median of a float array (of an even count the two middle values' sum in the
    array's dtype, halved), ``v`` reordered."""
    h = v.size // 2
    upper = _select(v, h)
    if v.size % 2:
        return upper
    return (v[:h].max() + upper) / 2


def standstill_samples(t_us: np.ndarray, starts: np.ndarray, cols: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The standstill samples (module doc) of the windows ``[starts[w], starts[w + 1])`` of one
    valve's rows: a mask over the rows and, per window, whether it has at least
    :data:`MIN_SAMPLES` of them. ``t_us`` µs since the epoch; ``cols`` the
    :data:`STANDSTILL_COLUMNS` (float32 as in the lake, or float64) in SI."""
    x_spool = cols["x_spool_m"]
    return _standstill_kernel(
        np.ascontiguousarray(t_us, np.int64), np.ascontiguousarray(starts, np.int64), cols["x_cyl_m"], x_spool,
        cols["ps_pa"], cols["pr_pa"], cols["p1_pa"], cols["p2_pa"],
        STANDSTILL_VELOCITY_M_S, x_spool.dtype.type(STANDSTILL_SPOOL_M), VELOCITY_HALF_SPAN_S, SETTLE_S, MIN_SAMPLES,
    )  # fmt: skip


@numba.njit(cache=True)
def _medians_kernel(use, starts, windows, ps, pr, p1, p2, x_spool):
    """Per window of ``windows``: its picked samples' count and the medians of ps, pr, p1, p2, x
    and of the per-sample Eq. 9 residual (computed in the signals' dtype, as numpy does)."""
    n = np.zeros(windows.size, np.int64)
    out = np.empty((windows.size, 6))
    for row in range(windows.size):
        a = starts[windows[row]]
        at = np.flatnonzero(use[a:starts[windows[row] + 1]]) + a
        n[row] = at.size
        q = np.empty((6, at.size), ps.dtype)
        for i in range(at.size):
            j = at[i]
            q[0, i], q[1, i], q[2, i], q[3, i], q[4, i] = ps[j], pr[j], p1[j], p2[j], x_spool[j]
            q[5, i] = (p1[j] - pr[j]) / (ps[j] - p1[j]) - (ps[j] - p2[j]) / (p2[j] - pr[j])
        for c in range(6):
            out[row, c] = _median(q[c])
    return n, out


def _array(col: pl.Series) -> np.ndarray:
    """A column as one read-only numpy array (as polars gives a single chunk; one compiled
    signature of the kernels): each chunk as a view, joined in one copy (a chunk carried over from
    the previous read makes two; polars' own rechunk is ~2x slower)."""
    if col.n_chunks() == 1:
        return col.to_numpy()
    out = np.concatenate([c.to_numpy() for c in col.get_chunks()])
    out.setflags(write=False)
    return out


def standstill_rows(
    frame: pl.DataFrame, *, max_gap_s: float, commissioned: datetime, computed_at: datetime, window_s: float | None = None
) -> pl.DataFrame:
    """Eq. 9 rows (:data:`schemas.fields.STANDSTILL_FIELDS`) of one valve's lake rows.

    ``frame`` is the canonical sensor frame of one valve, sorted by time; windows are the
    monitor's: runs without a gap longer than ``max_gap_s``, cut by the clock every ``window_s``
    (:func:`transforms.windows.window_starts`; None: whole runs).
    """
    schema = polars_schema(STANDSTILL_FIELDS)
    if frame.height < 2:
        return pl.DataFrame(schema=schema)
    valve_id = frame["valve_id"][0]
    t_us = _array(frame["timestamp_utc"].dt.epoch("us"))
    starts = np.r_[window_starts(t_us, max_gap_s * 1e6, window_s), t_us.size]
    cols = {c: _array(frame[c]) for c in STANDSTILL_COLUMNS}
    use, ok = standstill_samples(t_us, starts, cols)
    windows = np.flatnonzero(ok)
    if windows.size == 0:
        return pl.DataFrame(schema=schema)
    n, medians = _medians_kernel(use, starts, windows, *(cols[c] for c in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m")))
    first = t_us[starts[windows]]
    since = first - int((commissioned - EPOCH) / timedelta(microseconds=1))
    return pl.DataFrame({
        "valve_id": valve_id,
        "window_start": pl.Series(first).cast(pl.Datetime("us", "UTC")),
        "window_end": pl.Series(t_us[starts[windows + 1] - 1]).cast(pl.Datetime("us", "UTC")),
        "operating_hours": since / 1e6 / 3600.0,
        "n_samples": n,
        **{name: medians[:, j] / 1e5 for j, name in enumerate(("ps_bar", "pr_bar", "p1_bar", "p2_bar"))},  # Pa to bar
        "x_spool_mm": medians[:, 4] * 1e3,
        "eq9_residual": medians[:, 5],
        "computed_at": computed_at,
    }).cast(dict(schema)).select(list(schema))  # fmt: skip


EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)

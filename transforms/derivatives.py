"""Step 2: Savitzky–Golay smoothing and first derivatives as polars expressions.

A Savitzky–Golay filter of length L = 2h + 1 and order p is a fixed weighted sum over the
centred stencil (the least-squares weights of scipy's ``savgol_coeffs``, computed here with
numpy: importing ``scipy.signal`` alone costs a command ~1 s), so over a uniform grid it is a weighted
``rolling_sum`` of the whole column. The stencil is never laid across a window boundary or an
irregular step: a row gets null unless its stencil [i − h, i + h] holds no ``run_start``
(:mod:`transforms.windows`) after its first sample, i.e. unless it has h samples of the same
uniform run on either side (two running sums of ``run_start``, O(n)). The result
is exact for polynomials in time of degree ≤ p (for odd p the centred derivative is even exact
for degree p + 1, its weights being those of order p + 1).

Outputs for the lake's signals (:data:`DEFAULT_OUTPUTS`):

| input     | smoothed          | first derivative |
|-----------|-------------------|------------------|
| p1_pa     | p1_smooth_pa      | dp1_dt_pa_s      |
| p2_pa     | p2_smooth_pa      | dp2_dt_pa_s      |
| x_cyl_m   | x_cyl_smooth_m    | v_cyl_m_s        |
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache

import numba
import numpy as np
import polars as pl

from transforms.arrays import float_array

__all__ = [
    "DEFAULT_OUTPUTS",
    "add_savgol",
    "savgol_arrays",
    "box_mean_at",
    "box_mean_expr",
    "box_weights",
    "savgol_at",
    "savgol_exprs",
    "savgol_valid",
    "savgol_weights",
    "take_range",
    "stencil_at",
    "take_rows",
]

DEFAULT_OUTPUTS: dict[str, tuple[str | None, str | None]] = {
    "p1_pa": ("p1_smooth_pa", "dp1_dt_pa_s"),
    "p2_pa": ("p2_smooth_pa", "dp2_dt_pa_s"),
    "x_cyl_m": ("x_cyl_smooth_m", "v_cyl_m_s"),
}
"""input column → (smoothed column, derivative column); None skips one of the two."""


@lru_cache(maxsize=64)
def _weights(window: int, order: int, deriv: int) -> tuple[float, ...]:
    if window % 2 != 1 or window < 3:
        raise ValueError(f"window must be odd and >= 3, got {window}")
    if not 0 <= order < window:
        raise ValueError(f"order must be in [0, window), got {order}")
    # scipy.signal.savgol_coeffs(window, order, deriv, delta=1.0, use="dot"): w[0] multiplies the
    # oldest sample of the stencil, as rolling_sum's weights do. The least-squares polynomial of
    # degree `order` through the stencil, evaluated (its deriv-th derivative) at the centre: the
    # minimum-norm w with A w = deriv! e_deriv, A[k, j] = (j - h)^k.
    if deriv > order:
        return (0.0,) * window
    h = window // 2
    a = np.arange(-h, h + 1, dtype=float) ** np.arange(order + 1)[:, None]
    y = np.zeros(order + 1)
    y[deriv] = math.factorial(deriv)
    return tuple(float(v) for v in np.linalg.lstsq(a, y, rcond=None)[0])


def savgol_weights(window: int, order: int, deriv: int = 0) -> np.ndarray:
    """Stencil weights (oldest sample first) for unit sample spacing; divide a derivative by Δt."""
    return np.array(_weights(window, order, deriv))


def savgol_valid(window: int, box: int = 1) -> pl.Expr:
    """True where the centred stencil of ``window`` samples lies inside one uniform run:
    no run start in rows (i − h, i] nor in (i, i + h], and i + h within the frame (``box`` = k:
    the stencils of rows i … i + k − 1, :func:`savgol_at`'s: none in (i, i + k − 1 + h] either)."""
    h = window // 2
    run_start = pl.col("run_start").cast(pl.Int32)
    starts = run_start.rolling_sum(h, min_samples=1)  # starts in (i − h, i]
    ahead = starts.shift(-h) if box == 1 else run_start.rolling_sum(h + box - 1, min_samples=1).shift(-(h + box - 1))
    return ((starts == 0) & (ahead == 0)).fill_null(False)


def savgol_exprs(
    column: str,
    *,
    window: int,
    order: int,
    sample_period_s: float,
    smooth_name: str | None,
    deriv_name: str | None,
    valid: pl.Expr | None = None,
    mask: bool = True,
    nulls: bool = True,
    box: int = 1,
) -> list[pl.Expr]:
    """Expressions for the smoothed value and/or the first time derivative of ``column``
    (``box`` = k > 1: at row i the mean of those of rows i … i + k − 1, as :func:`savgol_at`'s).

    ``valid`` (default :func:`savgol_valid`) masks rows whose stencil would leave the run.
    ``mask=False`` returns the plain weighted sums over the whole column (null only in the first
    and last h rows): for callers that apply the validity themselves (the monitor's compiled
    path, which gets it from :func:`transforms.windows.window_arrays`).

    Missing input values (null or NaN) make every stencil that touches them null (with
    ``mask=False``: NaN). ``nulls=False`` promises an input without nulls and skips the
    null → NaN pass that polars' weighted ``rolling_sum`` needs.
    """
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    if valid is None and mask:
        valid = savgol_valid(window, box)
    col = pl.col(column)
    if nulls:  # polars' weighted rolling_sum rejects nulls; NaN propagates through the stencil
        col = col.fill_null(float("nan"))

    def stencil(deriv: int) -> pl.Expr:
        w = box_weights(np.array(_weights(window, order, deriv)), box)
        if box == 1:
            return col.rolling_sum(window, weights=list(w), center=True)
        return col.rolling_sum(w.shape[0], weights=list(w)).shift(-(w.shape[0] - 1 - window // 2))

    out: list[pl.Expr] = []
    if smooth_name is not None:
        e = stencil(0)
        out.append((pl.when(valid).then(e.fill_nan(None)) if mask else e).alias(smooth_name))
    if deriv_name is not None:
        e = stencil(1) * (1.0 / sample_period_s)
        out.append((pl.when(valid).then(e.fill_nan(None)) if mask else e).alias(deriv_name))
    return out


def box_mean_expr(column: str, box: int) -> pl.Expr:
    """The mean of ``column`` over rows i … i + box − 1 at row i, as :func:`box_mean_at`'s (null
    where that leaves the frame or meets a missing value)."""
    e = pl.col(column).fill_null(float("nan")).rolling_sum(box, weights=[1.0 / box] * box).shift(-(box - 1))
    return e.fill_nan(None)


def add_savgol(
    framed: pl.DataFrame | pl.LazyFrame,
    *,
    window: int,
    order: int,
    sample_period_s: float,
    outputs: Mapping[str, tuple[str | None, str | None]] = DEFAULT_OUTPUTS,
) -> pl.DataFrame | pl.LazyFrame:
    """Add smoothed values and derivatives to a frame carrying ``run_start``.

    The stencil validity is computed once (column ``_sg_valid``, dropped again) rather than per
    output: polars does not share the rolling sums of repeated sub-expressions."""
    valid = pl.col("_sg_valid")
    exprs: list[pl.Expr] = []
    for column, (smooth_name, deriv_name) in outputs.items():
        exprs += savgol_exprs(
            column,
            window=window,
            order=order,
            sample_period_s=sample_period_s,
            smooth_name=smooth_name,
            deriv_name=deriv_name,
            valid=valid,
        )
    return framed.with_columns(savgol_valid(window).alias("_sg_valid")).with_columns(exprs).drop("_sg_valid")


# --------------------------------------------------------------------------------------------
# compiled path (used by transforms.monitor for throughput)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _savgol_kernel(x, w0, w1, scale1, smooth, deriv, want_smooth):
    """Blocks of 512 outputs accumulated in local buffers: the stencil loop outside, a
    contiguous (vectorised) loop over the block inside; each output sums its stencil in the same
    order as polars' weighted rolling_sum (oldest sample first), so the two agree bit for bit."""
    n = x.shape[0]
    m = w1.shape[0]
    h = m // 2
    for i in range(min(h, n)):
        deriv[i] = np.nan
        if want_smooth:
            smooth[i] = np.nan
    for i in range(max(n - h, h), n):
        deriv[i] = np.nan
        if want_smooth:
            smooth[i] = np.nan
    block = 512
    acc0 = np.empty(block)
    acc1 = np.empty(block)
    for b0 in range(h, n - h, block):
        b1 = min(b0 + block, n - h)
        length = b1 - b0
        acc0[:length] = 0.0
        acc1[:length] = 0.0
        for k in range(m):
            a0 = w0[k]
            a1 = w1[k]
            xs = x[b0 - h + k : b1 - h + k]
            if want_smooth:
                for i in range(length):
                    v = xs[i]
                    acc0[i] += a0 * v
                    acc1[i] += a1 * v
            else:
                for i in range(length):
                    acc1[i] += a1 * xs[i]
        if want_smooth:
            smooth[b0:b1] = acc0[:length]
        for i in range(length):
            deriv[b0 + i] = acc1[i] * scale1


def savgol_arrays(x: np.ndarray, *, window: int, order: int, sample_period_s: float, smooth: bool = True):
    """The plain weighted sums of :func:`savgol_exprs` with ``mask=False`` over a float array,
    in one compiled pass: (smoothed or None, first derivative), NaN in the first and last h
    entries and wherever the stencil touches a NaN (the validity is the caller's, as there)."""
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    x = float_array(x)
    w0 = np.array(_weights(window, order, 0))
    w1 = np.array(_weights(window, order, 1))
    out0 = np.empty(x.shape[0]) if smooth else np.empty(0)
    out1 = np.empty(x.shape[0])
    _savgol_kernel(x, w0, w1, 1.0 / sample_period_s, out0, out1, bool(smooth))
    return (out0 if smooth else None), out1


@numba.njit(cache=True)
def _savgol_at_kernel(x, rows, w0, w1, lo, scale1, smooth, deriv, want_smooth):
    """The stencil sums of :func:`_savgol_kernel` at the given rows only (a stencil of m taps
    whose first is ``lo`` rows before its row: ``lo`` = h for a centred one), four rows at a time with
    their sums side by side in registers (independent sums: the additions of one row need not
    wait for each other's), each summed in the same order (oldest sample first, from 0.0), so
    the values are bit for bit those of the full pass."""
    n = x.shape[0]
    m = w1.shape[0]
    hi = n - (m - 1 - lo)  # a row i is inside where lo <= i < hi
    nr = rows.shape[0]
    if n < m:  # no stencil fits
        for r in range(nr):
            deriv[r] = np.nan
            if want_smooth:
                smooth[r] = np.nan
        return
    for r in range(0, nr, 4):
        q = min(4, nr - r)
        # a stencil that leaves the array (or a fourth row past the end) reads row lo instead
        # (its value is replaced by NaN or not stored)
        i0 = rows[r]
        i1 = rows[r + 1] if q > 1 else lo
        i2 = rows[r + 2] if q > 2 else lo
        i3 = rows[r + 3] if q > 3 else lo
        b0 = i0 - lo if lo <= i0 < hi else 0
        b1 = i1 - lo if lo <= i1 < hi else 0
        b2 = i2 - lo if lo <= i2 < hi else 0
        b3 = i3 - lo if lo <= i3 < hi else 0
        s0 = s1 = s2 = s3 = 0.0
        d0 = d1 = d2 = d3 = 0.0
        if want_smooth:
            for k in range(m):
                a0 = w0[k]
                a1 = w1[k]
                v0 = np.float64(x[b0 + k])
                v1 = np.float64(x[b1 + k])
                v2 = np.float64(x[b2 + k])
                v3 = np.float64(x[b3 + k])
                s0 += a0 * v0
                s1 += a0 * v1
                s2 += a0 * v2
                s3 += a0 * v3
                d0 += a1 * v0
                d1 += a1 * v1
                d2 += a1 * v2
                d3 += a1 * v3
        else:
            for k in range(m):
                a1 = w1[k]
                d0 += a1 * np.float64(x[b0 + k])
                d1 += a1 * np.float64(x[b1 + k])
                d2 += a1 * np.float64(x[b2 + k])
                d3 += a1 * np.float64(x[b3 + k])
        for j in range(q):
            i, s, d = (i0, s0, d0) if j == 0 else (i1, s1, d1) if j == 1 else (i2, s2, d2) if j == 2 else (i3, s3, d3)
            inside = lo <= i < hi
            deriv[r + j] = d * scale1 if inside else np.nan
            if want_smooth:
                smooth[r + j] = s if inside else np.nan


def box_weights(w: np.ndarray, box: int) -> np.ndarray:
    """The stencil ``w`` (oldest sample first) convolved with a ``box``-row mean: its value at row i
    is the mean of ``w``'s at rows i … i + box − 1 (box − 1 taps longer; ``w`` itself for box 1)."""
    return w if box == 1 else np.convolve(w, np.full(box, 1.0 / box))


def savgol_at(x, rows: np.ndarray, *, window: int, order: int, sample_period_s: float, smooth: bool = True, box: int = 1):
    """:func:`savgol_arrays` evaluated at ``rows`` only (int64 indices into ``x``): (smoothed or
    None, first derivative), one entry per row, equal bit for bit to the full pass's entries at
    those rows.

    ``box`` = k > 1: each entry is instead the mean of the full pass's entries at rows i … i + k − 1
    (one stencil of window + k − 1 taps, :func:`box_weights`): the row stands for the k rows up to
    the next evaluated one (NaN where that stencil leaves ``x``).

    ``x``: an array, or the chunks of one (a sequence of arrays, in order; ``rows`` then sorted):
    each chunk is read where it is, and only the stencils that reach across a chunk's end are
    summed over a joined copy of their few samples (a column decoded from Parquet comes in row
    groups: this spares joining them)."""
    if sample_period_s <= 0:
        raise ValueError("sample_period_s must be > 0")
    w0 = box_weights(np.array(_weights(window, order, 0)), box)
    w1 = box_weights(np.array(_weights(window, order, 1)), box)
    return stencil_at(x, rows, w0, w1, window // 2, 1.0 / sample_period_s, smooth)


def box_mean_at(x, rows: np.ndarray, box: int) -> np.ndarray:
    """The mean of ``x`` over rows i … i + box − 1 for each row i of ``rows`` (NaN where that
    leaves ``x``); ``x`` an array or its chunks, as for :func:`savgol_at`."""
    if box == 1:
        return take_rows([x] if isinstance(x, np.ndarray) else list(x), np.ascontiguousarray(rows, dtype=np.int64))
    return stencil_at(x, rows, np.empty(0), np.full(box, 1.0 / box), 0, 1.0, False)[1]


def stencil_at(x, rows: np.ndarray, w0: np.ndarray, w1: np.ndarray, before: int, scale1: float, smooth: bool):
    """The weighted sums of ``x`` (an array or its chunks) at ``rows`` over the stencils of
    weights ``w0`` (if ``smooth``) and ``w1`` × ``scale1``, whose first tap is ``before`` rows
    before the row: (sums by w0 or None, sums by w1), NaN where a stencil leaves ``x``."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    m = w1.shape[0]
    after = m - 1 - before
    out0 = np.empty(rows.shape[0]) if smooth else np.empty(0)
    out1 = np.empty(rows.shape[0])

    def run(xs, rs, r0, r1):  # the rows rows[r0:r1], at rs in the array xs
        _savgol_at_kernel(float_array(xs), rs, w0, w1, before, scale1, out0[r0:r1] if smooth else out0, out1[r0:r1], bool(smooth))

    chunks = [x] if isinstance(x, np.ndarray) else list(x)
    if len(chunks) == 1:
        run(chunks[0], rows, 0, rows.shape[0])
        return (out0 if smooth else None), out1
    offsets = np.concatenate([[0], np.cumsum([c.shape[0] for c in chunks])])
    n = int(offsets[-1])
    inside = np.zeros(rows.shape[0], dtype=np.bool_)
    for j, c in enumerate(chunks):
        # the rows whose stencil stays in chunk j (at the array's own ends the kernel's rule holds)
        a = offsets[j] + (before if j > 0 else 0)
        b = offsets[j + 1] - (after if j + 1 < len(chunks) else 0)
        r0, r1 = np.searchsorted(rows, [a, b])
        if r1 > r0:
            run(c, rows[r0:r1] - offsets[j], r0, r1)
            inside[r0:r1] = True
    rest = np.flatnonzero(~inside)
    # the others in clusters of rows less than a stencil apart, each over a copy of its samples
    cuts = np.flatnonzero(np.diff(rows[rest]) > m) + 1
    for part in np.split(rest, cuts):
        if part.size:
            a, b = max(0, int(rows[part[0]]) - before), min(n, int(rows[part[-1]]) + after + 1)
            r0, r1 = int(part[0]), int(part[-1]) + 1  # rest is sorted and the cluster contiguous in rows
            run(take_range(chunks, offsets, a, b), rows[r0:r1] - a, r0, r1)
    return (out0 if smooth else None), out1


def take_range(chunks, offsets: np.ndarray, a: int, b: int) -> np.ndarray:
    """Rows [a, b) of the array made of ``chunks`` (``offsets``: their first rows and the total), joined."""
    j0 = int(np.searchsorted(offsets, a, side="right")) - 1
    parts = []
    j = j0
    while j < len(chunks) and offsets[j] < b:
        parts.append(chunks[j][max(a - offsets[j], 0) : min(b - offsets[j], chunks[j].shape[0])])
        j += 1
    return np.concatenate(parts)


def take_rows(chunks, rows: np.ndarray) -> np.ndarray:
    """``x[rows]`` of the array ``x`` made of ``chunks`` (a sequence of arrays; ``rows`` sorted
    int64), without joining them."""
    if len(chunks) == 1:
        return chunks[0][rows]
    offsets = np.concatenate([[0], np.cumsum([c.shape[0] for c in chunks])])
    out = np.empty(rows.shape[0], dtype=chunks[0].dtype)
    bounds = np.searchsorted(rows, offsets)
    for j, c in enumerate(chunks):
        lo, hi = bounds[j], bounds[j + 1]
        if hi > lo:
            out[lo:hi] = c[rows[lo:hi] - offsets[j]]
    return out

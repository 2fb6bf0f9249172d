"""Step 4b, Eq. 8: scale α̂ and shift x̂ of the baseline Â, fitted to each population of points.

For a population (one window, one edge) of N points (u_i, A_i),

    e = min over (α̂, x̂) of sqrt( (1/N) Σ_i (A_i − α̂ Â(u_i + x̂))² ).

For fixed x̂ the best α̂ is closed-form, α̂(x̂) = Σ A_i Â_i / Σ Â_i², so the fit is a 1-D search
on the profile cost f(x̂) = Σ A_i² − (Σ A_i Â_i)² / Σ Â_i² (variable projection):

1. a coarse grid of x̂ over [−x_bound, x_bound] (25 points, 0.125 mm apart for the default
   1.5 mm) on an evenly strided subsample (≤ 96 points) of the population finds the basin of the
   global minimum;
2. a safeguarded Newton iteration on the full population converges to |Δx̂| < 1 nm; should it
   end on a bracket edge, the bracket moves on by a grid step. The derivatives are analytic for
   a piecewise-linear Â (Â″ = 0 between knots): with S_a = Σ A Â, S_b = Σ Â², S_ad = Σ A Â',
   S_bd = Σ Â Â', S_dd = Σ Â'², α = S_a/S_b,

       f'  = −2 α S_ad + 2 α² S_bd  (= the gradient of the cost at the optimal α̂: −2 α̂ Σ Â' r).

   Each step goes to the exact minimum of the cost with every point kept on its knot segment,
   where S_a and S_b are linear and quadratic in the shift δ and f′(δ) = 0 is linear:
   δ = (S_ad S_b − S_a S_bd) / (S_a S_dd − S_ad S_bd) (bisection when that is no descent or
   leaves the bracket). Without knot crossings this is the optimum in one step;
3. a step shorter than :data:`TRUST_STEP_M` (1 µm) is not checked by a pass of its own: the
   residual pass at its end takes the exact sums there too and confirms it when their step is
   below 1 nm, as a Newton pass would; else Newton goes on (~5 % of the windows). α̂, e and
   JᵀJ follow from the sums (Σ r² = Σ A² − α̂ S_a at the optimum).

The whole batch (every window and edge of every valve) runs in one compiled (numba) kernel,
one pass over a population's points per iteration (2–3 full passes in all from a warm start,
the residual pass included, plus the grid); during the Newton passes each point remembers its
knot segment, so evaluating Â costs a few nanoseconds whatever the number of knots.

Confidence intervals come from the Jacobian J = [Â(u_i + x̂), α̂ Â'(u_i + x̂)] at the optimum:
cov = σ² (JᵀJ)⁻¹ with σ² = Σ r² / (N − 2) and Student's t with N − 2 degrees of freedom. The
points of a window are serially correlated (the Savitzky–Golay stencil spans 21 samples, and
model error is smooth in time), which makes the i.i.d. formula too narrow; the half-widths are
therefore multiplied by ``ci_inflation`` = sqrt((1 + ρ)/(1 − ρ)), ρ the lag-1 autocorrelation of
the residuals in time order, clipped to [0, 0.98] (the AR(1) long-run variance factor; 1 for
independent residuals). It is a heuristic, reported per row.

Status of a row: ``ok``, or why there is no (trustworthy) estimate: ``no_points``,
``too_few_points`` (< min_points), ``too_little_coverage`` (u_max − u_min < min_coverage),
``no_baseline`` (no Â for the valve/edge), ``degenerate`` (Â vanishes or α̂ ≤ 0 at the points),
``x_hat_at_bound`` (optimum on the search bound; estimates reported), ``not_converged``
(iteration limit; estimates reported). ``iterations`` counts the full passes over the population
(Newton and the confirming residual pass).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numba
import numpy as np
import polars as pl

from transforms.characteristic import Characteristic
from transforms.arrays import read_only
from transforms.params import EDGES, MonitorParams

__all__ = [
    "FIT_COLUMNS",
    "STATUSES",
    "eq8_cost_gradient",
    "fit_arrays",
    "fit_groups",
    "fit_windows",
    "profile_cost",
    "sorted_fits",
]

STATUSES = (
    "ok",
    "no_points",
    "too_few_points",
    "too_little_coverage",
    "no_baseline",
    "degenerate",
    "x_hat_at_bound",
    "not_converged",
)

FIT_COLUMNS = (
    "valve_id",
    "window_id",
    "window_start",
    "window_end",
    "edge",
    "status",
    "n_points",
    "u_min_m",
    "u_max_m",
    "alpha_hat",
    "x_hat_m",
    "e_m2",
    "alpha_ci_low",
    "alpha_ci_high",
    "x_hat_ci_low_m",
    "x_hat_ci_high_m",
    "ci_inflation",
    "iterations",
    "u_spread_m",
    "x_hat_determined",
    "leak_scale",
    "leak_scale_ci_low",
    "leak_scale_ci_high",
    "leak_scale_held",
    "row_stride",
)
"""``leak_scale*``: the row's edge's closed-edge leakage scale λ (× Eq. 3's leakage at the edge's
state; identified from the other edge of its port, :mod:`transforms.leakage`) and its interval;
NaN without the closed-edge correction. ``leak_scale_held``: the window cannot resolve its own
leakage (its interval is wider than :data:`transforms.leakage.LEAK_RESOLUTION`), so
``leak_scale`` is the commissioning's, held (null without an estimate).

``row_stride``: the window's points are at every k-th row, each the mean of the k rows from it
(``MonitorParams.window_rows``; 1: every row); ``n_points`` × ``row_stride`` is the population's size in samples.

``u_spread_m``: the points' spread in u as the fit's covariance sees it; ``x_hat_determined``:
``u_spread_m`` ≥ :data:`X_HAT_MIN_SPREAD_M` (False without an estimate)."""

LEAK_COLUMNS = ("leak_scale", "leak_scale_ci_low", "leak_scale_ci_high")

# kernel result codes
_OK, _DEGENERATE, _AT_BOUND, _NOT_CONVERGED, _SKIPPED, _PREDICTED = 0, 1, 2, 3, 4, 5

X_HAT_MIN_SPREAD_M = 0.1e-3
"""x̂ is *determined* by a window only where its points spread over u by at least this (0.1 mm):
the spread as the fit's covariance sees it, ``u_spread_m`` = α̂ sqrt(det JᵀJ) / (α̂² Σ Â'²), the
standard deviation of u + x̂ on a straight Â and whatever the characteristic's intercept. Over
a shorter range the scale and the shift are confounded (the correlation of α̂ and x̂ then
depends on Â's intercept too: −0.998 on the reference plant's straight edges, beyond −0.9997 on
Eq. 3's curved ones in ordinary windows), and a point error that varies with u by a tenth of a
per cent per millimetre turns into micrometres of x̂: the reference plant's window over
u = 1.04–1.34 mm (spread 0.08 mm) read x̂ 2.1 µm (7 % of its 0.03 mm shift) off, its 95 %
interval ±0.5–1 µm. Such a window's α̂ and e stand; its x̂ is stored with its interval,
``x_hat_determined`` false, and the trends and the change detector leave it out
(docs/monitoring.md, "x̂ on any edge law")."""

TRUST_STEP_M = 1e-6
"""A Newton step shorter than this (1 µm, a fiftieth of the baseline's knot spacing) is not
checked by a pass of its own: the residual pass at its end confirms it (:func:`_fit_groups`)."""


# --------------------------------------------------------------------------------------------
# compiled core
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def walk_segment(kn, k0, k1, j, t):
    """The knot segment of t among kn[k0:k1], walked from segment j (neighbouring points in time
    order, or a shift barely moved: 0–1 steps, branch-predictable)."""
    while j > k0 and t < kn[j]:
        j -= 1
    while j < k1 - 2 and t >= kn[j + 1]:
        j += 1
    return j


@numba.njit(cache=True)
def _sums(u, a, jc, s, e, stride, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, mode):
    """One pass over points s, s+stride, … < e at shift x:
    S_a = Σ A Â, S_b = Σ Â², S_ad = Σ A Â', S_bd = Σ Â Â', S_dd = Σ Â'².

    Segment search: ``mode`` 0 = bucket table (large jumps of x: the coarse grid), 1 = bucket
    table and remember the segment of each point in ``jc``, 2 = walk from the remembered segment
    (the Newton steps barely move x, so the walk is 0–1 steps and branch-predictable).
    """
    sa = 0.0
    sb = 0.0
    sad = 0.0
    sbd = 0.0
    sdd = 0.0
    for i in range(s, e, stride):
        t = u[i] + x
        if mode == 2:
            j = walk_segment(kn, k0, k1, jc[i], t)
            jc[i] = j
        else:
            if t <= kn[k0]:
                j = k0
            elif t >= kn[k1 - 1]:
                j = k1 - 2
            else:
                b = int((t - tlo) * tinv)
                if b >= tn:
                    b = tn - 1
                j = tab[toff + b]
                while j < k1 - 2 and t >= kn[j + 1]:
                    j += 1
            if mode == 1:
                jc[i] = j
        d = ks[j]
        h = kv[j] + d * (t - kn[j])
        ai = a[i]
        sa += ai * h
        sb += h * h
        sad += ai * d
        sbd += h * d
        sdd += d * d
    return sa, sb, sad, sbd, sdd


@numba.njit(cache=True)
def _profile(u, a, jc, s, e, stride, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, mode, saa):
    """Profile cost f(x) = Σ A² − S_a²/S_b (α ≥ 0), f', f'' and α(x); ``good`` False where
    Â vanishes or α ≤ 0 at the points."""
    sa, sb, sad, sbd, sdd = _sums(u, a, jc, s, e, stride, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, mode)
    if sb <= 0.0 or sa <= 0.0:
        return saa, 0.0, 0.0, 0.0, False
    al = sa / sb
    f = saa - sa * al
    fp = -2.0 * al * sad + 2.0 * al * al * sbd
    alp = (sad - 2.0 * al * sbd) / sb
    fpp = -2.0 * alp * sad + 4.0 * al * alp * sbd + 2.0 * al * al * sdd
    return f, fp, fpp, al, True


@numba.njit(cache=True, inline="always")
def _locked_step(sa, sb, sad, sbd, sdd):
    """Exact minimiser of the profile cost with every point kept on its knot segment, as an
    offset from the point where the sums were taken (NaN if that is no descent): there
    S_a(δ) = S_a + δ S_ad, S_b(δ) = S_b + 2δ S_bd + δ² S_dd, and f′(δ) = 0 is linear in δ."""
    den = sa * sdd - sad * sbd
    if den > 0.0:
        return (sad * sb - sa * sbd) / den
    return np.nan


@numba.njit(cache=True, inline="always")
def _locked_sums(sa, sb, sad, sbd, sdd, d):
    """The sums δ = d further on, every point kept on its segment."""
    return sa + d * sad, sb + 2.0 * d * sbd + d * d * sdd, sad, sbd + d * sdd, sdd


@numba.njit(cache=True)
def _newton(u, a, jc, s, e, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, lo, hi, first_mode, xtol, trust, maxiter):
    """Safeguarded Newton on f′ within [lo, hi] from x, each step the exact minimiser of the
    segment-locked cost (:func:`_locked_step`; bisection when that leaves the bracket).

    Returns (x, code, passes, sums, dx): the last point evaluated, the sums
    (S_a, S_b, S_ad, S_bd, S_dd) there and the step still to take. On ``_OK`` |dx| < ``xtol``
    (the optimum is x + dx, its sums those at x moved on by dx with every point on its segment:
    exact up to the points that cross a knot within 1 nm); on ``_PREDICTED`` |dx| < ``trust``:
    the optimum is x + dx up to the few points that cross a knot on the way, for the caller to
    confirm in its residual pass. Otherwise the sums are zeros."""
    mode = first_mode
    zero = (0.0, 0.0, 0.0, 0.0, 0.0)
    for it in range(maxiter):
        sa, sb, sad, sbd, sdd = _sums(u, a, jc, s, e, 1, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, mode)
        mode = 2
        if sb <= 0.0 or sa <= 0.0:
            return x, _DEGENERATE, it + 1, zero, 0.0
        al = sa / sb
        fp = -2.0 * al * sad + 2.0 * al * al * sbd
        if fp < 0.0:
            lo = x
        else:
            hi = x
        step = _locked_step(sa, sb, sad, sbd, sdd)
        if abs(step) < xtol:
            # converged. Tested before the bracket: at the optimum f′ and the step are both ~0,
            # and their signs may disagree in the last bits, which put x + step just outside
            # [lo, hi] and sent the search into bisection away from the optimum.
            return x, _OK, it + 1, (sa, sb, sad, sbd, sdd), step
        xn = x + step
        locked = lo < xn < hi  # False for NaN
        if not locked:
            xn = 0.5 * (lo + hi)
        if abs(xn - x) < xtol:
            return x, _OK, it + 1, (sa, sb, sad, sbd, sdd), xn - x
        if locked and abs(xn - x) < trust:
            return x, _PREDICTED, it + 1, (sa, sb, sad, sbd, sdd), xn - x
        if hi - lo < xtol:
            return xn, _OK, it + 1, zero, 0.0  # sums not at xn
        x = xn
    return x, _NOT_CONVERGED, maxiter, zero, 0.0


@numba.njit(cache=True)
def _grid_start(u, a, s, e, stride, kn, kv, ks, k0, k1, x_first, step, n_grid):
    """Step 1: the grid point x_first + g·step (g < n_grid) of least profile cost on the strided
    subsample of the population (-1 if Â vanishes or α ≤ 0 at every one). The subsample is
    sorted by u first, so at each grid point the knot segment is found by walking forward."""
    m = (e - s + stride - 1) // stride
    us = np.empty(m)
    for k in range(m):
        us[k] = u[s + k * stride]
    order = np.argsort(us)
    us = us[order]
    aa = np.empty(m)
    saa = 0.0
    for k in range(m):
        aa[k] = a[s + order[k] * stride]
        saa += aa[k] * aa[k]
    best_g = -1
    best_f = np.inf
    j_first = k0
    for g in range(n_grid):
        x = x_first + g * step
        j = j_first
        sa = 0.0
        sb = 0.0
        for k in range(m):
            t = us[k] + x
            # t only grows (sorted u, increasing x): walk forward only, not walk_segment's both
            # ways (its extra test made the grid ~10 % slower: the innermost loop of the first fit)
            while j < k1 - 2 and t >= kn[j + 1]:
                j += 1
            if k == 0:
                j_first = j
            h = kv[j] + ks[j] * (t - kn[j])
            sa += aa[k] * h
            sb += h * h
        if sb > 0.0 and sa > 0.0:
            f = saa - sa * (sa / sb)
            if f < best_f:
                best_f = f
                best_g = g
    return best_g


@numba.njit(cache=True)
def _fit_one(u, a, jc, s, e, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, xb, n_grid, sub_max, xtol, trust, maxiter, x_start):
    """Returns (x, code, passes, sums at x or zeros, dx) as :func:`_newton` does. A finite
    ``x_start`` (a previous optimum of nearly the same population) replaces the coarse grid:
    Newton starts there, bracketed by one grid step on either side (moved on like any bracket
    if the optimum lies beyond)."""
    zero = (0.0, 0.0, 0.0, 0.0, 0.0)
    n = e - s
    stride = max(1, n // sub_max)
    step = 2.0 * xb / (n_grid - 1)
    if np.isfinite(x_start):
        x0 = min(max(x_start, -xb), xb)
    else:
        best_g = _grid_start(u, a, s, e, stride, kn, kv, ks, k0, k1, -xb, step, n_grid)
        if best_g < 0:
            return 0.0, _DEGENERATE, 0, zero, 0.0
        x0 = -xb + best_g * step
    lo = max(-xb, x0 - step)
    hi = min(xb, x0 + step)
    # 2. Newton on the full population inside the grid bracket; if it ends on a bracket edge that
    #    is not the search bound, the minimum lies beyond: move the bracket and go on
    passes = 0
    mode = 1
    x = x0
    for _expand in range(2 * n_grid):
        x, code, p, sums, dx = _newton(u, a, jc, s, e, kn, kv, ks, k0, k1, tab, toff, tlo, tinv, tn, x, lo, hi, mode, xtol, trust, maxiter)
        passes += p
        mode = 2
        if code != _OK and code != _PREDICTED:
            return x, code, passes, zero, 0.0
        xe = x + dx
        if xe - lo < 2.0 * xtol and lo > -xb:
            hi = lo
            lo = max(-xb, lo - step)
            x = 0.5 * (lo + hi)
            continue
        if hi - xe < 2.0 * xtol and hi < xb:
            lo = hi
            hi = min(xb, hi + step)
            x = 0.5 * (lo + hi)
            continue
        if xe - lo < 2.0 * xtol or hi - xe < 2.0 * xtol:
            return xe, _AT_BOUND, passes, zero, 0.0
        return x, code, passes, sums, dx
    return x, _NOT_CONVERGED, passes, zero, 0.0


@numba.njit(cache=True)
def _fit_groups(u, a, offsets, kstart, kend, kn, kv, ks, tab, tstart, tlo, tinv, tn, xbound, active, n_grid, sub_max, xtol, maxiter, x_start, residuals):
    g_n = offsets.shape[0] - 1
    alpha = np.full(g_n, np.nan)
    xhat = np.full(g_n, np.nan)
    ssr = np.full(g_n, np.nan)
    shh = np.full(g_n, np.nan)
    shd = np.full(g_n, np.nan)
    sdd = np.full(g_n, np.nan)
    rho = np.full(g_n, np.nan)
    code = np.full(g_n, _SKIPPED, dtype=np.int8)
    iters = np.zeros(g_n, dtype=np.int32)
    jc = np.zeros(u.shape[0], dtype=np.int64)
    for g in range(g_n):
        if not active[g]:
            continue
        s = offsets[g]
        e = offsets[g + 1]
        k0 = kstart[g]
        k1 = kend[g]
        toff, tlo_g, tinv_g, tn_g = tstart[g], tlo[g], tinv[g], tn[g]
        r2 = -1.0  # no residual pass yet
        r11 = saa = 0.0
        x, c, p, sums, dx = _fit_one(u, a, jc, s, e, kn, kv, ks, k0, k1, tab, toff, tlo_g, tinv_g, tn_g, xbound[g], n_grid,
                                     sub_max, xtol, TRUST_STEP_M, maxiter, x_start[g])  # fmt: skip
        if c == _PREDICTED and residuals:
            # the residual pass at the predicted optimum x + dx (α from the locked sums there)
            # also takes the exact sums there: if their step is below xtol, it is the last one
            # (as if Newton had made that pass); else Newton goes on from there, and the
            # residuals are taken again.
            x = x + dx
            ls = _locked_sums(sums[0], sums[1], sums[2], sums[3], sums[4], dx)
            al_p = ls[0] / ls[1] if ls[1] > 0.0 else 0.0
            r2, r11, saa, ex = _residual_pass(u, a, jc, s, e, kn, kv, ks, k0, k1, x, al_p)
            p += 1
            dx = _locked_step(ex[0], ex[1], ex[2], ex[3], ex[4])
            if abs(dx) < xtol:
                sums = ex
                c = _OK
            else:
                step = 2.0 * xbound[g] / (n_grid - 1)
                x, c, p2, sums, dx = _newton(u, a, jc, s, e, kn, kv, ks, k0, k1, tab, toff, tlo_g, tinv_g, tn_g, x,
                                             max(-xbound[g], x - step), min(xbound[g], x + step), 2, xtol, 0.0, maxiter)  # fmt: skip
                p += p2
                r2 = -1.0
        elif c == _PREDICTED:
            c = _OK
        iters[g] = p
        code[g] = c
        if c == _DEGENERATE:
            continue
        # α̂ and the JᵀJ pieces at the optimum x + dx (from the sums taken at x, else one more
        # pass), then the residuals: their sum of squares and lag-1 autocorrelation
        sa, sb, sad, sbd, sdd_ = sums
        if sb <= 0.0:
            sa, sb, sad, sbd, sdd_ = _sums(u, a, jc, s, e, 1, kn, kv, ks, k0, k1, tab, toff, tlo_g, tinv_g, tn_g, x, 2)
            dx = 0.0
        sa, sb, sad, sbd, sdd_ = _locked_sums(sa, sb, sad, sbd, sdd_, dx)
        x = x + dx
        if sb <= 0.0 or sa <= 0.0:
            code[g] = _DEGENERATE
            continue
        al = sa / sb
        alpha[g] = al
        xhat[g] = x
        if not residuals:
            continue
        if r2 < 0.0:
            r2, r11, saa, _ex = _residual_pass(u, a, jc, s, e, kn, kv, ks, k0, k1, x, al)
        # Σ r² at (α̂, x̂) from the sums (exact for the locked segments; the pass's own Σ r²
        # was taken at the predicted α, a hair away)
        ssr[g] = max(saa - al * sa, 0.0)
        shh[g] = sb
        shd[g] = al * sbd
        sdd[g] = al * al * sdd_
        rho[g] = r11 / r2 if r2 > 0.0 else 0.0
    return alpha, xhat, ssr, shh, shd, sdd, rho, code, iters


@numba.njit(cache=True)
def _residual_pass(u, a, jc, s, e, kn, kv, ks, k0, k1, x, al):
    """Residuals r = A − α Â(u + x) (segments walked from ``jc``): Σ r², Σ rᵢ rᵢ₋₁, Σ A² and
    the sums (S_a, S_b, S_ad, S_bd, S_dd) at x."""
    saa = 0.0
    r2 = 0.0
    r11 = 0.0
    prev = 0.0
    sa = 0.0
    sb = 0.0
    sad = 0.0
    sbd = 0.0
    sdd = 0.0
    for i in range(s, e):
        t = u[i] + x
        j = walk_segment(kn, k0, k1, jc[i], t)
        jc[i] = j
        d = ks[j]
        h = kv[j] + d * (t - kn[j])
        ai = a[i]
        saa += ai * ai
        r = ai - al * h
        r2 += r * r
        if i > s:
            r11 += r * prev
        prev = r
        sa += ai * h
        sb += h * h
        sad += ai * d
        sbd += h * d
        sdd += d * d
    return r2, r11, saa, (sa, sb, sad, sbd, sdd)


@numba.njit(cache=True, fastmath={"reassoc"})
def _all_finite(x):
    """No NaN or ±inf in x: x·0 is 0 for every finite value and NaN otherwise, and a NaN stays in
    the sum (reassociation only lets the loop vectorise)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += x[i] * 0.0
    return acc == 0.0


# --------------------------------------------------------------------------------------------
# array API
# --------------------------------------------------------------------------------------------


class _Packed:
    """Knots, values, segment slopes and bucket tables of distinct characteristics, concatenated,
    with per-population indices into them."""

    def __init__(self, chars: Sequence[Characteristic | None]):
        index: dict[int, int] = {}
        kn_parts, kv_parts, ks_parts, tab_parts = [], [], [], []
        starts, ends, tstarts, tlos, tinvs, tns = [], [], [], [], [], []
        pos = tpos = 0
        g_n = len(chars)
        self.kstart = np.zeros(g_n, dtype=np.int64)
        self.kend = np.full(g_n, 2, dtype=np.int64)
        self.tstart = np.zeros(g_n, dtype=np.int64)
        self.tlo = np.zeros(g_n)
        self.tinv = np.ones(g_n)
        self.tn = np.ones(g_n, dtype=np.int64)
        for gi, c in enumerate(chars):
            if c is None:
                continue
            key = id(c)
            if key not in index:
                index[key] = len(starts)
                k = c.knots_u_m
                v = c.values_m2
                sl = np.empty_like(k)
                sl[:-1] = np.diff(v) / np.diff(k)
                sl[-1] = sl[-2]
                n_b = int(min(max(16, 4 * k.shape[0]), 1 << 16))
                width = (k[-1] - k[0]) / n_b
                edges = k[0] + width * np.arange(n_b)
                seg = np.clip(np.searchsorted(k, edges, side="right") - 1, 0, k.shape[0] - 2)
                kn_parts.append(k)
                kv_parts.append(v)
                ks_parts.append(sl)
                tab_parts.append(seg + pos)
                starts.append(pos)
                ends.append(pos + k.shape[0])
                tstarts.append(tpos)
                tlos.append(k[0])
                tinvs.append(1.0 / width)
                tns.append(n_b)
                pos += k.shape[0]
                tpos += n_b
            ci = index[key]
            self.kstart[gi] = starts[ci]
            self.kend[gi] = ends[ci]
            self.tstart[gi] = tstarts[ci]
            self.tlo[gi] = tlos[ci]
            self.tinv[gi] = tinvs[ci]
            self.tn[gi] = tns[ci]
        if starts:
            self.kn = np.concatenate(kn_parts)
            self.kv = np.concatenate(kv_parts)
            self.ks = np.concatenate(ks_parts)
            self.tab = np.concatenate(tab_parts).astype(np.int64)
        else:
            self.kn = np.array([0.0, 1.0])
            self.kv = np.zeros(2)
            self.ks = np.zeros(2)
            self.tab = np.zeros(1, dtype=np.int64)


def _as_group_array(value, n: int, dtype) -> np.ndarray:
    arr = np.asarray(value, dtype=dtype)
    if arr.ndim == 0:
        return np.full(n, arr, dtype=dtype)
    if arr.shape != (n,):
        raise ValueError(f"per-group setting has shape {arr.shape}, expected ({n},)")
    return arr


def fit_arrays(
    u: np.ndarray,
    area: np.ndarray,
    offsets: np.ndarray,
    characteristics: Sequence[Characteristic | None],
    *,
    x_bound_m: float | np.ndarray = 1.5e-3,
    min_points: int | np.ndarray = 500,
    min_coverage_m: float | np.ndarray = 0.25e-3,
    ci_level: float = 0.95,
    n_grid: int = 25,
    sub_max: int = 96,
    xtol_m: float = 1e-9,
    maxiter: int = 60,
    x_start_m: np.ndarray | None = None,
    residuals: bool = True,
) -> dict[str, np.ndarray]:
    """Eq. 8 for G populations stored contiguously: points ``offsets[g]:offsets[g+1]`` of
    ``u``/``area`` belong to population g, whose baseline is ``characteristics[g]``
    (None = no baseline). Settings may be scalars or per-population arrays.

    ``x_start_m`` (per population, NaN = none): warm start from a previous optimum of nearly the
    same points (the leakage refinement of :func:`transforms.monitor.monitor`); the coarse grid
    is skipped for those populations. ``residuals=False`` skips the pass over the residuals:
    α̂ and x̂ only (e, the confidence intervals and ``ci_inflation`` are NaN).

    Returns per population: ``status`` (str), ``n_points``, ``u_min_m``, ``u_max_m``,
    ``alpha_hat``, ``x_hat_m``, ``e_m2``, CI bounds, ``ci_inflation``, ``iterations``,
    ``u_spread_m``, ``x_hat_determined`` (:data:`FIT_COLUMNS`).
    Estimates are NaN where the status says there is none.
    """
    u = read_only(np.ascontiguousarray(u, dtype=np.float64))
    area = read_only(np.ascontiguousarray(area, dtype=np.float64))
    offsets = np.ascontiguousarray(offsets, dtype=np.int64)
    if u.shape != area.shape or u.ndim != 1:
        raise ValueError("u and area must be 1-D arrays of equal length")
    g_n = offsets.shape[0] - 1
    if g_n < 0 or offsets[0] != 0 or offsets[-1] != u.shape[0] or np.any(np.diff(offsets) < 0):
        raise ValueError("offsets must start at 0, be non-decreasing and end at len(u)")
    if len(characteristics) != g_n:
        raise ValueError("need one characteristic (or None) per population")
    if n_grid < 3:
        raise ValueError("n_grid must be >= 3")
    x_bound = _as_group_array(x_bound_m, g_n, np.float64)
    min_pts = _as_group_array(min_points, g_n, np.int64)
    min_cov = _as_group_array(min_coverage_m, g_n, np.float64)

    n = np.diff(offsets)
    nonempty = n > 0
    u_min = np.full(g_n, np.nan)
    u_max = np.full(g_n, np.nan)
    if np.any(nonempty):
        starts = offsets[:-1][nonempty]
        u_min[nonempty] = np.minimum.reduceat(u, starts)
        u_max[nonempty] = np.maximum.reduceat(u, starts)
    has_base = np.array([c is not None for c in characteristics], dtype=bool)
    if not (_all_finite(u) and _all_finite(area)):
        raise ValueError("u and area must be finite (drop non-finite points before fitting)")

    status = np.full(g_n, "ok", dtype=object)
    status[~has_base] = "no_baseline"
    coverage_short = nonempty & ((u_max - u_min) < min_cov)
    status[coverage_short] = "too_little_coverage"
    status[n < np.maximum(min_pts, 3)] = "too_few_points"
    status[n == 0] = "no_points"
    active = status == "ok"

    pk = _Packed(characteristics)
    alpha, xhat, ssr, shh, shd, sdd, rho, code, iters = _fit_groups(
        u, area, offsets, pk.kstart, pk.kend, pk.kn, pk.kv, pk.ks, pk.tab, pk.tstart, pk.tlo, pk.tinv, pk.tn,
        x_bound, active.astype(np.bool_),
        int(n_grid), int(sub_max), float(xtol_m), int(maxiter),
        np.full(g_n, np.nan) if x_start_m is None else _as_group_array(x_start_m, g_n, np.float64),
        bool(residuals),
    )
    status[code == _DEGENERATE] = "degenerate"
    status[code == _AT_BOUND] = "x_hat_at_bound"
    status[code == _NOT_CONVERGED] = "not_converged"

    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.sqrt(ssr / n)
        dof = np.maximum(n - 2, 1)
        sigma2 = ssr / dof
        det = shh * sdd - shd * shd
        var_a = sigma2 * sdd / det
        var_x = sigma2 * shh / det
        rho_c = np.clip(np.nan_to_num(rho, nan=0.0), 0.0, 0.98)
        infl = np.sqrt((1.0 + rho_c) / (1.0 - rho_c))
        from scipy.special import stdtrit  # noqa: PLC0415 - Student's t quantile (scipy.stats.t.ppf) without scipy.stats (~1 s); imported here, not by every command that imports this module (~0.3 s)

        tq = stdtrit(dof, 0.5 + ci_level / 2.0)
        half_a = tq * infl * np.sqrt(var_a)
        half_x = tq * infl * np.sqrt(var_x)
        spread = alpha * np.sqrt(det) / sdd
    fitted = np.isfinite(alpha) & np.isfinite(ssr)
    infl = np.where(fitted, infl, np.nan)
    return {
        "status": status.astype(str),
        "n_points": n.astype(np.int64),
        "u_min_m": u_min,
        "u_max_m": u_max,
        "alpha_hat": alpha,
        "x_hat_m": xhat,
        "e_m2": np.where(fitted, e, np.nan),
        "alpha_ci_low": alpha - half_a,
        "alpha_ci_high": alpha + half_a,
        "x_hat_ci_low_m": xhat - half_x,
        "x_hat_ci_high_m": xhat + half_x,
        "ci_inflation": infl,
        "iterations": iters.astype(np.int64),
        "u_spread_m": np.where(fitted, spread, np.nan),
        "x_hat_determined": fitted & (spread >= X_HAT_MIN_SPREAD_M),
    }


def profile_cost(u: np.ndarray, area: np.ndarray, characteristic: Characteristic, x_hat: float):
    """(f, f', f'', α̂) of the profile cost at ``x_hat`` for one population (for tests/diagnostics)."""
    u = read_only(np.ascontiguousarray(u, dtype=np.float64))
    area = read_only(np.ascontiguousarray(area, dtype=np.float64))
    pk = _Packed([characteristic])
    tb = (pk.tab, int(pk.tstart[0]), float(pk.tlo[0]), float(pk.tinv[0]), int(pk.tn[0]))
    saa = float(area @ area)
    jc = np.zeros(u.shape[0], dtype=np.int64)
    f, fp, fpp, al, _good = _profile(
        u, area, jc, 0, u.shape[0], 1, pk.kn, pk.kv, pk.ks, int(pk.kstart[0]), int(pk.kend[0]), *tb, float(x_hat), 0, saa
    )
    return f, fp, fpp, al


def eq8_cost_gradient(
    u: np.ndarray, area: np.ndarray, characteristic: Characteristic, alpha_hat: float, x_hat: float
) -> tuple[float, float, float]:
    """Eq. 8's e(α̂, x̂) = sqrt(mean r²), r = A − α̂ Â(u + x̂), and its analytic gradient
    (∂e/∂α̂, ∂e/∂x̂) = −(1/(N e)) Σ r · (Â(u + x̂), α̂ Â'(u + x̂))."""
    u = np.asarray(u, dtype=np.float64)
    area = np.asarray(area, dtype=np.float64)
    h = characteristic.evaluate(u + x_hat)
    d = characteristic.slope(u + x_hat)
    r = area - alpha_hat * h
    n = r.shape[0]
    e = float(np.sqrt(np.mean(r * r)))
    if e == 0.0:
        return 0.0, 0.0, 0.0
    return e, float(-(r @ h) / (n * e)), float(-(alpha_hat * (r @ d)) / (n * e))


# --------------------------------------------------------------------------------------------
# polars API
# --------------------------------------------------------------------------------------------

_KEYS = ("valve_id", "edge", "window_id")


def _group_runs(points: pl.DataFrame) -> tuple[pl.DataFrame, np.ndarray]:
    """Populations as contiguous runs of (valve_id, edge, window_id): (run table, offsets)."""
    change = pl.any_horizontal(*((pl.col(k) != pl.col(k).shift(1)).fill_null(True) for k in _KEYS))
    starts = (
        points.select(change.alias("c")).with_row_index("i").filter(pl.col("c"))["i"].to_numpy().astype(np.int64)
    )
    offsets = np.append(starts, points.height).astype(np.int64)
    runs = points[starts.tolist()].select(*_KEYS, "window_start") if len(starts) else points.head(0).select(*_KEYS, "window_start")
    return runs, offsets


def fit_windows(
    points: pl.DataFrame,
    baselines: Mapping[str, Mapping[str, Characteristic]],
    params: Mapping[str, MonitorParams],
    *,
    windows: pl.DataFrame | None = None,
    edges: tuple[str, ...] = EDGES,
) -> pl.DataFrame:
    """Eq. 8 for every (valve, window, edge) at once; one row each (:data:`FIT_COLUMNS`).

    ``points``: ``valve_id, window_id, window_start, edge, u_m, area_m2`` (as from
    :func:`transforms.points.opening_area_points`; rows of a population need not be contiguous,
    but they are fitted fastest when they are, and the lag-1 autocorrelation assumes time order).
    ``baselines[valve_id][edge]``: Â. ``params[valve_id]``: the fit settings.
    ``windows`` (``valve_id, window_id, window_start, window_end``): every window to report; each
    gets a row per edge even without points (status ``no_points``). Without it, the windows
    present in ``points`` are reported (``window_end`` null).
    """
    points = points.select("valve_id", "edge", "window_id", "window_start", "u_m", "area_m2")
    runs, offsets = _group_runs(points)
    if runs.select(_KEYS).is_duplicated().any():
        points = points.sort(list(_KEYS), maintain_order=True)
        runs, offsets = _group_runs(points)

    if windows is None:
        windows = (
            runs.select("valve_id", "window_id", "window_start")
            .unique(maintain_order=True)
            .with_columns(pl.lit(None, dtype=points.schema["window_start"]).alias("window_end"))
        )
    windows = windows.select("valve_id", "window_id", "window_start", "window_end")
    all_groups = windows.join(pl.DataFrame({"edge": list(edges)}), how="cross")

    # every population with points, in the order of `points`, then the (window, edge) pairs
    # without points (empty populations: status no_points)
    runs = runs.with_row_index("_run")
    with_points = runs.join(
        all_groups.select("valve_id", "window_id", "edge", "window_end"), on=["valve_id", "window_id", "edge"], how="left"
    ).sort("_run")
    without = all_groups.join(runs.select("valve_id", "window_id", "edge"), on=["valve_id", "window_id", "edge"], how="anti")
    cols = ["valve_id", "window_id", "window_start", "window_end", "edge"]
    groups = pl.concat([with_points.select(cols), without.select(cols)], how="vertical")
    offs = np.concatenate([offsets, np.full(without.height, offsets[-1], dtype=np.int64)])
    return fit_groups(groups, points["u_m"].to_numpy(), points["area_m2"].to_numpy(), offs, baselines, params)


def fit_groups(
    groups: pl.DataFrame,
    u: np.ndarray,
    area: np.ndarray,
    offsets: np.ndarray,
    baselines: Mapping[str, Mapping[str, Characteristic]],
    params: Mapping[str, MonitorParams],
    *,
    x_start_m: np.ndarray | None = None,
    sort: bool = True,
    quick: bool = False,
    strides: np.ndarray | None = None,
) -> pl.DataFrame:
    """Eq. 8 for populations laid out contiguously: ``groups`` (``valve_id, window_id,
    window_start, window_end, edge``) row g owns the points ``offsets[g]:offsets[g + 1]`` of
    ``u``/``area``. Returns :data:`FIT_COLUMNS`, sorted by valve, window and edge (in the order
    of ``groups`` when not ``sort``). ``x_start_m``: warm starts (:func:`fit_arrays`).
    ``quick``: α̂ and x̂ to 0.1 µm, no residual pass (e and the intervals NaN): a first estimate
    that a refit will polish. ``strides``: per population, the k of points that are every k-th
    row's (``MonitorParams.window_rows``): ``min_points`` counts samples, so such a population
    needs ⌈min_points / k⌉ points (:data:`transforms.monitor.THIN_MARGIN`)."""
    valve_ids = groups["valve_id"].to_list()
    edge_ids = groups["edge"].to_list()
    g_n = groups.height
    chars: list[Characteristic | None] = [baselines.get(v, {}).get(e) for v, e in zip(valve_ids, edge_ids, strict=True)]
    per_valve = {v: params[v] for v in set(valve_ids)}
    if len({p.ci_level for p in per_valve.values()}) > 1:
        raise ValueError("all valves of one call must share ci_level")
    ci_level = next(iter(per_valve.values())).ci_level if per_valve else 0.95
    res = fit_arrays(
        u,
        area,
        offsets,
        chars,
        x_bound_m=np.array([per_valve[v].x_hat_bound_m for v in valve_ids]).reshape(g_n),
        min_points=-(-np.array([per_valve[v].min_points for v in valve_ids], dtype=np.int64).reshape(g_n) // (1 if strides is None else strides)),
        min_coverage_m=np.array([per_valve[v].min_coverage_m for v in valve_ids]).reshape(g_n),
        ci_level=ci_level,
        x_start_m=x_start_m,
        xtol_m=1e-7 if quick else 1e-9,
        residuals=not quick,
    )
    out = groups.with_columns(pl.Series(name, col) for name, col in res.items())
    out = out.with_columns(pl.lit(float("nan")).alias(c) for c in LEAK_COLUMNS if c not in out.columns)
    out = out.with_columns(pl.lit(None, dtype=pl.Boolean).alias("leak_scale_held"),
                           pl.Series("row_stride", np.ones(g_n, dtype=np.int64) if strides is None else strides, dtype=pl.Int64))
    return sorted_fits(out.select(FIT_COLUMNS)) if sort else out.select(FIT_COLUMNS)


def sorted_fits(fits: pl.DataFrame) -> pl.DataFrame:
    """Fit rows sorted by valve, window and edge (EDGES order)."""
    edge_rank = {e: i for i, e in enumerate(EDGES)}
    return fits.sort(
        pl.col("valve_id"),
        pl.col("window_start"),
        pl.col("window_id"),
        pl.col("edge").replace_strict(edge_rank, return_dtype=pl.Int8),
        maintain_order=True,
    )

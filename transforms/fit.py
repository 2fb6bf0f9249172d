"""Step 4b, Eq. 8: scale α̂ and shift x̂ of the baseline Â, fitted to each population of points.

For a population (one window, one edge) of N points (u_i, A_i),

    e = min over (α̂, x̂) of sqrt( (1/N) Σ_i (A_i − α̂ Â(u_i + x̂))² ).

For fixed x̂ the best α̂ is closed-form, α̂(x̂) = Σ A_i Â_i / Σ Â_i², so the fit is a 1-D search
on the profile cost f(x̂) = Σ A_i² − (Σ A_i Â_i)² / Σ Â_i² (variable projection):

1. a coarse grid of x̂ over [−x_bound, x_bound] on an evenly strided subsample (≤ 256 points; 41 grid points) of
   the population finds the basin of the global minimum;
2. a safeguarded Newton iteration on the full population (bisection whenever Newton would leave
   the bracket or f″ ≤ 0) converges to |Δx̂| < 1 nm. The derivatives are analytic for a
   piecewise-linear Â (Â″ = 0 between knots): with S_a = Σ A Â, S_b = Σ Â², S_ad = Σ A Â',
   S_bd = Σ Â Â', S_dd = Σ Â'², α = S_a/S_b,

       f'  = −2 α S_ad + 2 α² S_bd  (= the gradient of the cost at the optimal α̂: −2 α̂ Σ Â' r)
       f'' = −2 α' S_ad + 4 α α' S_bd + 2 α² S_dd,   α' = (S_ad − 2 α S_bd) / S_b.

The whole batch (every window and edge of every valve) runs in one compiled (numba) kernel,
one pass over a population's points per iteration (about 10 passes in all).

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
(iteration limit; estimates reported).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numba
import numpy as np
import polars as pl
from scipy import stats

from transforms.characteristic import Characteristic
from transforms.params import EDGES, MonitorParams

__all__ = [
    "FIT_COLUMNS",
    "STATUSES",
    "eq8_cost_gradient",
    "fit_arrays",
    "fit_windows",
    "profile_cost",
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
)

# kernel result codes
_OK, _DEGENERATE, _AT_BOUND, _NOT_CONVERGED, _SKIPPED = 0, 1, 2, 3, 4


# --------------------------------------------------------------------------------------------
# compiled core
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _segment(kn, k0, k1, tab, toff, tlo, tinv, tn, t):
    """Index j in [k0, k1 − 2] of the knot segment holding t (end segments extrapolate).

    A uniform bucket table (``tn`` buckets from ``tlo``, width 1/``tinv``) gives the segment of
    each bucket's left edge; a short forward walk finishes the search (O(1) for any knot count).
    """
    if t <= kn[k0]:
        return k0
    if t >= kn[k1 - 1]:
        return k1 - 2
    b = int((t - tlo) * tinv)
    if b >= tn:
        b = tn - 1
    j = tab[toff + b]
    while j < k1 - 2 and t >= kn[j + 1]:
        j += 1
    return j


@numba.njit(cache=True)
def _sums(u, a, s, e, stride, kn, kv, ks, k0, k1, tb, x):
    """One pass: S_a, S_b, S_ad, S_bd, S_dd (and S_aa) at shift x over points s, s+stride, … < e."""
    sa = 0.0
    sb = 0.0
    sad = 0.0
    sbd = 0.0
    sdd = 0.0
    saa = 0.0
    for i in range(s, e, stride):
        t = u[i] + x
        j = _segment(kn, k0, k1, tb[0], tb[1], tb[2], tb[3], tb[4], t)
        d = ks[j]
        h = kv[j] + d * (t - kn[j])
        ai = a[i]
        sa += ai * h
        sb += h * h
        sad += ai * d
        sbd += h * d
        sdd += d * d
        saa += ai * ai
    return sa, sb, sad, sbd, sdd, saa


@numba.njit(cache=True)
def _profile(u, a, s, e, stride, kn, kv, ks, k0, k1, tb, x):
    """Profile cost f(x) = Σ A² − S_a²/S_b (α ≥ 0), its derivatives, and α(x)."""
    sa, sb, sad, sbd, sdd, saa = _sums(u, a, s, e, stride, kn, kv, ks, k0, k1, tb, x)
    if sb <= 0.0 or sa <= 0.0:
        return saa, 0.0, 0.0, 0.0, False
    al = sa / sb
    f = saa - sa * al
    fp = -2.0 * al * sad + 2.0 * al * al * sbd
    alp = (sad - 2.0 * al * sbd) / sb
    fpp = -2.0 * alp * sad + 4.0 * al * alp * sbd + 2.0 * al * al * sdd
    return f, fp, fpp, al, True


@numba.njit(cache=True)
def _fit_one(u, a, s, e, kn, kv, ks, k0, k1, tb, xb, n_grid, sub_max, xtol, maxiter):
    n = e - s
    stride = max(1, n // sub_max)
    # 1. coarse grid on a strided subsample
    best_g = 0
    best_f = np.inf
    step = 2.0 * xb / (n_grid - 1)
    for g in range(n_grid):
        xg = -xb + g * step
        f, fp, fpp, al, good = _profile(u, a, s, e, stride, kn, kv, ks, k0, k1, tb, xg)
        if good and f < best_f:
            best_f = f
            best_g = g
    if not np.isfinite(best_f):
        return 0.0, 0.0, _DEGENERATE, 0
    x = -xb + best_g * step
    lo = max(-xb, x - step)
    hi = min(xb, x + step)
    # 2. make sure [lo, hi] brackets a sign change of f' on the full data (expand if not)
    passes = 0
    for _ in range(4 * n_grid):
        flo, fplo, _a, _b, glo = _profile(u, a, s, e, 1, kn, kv, ks, k0, k1, tb, lo)
        passes += 1
        if glo and fplo >= 0.0 and lo > -xb:
            hi = lo
            lo = max(-xb, lo - step)
            continue
        break
    for _ in range(4 * n_grid):
        fhi, fphi, _a, _b, ghi = _profile(u, a, s, e, 1, kn, kv, ks, k0, k1, tb, hi)
        passes += 1
        if ghi and fphi <= 0.0 and hi < xb:
            lo = hi
            hi = min(xb, hi + step)
            continue
        break
    if glo and fplo >= 0.0 and lo <= -xb:
        return -xb, 0.0, _AT_BOUND, passes
    if ghi and fphi <= 0.0 and hi >= xb:
        return xb, 0.0, _AT_BOUND, passes
    if x < lo or x > hi:
        x = 0.5 * (lo + hi)
    # 3. safeguarded Newton on f'
    for it in range(maxiter):
        f, fp, fpp, al, good = _profile(u, a, s, e, 1, kn, kv, ks, k0, k1, tb, x)
        passes += 1
        if not good:
            return x, 0.0, _DEGENERATE, passes
        if fp < 0.0:
            lo = x
        else:
            hi = x
        if fpp > 0.0:
            xn = x - fp / fpp
            if not (lo < xn < hi):
                xn = 0.5 * (lo + hi)
        else:
            xn = 0.5 * (lo + hi)
        if abs(xn - x) < xtol or hi - lo < xtol:
            return xn, 0.0, _OK, passes
        x = xn
    return x, 0.0, _NOT_CONVERGED, passes


@numba.njit(cache=True)
def _fit_groups(u, a, offsets, kstart, kend, kn, kv, ks, tab, tstart, tlo, tinv, tn, xbound, active, n_grid, sub_max, xtol, maxiter):
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
    for g in range(g_n):
        if not active[g]:
            continue
        s = offsets[g]
        e = offsets[g + 1]
        k0 = kstart[g]
        k1 = kend[g]
        tb = (tab, tstart[g], tlo[g], tinv[g], tn[g])
        x, _unused, c, p = _fit_one(u, a, s, e, kn, kv, ks, k0, k1, tb, xbound[g], n_grid, sub_max, xtol, maxiter)
        iters[g] = p
        code[g] = c
        if c == _DEGENERATE:
            continue
        # final pass at the optimum: α̂, residual sums, JᵀJ pieces, lag-1 autocorrelation
        sa, sb, sad, sbd, sdd_, saa = _sums(u, a, s, e, 1, kn, kv, ks, k0, k1, tb, x)
        if sb <= 0.0 or sa <= 0.0:
            code[g] = _DEGENERATE
            continue
        al = sa / sb
        r2 = 0.0
        r11 = 0.0
        prev = 0.0
        for i in range(s, e):
            t = u[i] + x
            j = _segment(kn, k0, k1, tb[0], tb[1], tb[2], tb[3], tb[4], t)
            r = a[i] - al * (kv[j] + ks[j] * (t - kn[j]))
            r2 += r * r
            if i > s:
                r11 += r * prev
            prev = r
        alpha[g] = al
        xhat[g] = x
        ssr[g] = r2
        shh[g] = sb
        shd[g] = al * sbd
        sdd[g] = al * al * sdd_
        rho[g] = r11 / r2 if r2 > 0.0 else 0.0
    return alpha, xhat, ssr, shh, shd, sdd, rho, code, iters


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
    n_grid: int = 41,
    sub_max: int = 256,
    xtol_m: float = 1e-9,
    maxiter: int = 60,
) -> dict[str, np.ndarray]:
    """Eq. 8 for G populations stored contiguously: points ``offsets[g]:offsets[g+1]`` of
    ``u``/``area`` belong to population g, whose baseline is ``characteristics[g]``
    (None = no baseline). Settings may be scalars or per-population arrays.

    Returns per population: ``status`` (str), ``n_points``, ``u_min_m``, ``u_max_m``,
    ``alpha_hat``, ``x_hat_m``, ``e_m2``, CI bounds, ``ci_inflation``, ``iterations``.
    Estimates are NaN where the status says there is none.
    """
    u = np.ascontiguousarray(u, dtype=np.float64)
    area = np.ascontiguousarray(area, dtype=np.float64)
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
    finite = np.isfinite(u).all() and np.isfinite(area).all()
    if not finite:
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
        tq = stats.t.ppf(0.5 + ci_level / 2.0, dof)
        half_a = tq * infl * np.sqrt(var_a)
        half_x = tq * infl * np.sqrt(var_x)
    fitted = np.isfinite(alpha)
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
    }


def profile_cost(u: np.ndarray, area: np.ndarray, characteristic: Characteristic, x_hat: float):
    """(f, f', f'', α̂) of the profile cost at ``x_hat`` for one population (for tests/diagnostics)."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    area = np.ascontiguousarray(area, dtype=np.float64)
    pk = _Packed([characteristic])
    tb = (pk.tab, int(pk.tstart[0]), float(pk.tlo[0]), float(pk.tinv[0]), int(pk.tn[0]))
    f, fp, fpp, al, _good = _profile(
        u, area, 0, u.shape[0], 1, pk.kn, pk.kv, pk.ks, int(pk.kstart[0]), int(pk.kend[0]), tb, float(x_hat)
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

    # populations with points and one without points per missing (window, edge)
    runs = runs.with_row_index("_run")
    groups = all_groups.join(
        runs.select("valve_id", "window_id", "edge", "_run"), on=["valve_id", "window_id", "edge"], how="left"
    )
    extra = runs.join(all_groups.select("valve_id", "window_id", "edge"), on=["valve_id", "window_id", "edge"], how="anti")
    if extra.height:
        groups = pl.concat(
            [groups, extra.with_columns(pl.lit(None, dtype=windows.schema["window_end"]).alias("window_end"))
             .select(groups.columns)],
            how="vertical",
        )

    run_idx = groups["_run"].to_numpy()
    has_run = ~groups["_run"].is_null().to_numpy()
    run_idx = np.where(has_run, np.nan_to_num(run_idx, nan=0), 0).astype(np.int64)
    # offsets per reported group: populations that have points keep their run; others are empty
    n_run = np.diff(offsets)
    order = np.argsort(np.where(has_run, run_idx, np.iinfo(np.int64).max), kind="stable")
    # Build a contiguous layout: groups with runs in run order first (the points stay in place).
    g_n = groups.height
    sizes = np.where(has_run, n_run[run_idx] if len(n_run) else 0, 0)
    # groups sorted so that runs appear in the same order as in `points`
    sizes_sorted = sizes[order]
    offs = np.concatenate([[0], np.cumsum(sizes_sorted)]).astype(np.int64)

    valve_ids = groups["valve_id"].to_list()
    edge_ids = groups["edge"].to_list()
    chars: list[Characteristic | None] = []
    x_bound = np.empty(g_n)
    min_pts = np.empty(g_n, dtype=np.int64)
    min_cov = np.empty(g_n)
    ci_levels = set()
    for gi in order:
        v, e = valve_ids[gi], edge_ids[gi]
        chars.append(baselines.get(v, {}).get(e))
    for k, gi in enumerate(order):
        p = params[valve_ids[gi]]
        x_bound[k] = p.x_hat_bound_m
        min_pts[k] = p.min_points
        min_cov[k] = p.min_coverage_m
        ci_levels.add(p.ci_level)
    if len(ci_levels) > 1:
        raise ValueError("all valves of one call must share ci_level")
    ci_level = ci_levels.pop() if ci_levels else 0.95

    res = fit_arrays(
        points["u_m"].to_numpy(),
        points["area_m2"].to_numpy(),
        offs,
        chars,
        x_bound_m=x_bound,
        min_points=min_pts,
        min_coverage_m=min_cov,
        ci_level=ci_level,
    )
    inv = np.empty(g_n, dtype=np.int64)
    inv[order] = np.arange(g_n)
    out = groups.drop("_run").with_columns(
        pl.Series(name, np.asarray(col)[inv]) for name, col in res.items()
    )
    edge_rank = {e: i for i, e in enumerate(EDGES)}
    return out.select(FIT_COLUMNS).sort(
        pl.col("valve_id"),
        pl.col("window_start"),
        pl.col("window_id"),
        pl.col("edge").replace_strict(edge_rank, return_dtype=pl.Int8),
        maintain_order=True,
    )

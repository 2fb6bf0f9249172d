"""Step 4a (initial opening-area characteristic) and step 5a (its plausibility check).

:func:`fit_characteristic` fits Â to points (u_i, A_i) by linear least squares in the hat-function
basis. Knots follow the distribution of the points (paper: "the location of nodes is adaptively
chosen depending on the distribution of the measurement points"): quantiles of u, one interval per
``points_per_interval`` points, at most ``max_knots`` knots, never closer than
``min_spacing_m`` (0.1 mm: several times the spool sensor noise, about 3 % of x_max). With a
``carrier`` (what the monitor uses: the nominal characteristic) the piecewise-linear fit is a
correction factor on the carrier's shape, sampled finely (see :func:`fit_characteristic`).

:func:`plausibility` compares a baseline with the nominal characteristic over their common
u-range (value, slope, shape, monotonicity, and the scale/shift of Eq. 8 that maps one onto the
other). Default thresholds and why:

* value scale Σ ÂN/ΣN² and slope ratio within [0.7, 1/0.7]: the nominal contraction coefficient
  is a handbook value (0.6–0.75 for sharp edges depending on Reynolds number and edge radius,
  ±15 % around the configured value), Eq. 7 itself carries β (±7 %) and a few per cent of
  closed-edge leakage; ±30 % (log-symmetric) leaves room for all of it but not for the paper's
  broken edge (α ×2.5);
* relative RMS difference ≤ 0.43 (= 1/0.7 − 1, what the ratio bounds allow), catching a
  combination of scale and shift that each alone would pass;
* shape: the RMS error left after the best scale and shift (Eq. 8 of nominal onto baseline),
  relative to the baseline's RMS, ≤ 0.1: a healthy valve differs from the ideal conical-gap
  geometry by a few per cent;
* shift |x̂| ≤ 0.2 mm: manufacturing underlaps vary by a few hundredths of a millimetre (model.md:
  up to about 0.1 mm); the broken edge of Table 2 is +0.41 mm;
* monotone: no segment slope below −5 % of the nominal mean slope (Â must grow with u).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from transforms.characteristic import Characteristic, scaled_shifted
from transforms.fit import fit_arrays

__all__ = ["EDGE_LAWS", "EDGE_LAW_MARGIN", "Plausibility", "carrier_fit", "choose_knots", "edge_law_residuals", "fit_characteristic",
           "leak_scale_lstsq", "plausibility", "recognise_edge_law"]


def choose_knots(
    u,
    *,
    max_knots: int = 12,
    min_spacing_m: float = 1e-4,
    points_per_interval: int = 200,
) -> np.ndarray:
    """Knots at quantiles of ``u``: the end knots at min/max, one interval per
    ``points_per_interval`` points (at most ``max_knots − 1``), inner knots dropped where they would
    come closer than ``min_spacing_m`` to a kept neighbour."""
    u = np.asarray(u, dtype=np.float64)
    u = u[np.isfinite(u)]
    if u.shape[0] < 2:
        raise ValueError("need at least two points to place knots")
    if max_knots < 2:
        raise ValueError("max_knots must be >= 2")
    lo, hi = float(u.min()), float(u.max())
    if hi - lo < min_spacing_m:
        raise ValueError(f"points span {hi - lo:.3g} m, less than the minimum knot spacing {min_spacing_m:g} m")
    n_int = int(np.clip(u.shape[0] // max(points_per_interval, 1), 1, max_knots - 1))
    q = np.quantile(u, np.linspace(0.0, 1.0, n_int + 1))
    kept = [lo]
    for k in q[1:-1]:
        if k - kept[-1] >= min_spacing_m and hi - k >= min_spacing_m:
            kept.append(float(k))
    kept.append(hi)
    return np.array(kept)


def _hat_lstsq(u: np.ndarray, a: np.ndarray, k: np.ndarray, carrier: np.ndarray | None = None) -> np.ndarray:
    """Values at the knots ``k`` of the piecewise-linear c(u) minimising Σ (A_i − S_i c(u_i))²
    (S_i = 1 without a carrier). Hat-function basis; the normal equations are tridiagonal and
    assembled with ``bincount`` (no loop over points)."""
    n_k = k.shape[0]
    j = np.clip(np.searchsorted(k, u, side="right") - 1, 0, n_k - 2)
    t = (u - k[j]) / (k[j + 1] - k[j])
    w0, w1 = 1.0 - t, t
    if carrier is not None:
        w0, w1 = w0 * carrier, w1 * carrier
    diag = np.bincount(j, w0 * w0, minlength=n_k) + np.bincount(j + 1, w1 * w1, minlength=n_k)
    off = np.bincount(j, w0 * w1, minlength=n_k - 1)[: n_k - 1]
    rhs = np.bincount(j, w0 * a, minlength=n_k) + np.bincount(j + 1, w1 * a, minlength=n_k)
    g = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)
    values, *_ = np.linalg.lstsq(g, rhs, rcond=None)
    return values


def fit_characteristic(
    u,
    area,
    *,
    knots=None,
    max_knots: int = 12,
    min_spacing_m: float = 1e-4,
    points_per_interval: int = 200,
    carrier: Characteristic | None = None,
    extend_m: float = 0.0,
    grid_step_m: float = 0.05e-3,
    closed: tuple[Characteristic, float, float] | None = None,
) -> Characteristic:
    """Step 4a: least-squares piecewise-linear Â through the points (u_i, A_i).

    ``knots`` fixes the knots; otherwise :func:`choose_knots`.

    Without ``carrier`` (the paper's form), Â itself is piecewise linear on the knots.

    With a ``carrier`` (the nominal α·A(u) of Eq. 3), Â follows the physical shape between and
    beyond the knots: first the carrier is scaled and shifted onto the points (Eq. 8,
    S(u) = α_b·carrier(u + x_b)), then a piecewise-linear correction factor c(u) on the knots is
    fitted by linear least squares (Σ (A_i − S(u_i) c(u_i))², still linear in the knot values)
    and Â = S·c is sampled every ``grid_step_m`` over the points' range widened by ``extend_m``
    on both sides, with c held at its end values beyond the points. Why: the open-edge area of
    Eq. 3 is curved (A'' = −2π cos φ sin²φ), so a chord over a sparsely populated 1.4 mm
    segment has a slope error of about 1 % on port 1, and a later window that lives inside that
    segment (or beyond the commissioning range, where a chord extrapolates linearly) maps it into
    α̂ and x̂ (≈ 0.3 % of x_max on simulated Table 1 valves; docs/monitoring.md). The carrier
    carries the curvature and the scatter of underlap and α; c keeps the data's own shape.

    ``closed`` = (L, u_c, u_from) (with a carrier): below the edge's closing point u_c (in u)
    Â is the edge's identified closed-edge leakage L (α·A with the fitted leakage,
    :func:`transforms.leakage.closed_leakage`), blended linearly into S·c over one grid step
    below u_c, and the samples start at u_from (e.g. −x_max): Â ≥ 0 over the whole stroke, and
    0 below the underlap when the edge does not leak.
    """
    u = np.asarray(u, dtype=np.float64).reshape(-1)
    a = np.asarray(area, dtype=np.float64).reshape(-1)
    if u.shape != a.shape:
        raise ValueError("u and area differ in length")
    ok = np.isfinite(u) & np.isfinite(a)
    u, a = u[ok], a[ok]
    if knots is None:
        k = choose_knots(u, max_knots=max_knots, min_spacing_m=min_spacing_m, points_per_interval=points_per_interval)
    else:
        k = np.asarray(knots, dtype=np.float64).reshape(-1)
        if k.shape[0] < 2 or np.any(np.diff(k) <= 0):
            raise ValueError("knots must be at least two, strictly increasing")
    if u.shape[0] < 2:
        raise ValueError("need at least two finite points")
    if carrier is None:
        return Characteristic(k, _hat_lstsq(u, a, k))
    if not extend_m >= 0 or not grid_step_m > 0:
        raise ValueError("extend_m must be >= 0 and grid_step_m > 0")
    shape = scaled_shifted(carrier, *carrier_fit(u, a, carrier))
    c = _hat_lstsq(u, a, k, shape.evaluate(u))
    lo, hi = float(k[0]), float(k[-1])
    start = lo - extend_m
    extra = k
    if closed is not None:
        leak, u_c, u_from = closed
        u_c = min(u_c, lo - grid_step_m)
        start = min(start, u_from, u_c - grid_step_m)
        extra = np.concatenate([[u_c - grid_step_m, u_c], k])
    n = int(np.ceil((hi + extend_m - start) / grid_step_m - 1e-9))
    grid = np.unique(np.concatenate([start + grid_step_m * np.arange(n + 1), extra]))
    grid = grid[np.concatenate([[True], np.diff(grid) > 1e-12])]
    values = shape.evaluate(grid) * np.interp(grid, k, c)
    if closed is not None:
        w = np.clip((grid - (u_c - grid_step_m)) / grid_step_m, 0.0, 1.0)
        values = w * values + (1.0 - w) * np.maximum(leak.evaluate(grid), 0.0)
    return Characteristic(grid, values)


def leak_scale_lstsq(u, plain, leak, knots, carrier: np.ndarray, *, block: int = 1, prior=None,
                     prior_sd: float = float("inf")) -> tuple[np.ndarray, np.ndarray]:
    """Step 4a with the closed-edge leakage (:mod:`transforms.leakage`): the coefficients λ ≥ 0 of
    the leakage columns ``leak`` (n × m) in the joint least squares plain_i = S_i c(u_i) + Σ λ_k ℓ_ik
    (c piecewise linear on ``knots``, S the carrier at the points), on the means of ``block``
    consecutive equations (points in time order: a linear combination of the equations, which
    filters the load's fast dynamics out of the pressure ratio), with the prior N(``prior``,
    ``prior_sd``²) on each λ (a ridge toward it, weighted by the residual variance) and a
    coefficient that would be negative set to 0 (active set). Returns (λ, their covariance with
    the residuals' serial-correlation factor; 0 for a coefficient held at 0)."""
    leak = np.asarray(leak, dtype=np.float64).reshape(u.shape[0], -1)
    m = leak.shape[1]
    prior = np.zeros(m) if prior is None else np.asarray(prior, dtype=np.float64)
    n_k = knots.shape[0]
    n = u.shape[0]
    j = np.clip(np.searchsorted(knots, u, side="right") - 1, 0, n_k - 2)
    t = (u - knots[j]) / (knots[j + 1] - knots[j])
    x = np.zeros((n, n_k + m))
    rows = np.arange(n)
    x[rows, j] = (1.0 - t) * carrier
    x[rows, j + 1] += t * carrier
    x[:, n_k:] = leak
    y = np.asarray(plain, dtype=np.float64)
    if block > 1 and n >= 2 * block:
        starts = np.arange(0, n, block)
        size = np.diff(np.append(starts, n))[:, None]
        x = np.add.reduceat(x, starts, axis=0) / size
        y = np.add.reduceat(y, starts) / size[:, 0]
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ coef
    rr = float(r @ r)
    rho = float(r[1:] @ r[:-1] / rr) if rr > 0 else 0.0
    rho = min(max(rho, 0.0), 0.98)
    s2 = rr / max(y.shape[0] - x.shape[1], 1) * (1.0 + rho) / (1.0 - rho)
    active = list(range(m))
    while True:
        cols = list(range(n_k)) + [n_k + k for k in active]
        xa, ya = x[:, cols], y
        if np.isfinite(prior_sd) and active:
            w = np.sqrt(s2) / prior_sd
            ridge = np.zeros((len(active), len(cols)))
            ridge[np.arange(len(active)), n_k + np.arange(len(active))] = w
            xa = np.vstack([xa, ridge])
            ya = np.concatenate([y, w * prior[active]])
        ca, *_ = np.linalg.lstsq(xa, ya, rcond=None)
        lam = ca[n_k:]
        if not active or lam.min() >= 0.0:
            break
        active.pop(int(np.argmin(lam)))
    out = np.zeros(m)
    cov = np.zeros((m, m))
    if active:
        out[active] = lam
        try:
            inv = np.linalg.inv(xa.T @ xa)[n_k:, n_k:]
        except np.linalg.LinAlgError:
            inv = np.full((len(active), len(active)), np.nan)
        cov[np.ix_(active, active)] = s2 * inv
    return out, cov


def carrier_fit(u, area, carrier: Characteristic, *, x_search_m: float = 1.5e-3) -> tuple[float, float]:
    """Eq. 8 of the points onto ``carrier``: (α, x) minimising Σ (A_i − α·carrier(u_i + x))²;
    (1, 0) when that fit gives no trustworthy optimum (degenerate, on the search bound)."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    a = np.ascontiguousarray(area, dtype=np.float64)
    res = fit_arrays(u, a, np.array([0, u.shape[0]]), [carrier], x_bound_m=x_search_m, min_points=3, min_coverage_m=0.0)
    if res["status"][0] != "ok":
        return 1.0, 0.0
    return float(res["alpha_hat"][0]), float(res["x_hat_m"][0])


EDGE_LAW_MARGIN = 0.02
"""Another edge law replaces the configured one when its nominal shape, scaled and shifted onto
each edge's commissioning points (Eq. 8), leaves a pooled residual sum of squares at least this
much (2 %) smaller. Measured with Table 1's sensors (the ratio of the sharp-edged law's residual to
Eq. 3's; the same points, so their noise largely cancels): six 10 s snapshots (the study's moves),
linear-gradient valves 0.88–0.93, Eq. 3 valves and worn lands ×3 1.07–1.13; one 10 s snapshot,
linear-gradient valves 0.82–0.99 (not every one recognised: the configured law is kept), Eq. 3
valves 1.002–1.19 (61 valves) and worn lands 1.008–1.25 (docs/monitoring.md, "x̂ on any edge law")."""

EDGE_LAWS = {"eq3": "Eq. 3 (curved open branch)", "sharp": "straight (sharp-edged, linear-gradient)"}
"""How the edge laws the monitor knows are named in its notes."""


def edge_law_residuals(u: Mapping[str, np.ndarray], area: Mapping[str, np.ndarray],
                       laws: Mapping[str, Mapping[str, Characteristic]], *, x_search_m: float = 1.5e-3) -> dict[str, float]:
    """Per edge law (``laws[name][edge]``: its nominal α·A), the residual sum of squares of Eq. 8 of
    every edge's points (``u[edge]``, ``area[edge]``) onto that law's nominal, pooled over the
    edges with ≥ 3 points. [m⁴]"""
    edges = [e for e in u if np.asarray(u[e]).shape[0] >= 3]
    if not edges:
        return {name: float("nan") for name in laws}
    uu = np.concatenate([u[e] for e in edges])
    aa = np.concatenate([area[e] for e in edges])
    off = np.concatenate([[0], np.cumsum([np.asarray(u[e]).shape[0] for e in edges])])
    out = {}
    for name, chars in laws.items():
        res = fit_arrays(uu, aa, off, [chars[e] for e in edges], x_bound_m=x_search_m, min_points=3, min_coverage_m=0.0)
        out[name] = float(np.nansum(res["e_m2"] ** 2 * res["n_points"]))
    return out


def recognise_edge_law(u, area, laws: Mapping[str, Mapping[str, Characteristic]], configured: str, *,
                       x_search_m: float = 1.5e-3, margin: float = EDGE_LAW_MARGIN) -> tuple[str, dict[str, float]]:
    """The edge law the commissioning points follow: the one of ``laws`` (the configured one
    included) of least :func:`edge_law_residuals`, unless the configured one's is within
    ``margin`` of it. Returns (name, the residuals)."""
    ssr = edge_law_residuals(u, area, laws, x_search_m=x_search_m)
    best = min((v, k) for k, v in ssr.items() if np.isfinite(v))[1] if any(np.isfinite(v) for v in ssr.values()) else configured
    if best != configured and np.isfinite(ssr[configured]) and ssr[best] > (1.0 - margin) * ssr[configured]:
        best = configured
    return best, ssr


@dataclass(frozen=True)
class Plausibility:
    """Step 5a's verdict and the numbers behind it (see the module docstring for the bounds)."""

    ok: bool
    reasons: tuple[str, ...]
    u_lo_m: float
    u_hi_m: float
    scale: float
    slope_ratio: float
    rel_rms: float
    shape_error: float
    alpha_vs_nominal: float
    x_hat_vs_nominal_m: float
    min_rel_slope: float
    limits: dict = field(default_factory=dict)


def plausibility(
    baseline: Characteristic,
    nominal: Characteristic,
    *,
    u_range: tuple[float, float] | None = None,
    n_grid: int = 201,
    ratio_bounds: tuple[float, float] = (0.7, 1.0 / 0.7),
    max_rel_rms: float = 0.43,
    max_shape_error: float = 0.1,
    max_shift_m: float = 0.2e-3,
    monotone_tolerance: float = 0.05,
    x_search_m: float = 1.5e-3,
) -> Plausibility:
    """Step 5a: is the baseline Â reasonable in value and shape compared with the nominal?

    Compared over ``u_range`` (default: where both are defined by knots, i.e. the baseline's
    covered range within the nominal's). Returns :class:`Plausibility`; ``ok`` is False with the
    failed checks in ``reasons``.
    """
    lo = max(baseline.u_range[0], nominal.u_range[0])
    hi = min(baseline.u_range[1], nominal.u_range[1])
    if u_range is not None:
        lo, hi = max(lo, u_range[0]), min(hi, u_range[1])
    limits = {
        "ratio_bounds": ratio_bounds,
        "max_rel_rms": max_rel_rms,
        "max_shape_error": max_shape_error,
        "max_shift_m": max_shift_m,
        "monotone_tolerance": monotone_tolerance,
    }
    if not hi > lo:
        nan = float("nan")
        return Plausibility(False, ("no common u-range",), lo, hi, nan, nan, nan, nan, nan, nan, nan, limits)
    g = np.linspace(lo, hi, n_grid)
    b = baseline.evaluate(g)
    nv = nominal.evaluate(g)
    reasons: list[str] = []

    scale = float(b @ nv / (nv @ nv)) if nv @ nv > 0 else float("nan")
    rel_rms = float(np.sqrt(np.mean((b - nv) ** 2)) / np.sqrt(np.mean(nv**2)))
    gc = g - g.mean()
    slope_b = float(gc @ b / (gc @ gc))
    slope_n = float(gc @ nv / (gc @ gc))
    slope_ratio = slope_b / slope_n if slope_n > 0 else float("nan")
    mean_slope_n = (nv[-1] - nv[0]) / (hi - lo)
    # segments of the baseline that overlap (lo, hi)
    k = baseline.knots_u_m
    seg = (k[1:] > lo) & (k[:-1] < hi)
    min_rel_slope = float(baseline.segment_slopes[seg].min() / mean_slope_n) if mean_slope_n > 0 else float("nan")

    res = fit_arrays(
        g, b, np.array([0, n_grid]), [nominal], x_bound_m=x_search_m, min_points=3, min_coverage_m=0.0, n_grid=121
    )
    alpha0 = float(res["alpha_hat"][0])
    x0 = float(res["x_hat_m"][0])
    shape_error = float(res["e_m2"][0] / np.sqrt(np.mean(b**2))) if np.mean(b**2) > 0 else float("nan")

    lo_r, hi_r = ratio_bounds
    if not (mean_slope_n > 0 and slope_n > 0):
        reasons.append("nominal characteristic not increasing over the range")
    if not lo_r <= scale <= hi_r:
        reasons.append(f"value scale {scale:.3g} outside [{lo_r:.3g}, {hi_r:.3g}]")
    if not lo_r <= slope_ratio <= hi_r:
        reasons.append(f"slope ratio {slope_ratio:.3g} outside [{lo_r:.3g}, {hi_r:.3g}]")
    if not rel_rms <= max_rel_rms:
        reasons.append(f"relative RMS difference {rel_rms:.3g} > {max_rel_rms:g}")
    if not shape_error <= max_shape_error:
        reasons.append(f"shape error {shape_error:.3g} > {max_shape_error:g}")
    if not abs(x0) <= max_shift_m:
        reasons.append(f"shift {x0 * 1e3:+.3f} mm beyond ±{max_shift_m * 1e3:g} mm")
    if not min_rel_slope >= -monotone_tolerance:
        reasons.append(f"not monotone (min segment slope {min_rel_slope:.3g} × nominal mean slope)")
    if res["status"][0] != "ok":
        reasons.append(f"scale/shift fit: {res['status'][0]}")
    return Plausibility(
        ok=not reasons,
        reasons=tuple(reasons),
        u_lo_m=float(lo),
        u_hi_m=float(hi),
        scale=scale,
        slope_ratio=slope_ratio,
        rel_rms=rel_rms,
        shape_error=shape_error,
        alpha_vs_nominal=alpha0,
        x_hat_vs_nominal_m=x0,
        min_rel_slope=min_rel_slope,
        limits=limits,
    )

"""Closed-edge leakage identified from the data (docs/monitoring.md, "Closed-edge leakage identified").

Eq. 7 with the closed edge subtracts, at every point of edge e, the flow through the other edge o
of its port: o's closed-branch area at −u_i times the pressure ratio

    ratio_i = sign(Δp_o) sqrt|Δp_o| / (sign(Δp_e) sqrt|Δp_e|).

The closed branch is a two-term family (:func:`closed_leakage`): Eq. 3's leakage branch at o's
state times λ₁ plus λ₂ times the same branch with worn lands (:func:`worn_branch`: equal to it at
the closing point, :data:`WORN_FACTOR` = 4 times it far from the edge), λ₁, λ₂ ≥ 0; (1, 0) is
Eq. 3's, (0, 0) no leakage (sharp edges). The two span the worn-lands branches of ``model.area``
(factors 1–4) to within about a per cent where the points lie, 1–3.5 mm inside the edge. The two regressors at the
points are :func:`leak_columns`; the coefficients are fitted at commissioning together with the
characteristic (:func:`transforms.baseline.leak_scale_lstsq`, called by
:func:`transforms.monitor.commissioning_baseline`), and reported as one number,
:func:`effective_scale`: the leakage over Eq. 3's :data:`LEAK_REF_M` inside the edge.

In a window, :func:`leak_scale_step` is the Gauss–Newton step of an extra leakage ℓ at the
(α̂, x̂) optimum (the residual projected off the fit's Jacobian Â(u + x̂), α̂ Â'(u + x̂)), on means
of consecutive equations, with its information ‖ℓ⊥‖²: its standard error is σ/‖ℓ⊥‖, widened like
the fit's intervals for the serial correlation of the residuals (:func:`inflation`). The monitor
reports it where it can resolve it (:data:`LEAK_RESOLUTION`), and holds the commissioning's
elsewhere; it never corrects with it (a window confounds it with α̂ and x̂).
"""

from __future__ import annotations

import numba
import numpy as np

from transforms.characteristic import Characteristic
from transforms.fit import walk_segment

__all__ = ["LEAK_REF_M", "LEAK_RESOLUTION", "WORN_FACTOR", "closed_leakage", "effective_scale", "inflation", "leak_columns", "leak_scale_step",
           "worn_branch"]


@numba.njit(cache=True)
def leak_scale_step(u, area, leak, offsets, ok, alpha, xhat, kstart, kend, kn, kv, ks, block):
    """Per population g (points offsets[g]:offsets[g+1] of ``u``, ``area`` = plain − λ_g ℓ and
    ``leak`` = ℓ; Â on kn[kstart[g]:kend[g]] with slopes ``ks``; (α̂, x̂) = (alpha[g], xhat[g]) where
    ``ok[g]``), on the means of ``block[g]`` consecutive points' equations (the load's ringing
    filtered out, as at commissioning): (step, info, sigma2, rho) — the Gauss–Newton step
    Δλ = ⟨ℓ⊥, r⟩ / ‖ℓ⊥‖², the information ‖ℓ⊥‖² [m⁴], the residual variance
    σ² = (‖r‖² − ⟨ℓ⊥, r⟩²/‖ℓ⊥‖²)/(M − 3) [m⁴] (M block means) and the lag-1 autocorrelation ρ of
    the block residuals. NaN where there is no estimate."""
    g_n = offsets.shape[0] - 1
    step = np.full(g_n, np.nan)
    info = np.full(g_n, np.nan)
    sigma2 = np.full(g_n, np.nan)
    rho = np.full(g_n, np.nan)
    for g in range(g_n):
        s = offsets[g]
        e = offsets[g + 1]
        bl = block[g]
        if not ok[g] or (e - s) // bl < 4:
            continue
        k0 = kstart[g]
        k1 = kend[g]
        al = alpha[g]
        x = xhat[g]
        s11 = s12 = s22 = l1 = l2 = ll = lr = r1 = r2 = rr = r11 = 0.0
        mb = md = mr = ml = 0.0
        cnt = 0
        m = 0
        prev = 0.0
        j = k0
        for i in range(s, e):
            t = u[i] + x
            j = walk_segment(kn, k0, k1, j, t)
            b = kv[j] + ks[j] * (t - kn[j])
            mb += b
            md += al * ks[j]
            mr += area[i] - al * b
            ml += leak[i]
            cnt += 1
            if cnt < bl and i < e - 1:
                continue
            b, d, r, lk = mb / cnt, md / cnt, mr / cnt, ml / cnt
            mb = md = mr = ml = 0.0
            cnt = 0
            s11 += b * b
            s12 += b * d
            s22 += d * d
            l1 += lk * b
            l2 += lk * d
            ll += lk * lk
            lr += lk * r
            r1 += b * r
            r2 += d * r
            rr += r * r
            if m > 0:
                r11 += r * prev
            prev = r
            m += 1
        det = s11 * s22 - s12 * s12
        if not det > 0.0:
            continue
        i11 = s22 / det
        i12 = -s12 / det
        i22 = s11 / det
        llp = ll - (l1 * (i11 * l1 + i12 * l2) + l2 * (i12 * l1 + i22 * l2))
        lrp = lr - (l1 * (i11 * r1 + i12 * r2) + l2 * (i12 * r1 + i22 * r2))
        if not llp > 0.0:
            continue
        step[g] = lrp / llp
        info[g] = llp
        sigma2[g] = max(rr - lrp * lrp / llp, 0.0) / (m - 3)
        rho[g] = r11 / rr if rr > 0.0 else 0.0
    return step, info, sigma2, rho


def inflation(rho: np.ndarray) -> np.ndarray:
    """sqrt((1 + ρ)/(1 − ρ)), ρ clipped to [0, 0.98]: the AR(1) long-run factor the fit's intervals use."""
    r = np.clip(np.nan_to_num(rho, nan=0.0), 0.0, 0.98)
    return np.sqrt((1.0 + r) / (1.0 - r))


LEAK_RESOLUTION = 1.0
"""A window resolves its own leakage only where its interval of ``leak_scale`` is narrower than
this: the distance from no leakage (0, sharp or linear edges) to Eq. 3's (1). A wider interval
cannot tell those two apart, so the window's number says nothing its commissioning did not: the
monitor then holds the commissioning's leakage and marks the row (``leak_scale_held``). Windows
of sparse motion or narrow coverage typically report intervals from 0 to 15-65."""


LEAK_REF_M = 1e-3
"""The effective leakage scale (``leak_scale``) compares the identified leakage with Eq. 3's this
far inside the closed edge (1 mm: where the monitor's points begin, the spool margin)."""


WORN_FACTOR = 4.0
"""The second leakage term is Eq. 3's branch with lands worn so that it leaks this many times
Eq. 3's far from the edge (:func:`worn_branch`)."""


def worn_branch(a, a_close: float) -> np.ndarray:
    """Eq. 3's leakage branch ``a`` = A_l(u) [m²] with worn lands, from its value ``a_close`` at the
    closing point [m²]: A_l = N/(c + d·w) (d the distance inside the edge) becomes N/(c + d·w/k),
    k = :data:`WORN_FACTOR`, i.e. 1/(1/a_c + (1/a − 1/a_c)/k) -- equal at the closing point, k
    times Eq. 3's far from it (``model.area``'s ``leakage_factor``). [m²]"""
    a = np.maximum(np.asarray(a, dtype=np.float64), 1e-300)
    return 1.0 / (1.0 / a_close + (1.0 / a - 1.0 / a_close) / WORN_FACTOR)


def closed_leakage(char: Characteristic, u_close: float, lam) -> Characteristic:
    """α·A of an edge over the whole stroke with its closed branch (u < ``u_close``, the closing
    point) replaced by λ₁·A(u) + λ₂·W(u), W the branch with worn lands (:func:`worn_branch`): Eq. 3's
    branch scaled, plus a worn-lands one. [m²]"""
    k = char.knots_u_m
    keep = k < u_close
    knots = np.append(k[keep], [u_close, *k[~keep & (k > u_close)]])
    vals = char.evaluate(knots)
    vc = float(char.evaluate(u_close))
    below = knots < u_close
    vals[below] = lam[0] * vals[below] + lam[1] * worn_branch(vals[below], vc)
    return Characteristic(knots, vals)


def leak_columns(char: Characteristic, u_close: float, u: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """The two leakage regressors of the closed edge at the points (its opening coordinate −u):
    A(−u)·ratio and W(−u)·ratio (:func:`worn_branch`), shape (n, 2). [m²]"""
    a = char.evaluate(-u)
    return np.column_stack([a * ratio, worn_branch(a, float(char.evaluate(u_close))) * ratio])


def effective_scale(char: Characteristic, u_close: float, lam, cov) -> tuple[float, float]:
    """(λ_eff, its standard error): the identified leakage over Eq. 3's at :data:`LEAK_REF_M`
    inside the closed edge; 1 = Eq. 3, 0 = none."""
    a_ref = float(char.evaluate(u_close - LEAK_REF_M))
    g = np.array([1.0, float(worn_branch(a_ref, float(char.evaluate(u_close)))) / a_ref])
    return float(g @ np.asarray(lam)), float(np.sqrt(max(g @ np.asarray(cov) @ g, 0.0)))

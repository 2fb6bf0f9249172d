"""Student's t quantile for integer degrees of freedom, with numpy and the standard library only.

The fits' confidence intervals (Eq. 8's α̂ and x̂, the windows' leakage scale) need the quantile
t_ν(p) of Student's t distribution. scipy's ``stdtrit`` gives it, but importing
``scipy.special`` costs every monitor command ~0.3 s of CPU; this module gives the same values
(within a few units in the last place, ``tests/model/test_student_t.py``) without it:

* ν ≥ :data:`EXPANSION_MIN_DOF`: the Cornish–Fisher expansion of t in powers of 1/ν around the
  normal quantile x (Abramowitz & Stegun 26.7.5, four terms); its error is O(x¹¹/ν⁵), below
  10⁻¹⁴ relative for p ≤ 0.9995 from ν = 1,000 on;
* smaller ν: Newton's method on the exact distribution function of integer ν (A&S 26.7.3 and
  26.7.4, a finite series in cos θ, θ = atan(t/√ν)), started from that expansion (or from
  the normal quantile when ν is too small for it).
"""

from __future__ import annotations

import math
from functools import lru_cache
from statistics import NormalDist

import numpy as np

EXPANSION_MIN_DOF = 1000
"""Degrees of freedom from which the expansion alone is used (its error: module docstring)."""


def _expansion(dof: np.ndarray, x: float) -> np.ndarray:
    """A&S 26.7.5: t ≈ x + g₁/ν + g₂/ν² + g₃/ν³ + g₄/ν⁴ around the normal quantile x."""
    x2 = x * x
    g1 = (x2 + 1.0) * x / 4.0
    g2 = ((5.0 * x2 + 16.0) * x2 + 3.0) * x / 96.0
    g3 = (((3.0 * x2 + 19.0) * x2 + 17.0) * x2 - 15.0) * x / 384.0
    g4 = ((((79.0 * x2 + 776.0) * x2 + 1482.0) * x2 - 1920.0) * x2 - 945.0) * x / 92160.0
    return x + (g1 + (g2 + (g3 + g4 / dof) / dof) / dof) / dof


def _central_probability(t: float, dof: int) -> float:
    """P(|T| < t) for T ~ t_ν, ν a positive integer, t ≥ 0 (A&S 26.7.3 odd ν, 26.7.4 even ν)."""
    theta = math.atan(t / math.sqrt(dof))
    s, c = math.sin(theta), math.cos(theta)
    c2 = c * c
    if dof % 2:
        # (2/π)[θ + sin θ (cos θ + (2/3) cos³θ + … + (2·4···(ν−3))/(1·3···(ν−2)) cos^(ν−2)θ)]
        k = np.arange(1, (dof - 1) // 2)
        terms = np.cumprod(np.concatenate(([c], (2.0 * k) / (2.0 * k + 1.0) * c2)))
        return 2.0 / math.pi * (theta + (s * terms.sum() if dof > 1 else 0.0))
    # sin θ [1 + (1/2) cos²θ + (1·3)/(2·4) cos⁴θ + … + (1·3···(ν−3))/(2·4···(ν−2)) cos^(ν−2)θ]
    k = np.arange(1, dof // 2)
    terms = np.cumprod(np.concatenate(([1.0], (2.0 * k - 1.0) / (2.0 * k) * c2)))
    return s * terms.sum()


@lru_cache(maxsize=4096)
def _small_dof_quantile(dof: int, p: float) -> float:
    """t_ν(p) for ν < :data:`EXPANSION_MIN_DOF`, p > 1/2: Newton's method on the exact P(|T| < t)."""
    x = NormalDist().inv_cdf(p)
    t = float(_expansion(np.float64(dof), x)) if dof >= 20 else x
    target = 2.0 * p - 1.0
    log_norm = math.lgamma((dof + 1) / 2.0) - math.lgamma(dof / 2.0) - 0.5 * math.log(dof * math.pi)
    for _ in range(100):
        density = math.exp(log_norm - (dof + 1) / 2.0 * math.log1p(t * t / dof))
        step = (_central_probability(t, dof) - target) / (2.0 * density)
        t_next = max(t - step, t / 2.0)  # P(|T| < t) is concave for t > 0: never step below 0
        if abs(step) <= 1e-12 * t:  # quadratic convergence: this step left ~1e-24, rounding aside
            return t_next
        t = t_next
    return t


def t_quantile(dof, p) -> np.ndarray:
    """Student's t quantile t_ν(p) [-] for integer degrees of freedom ``dof`` ≥ 1 and
    probabilities 1/2 < p < 1 (arrays, broadcast; scipy's ``stdtrit(dof, p)``); NaN where
    ``dof`` is not ≥ 1."""
    dof, p = np.broadcast_arrays(np.asarray(dof, dtype=np.float64), np.asarray(p, dtype=np.float64))
    if not np.all((p > 0.5) & (p < 1.0)):
        raise ValueError(f"p must lie in (0.5, 1), got {p[~((p > 0.5) & (p < 1.0))].ravel()[0]}")
    out = np.full(dof.shape, np.nan)
    for q in np.unique(p):
        at = p == q
        large = at & (dof >= EXPANSION_MIN_DOF)
        out[large] = _expansion(dof[large], NormalDist().inv_cdf(float(q)))
        small = at & (dof >= 1) & ~large
        for v in np.unique(dof[small]):
            out[small & (dof == v)] = _small_dof_quantile(int(v), float(q))
    return out

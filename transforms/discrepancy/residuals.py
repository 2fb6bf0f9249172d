"""Residuals of the model's equations on measured data.

Per-sample terms come from the model (``model.effects.equation_terms``, passed in as arrays:
this package does not import the model): q1, q2, the extra chamber flows ql1, ql2, the chamber
compliances c1 = V1/β_e(p1), c2 = V2/β_e(p2), the true pressures, the force m g + A1 p1 − A2 p2 −
F_f(v_X) and the mass.

Two forms:

* **pointwise** (:func:`pointwise_residuals`), with Savitzky–Golay derivatives, what the report
  shows per operating region:

      r1 = q1 − A1 v_X − ql1 − c1 dp1/dt           [m³/s]   (chamber 1, Eq. 6)
      r2 = A2 v_X − q2 − ql2 − c2 dp2/dt           [m³/s]   (chamber 2, Eq. 6)
      rm = force − F_l − m dv_X/dt                  [N]      (motion, Eq. 5; moving samples)

* **integrated** (:func:`interval_residuals`), what the selection regresses: each chamber
  equation integrated over intervals of L samples and the motion equation over two intervals,

      r1_i = ( ∫ (q1 − ql1) dt − A1 ΔX − ∫ c1 dp1 ) / T
      r2_i = ( A2 ΔX − ∫ (q2 + ql2) dt − ∫ c2 dp2 ) / T
      rm_i = Σ_j w_j force_j − m (X_{i+1} − 2 X_i + X_{i−1}) / T²      (w triangular, Σ w = 1)

  (trapezoidal sums over the raw samples; T = L Δt). They need no derivative of p or X: the
  Savitzky–Golay filter's small gain error at the hydraulic mode (~1 % at 25 Hz, monitoring
  docs) would otherwise look like a compressibility change and bias the entrained-air and
  sensor-gain candidates. rm_i carries no load term: the load is one unknown constant per load
  segment, removed by demeaning within segments (:func:`demean_by_group`).

  Every integrated term is further averaged over ``smooth`` shifts of the interval (a boxcar on
  the running integrals before they are differenced): the same linear filter on every term of
  a linear relation, so the equations still hold exactly, while the measurement noise at the
  interval ends is averaged. Without it the compliance term ∫ c(p) dp would carry the endpoint
  pressure noise with a coefficient that grows with the entrained air, the same noise as in the
  regressor (errors in variables): the air fraction was underestimated by ~10 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = [
    "INTEGRALS_OF",
    "IntervalResiduals",
    "demean_by_group",
    "interval_edges",
    "interval_integrals",
    "interval_residuals",
    "pointwise_residuals",
    "residuals_of_integrals",
    "triangular_force_balance",
]


def interval_edges(n: int, length: int, offset: int = 0) -> np.ndarray:
    """Sample indices offset, offset + L, … ≤ n − 1 that bound the integration intervals."""
    if length < 1:
        raise ValueError("length must be >= 1")
    return np.arange(offset, n, length, dtype=np.int64)


def _cum_trapz(y: np.ndarray, dt: float) -> np.ndarray:
    out = np.zeros(y.size)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1])) * dt
    return out


def _cum_stieltjes(c: np.ndarray, p: np.ndarray) -> np.ndarray:
    out = np.zeros(p.size)
    out[1:] = np.cumsum(0.5 * (c[1:] + c[:-1]) * np.diff(p))
    return out


@dataclass(frozen=True)
class IntervalResiduals:
    """Integrated residuals of one record.

    Attributes
    ----------
    r1, r2 : ndarray, shape (m,)
        Chamber residuals of the intervals [edges[i], edges[i+1]]. [m³/s]
    t_cont : ndarray, shape (m,)
        Mid time of each chamber interval. [s]
    rm : ndarray, shape (m − 1,)
        Motion residual (no load) centred at edges[1:-1]. [N]
    t_motion : ndarray, shape (m − 1,)
        Its time. [s]
    """

    r1: np.ndarray
    r2: np.ndarray
    t_cont: np.ndarray
    rm: np.ndarray
    t_motion: np.ndarray


def box_at(y: np.ndarray, at: np.ndarray, m: int) -> np.ndarray:
    """Centred moving averages of ``y`` over m (odd) samples, at the sample indices ``at`` only
    (a dot product per index, not a convolution of the whole record); NaN within m // 2 of the
    ends."""
    y = np.asarray(y, float)
    if m <= 1:
        return y[at]
    h = m // 2
    inside = (at >= h) & (at < y.size - h)
    out = np.full(at.size, np.nan)
    out[inside] = sliding_window_view(y, m)[at[inside] - h] @ np.full(m, 1.0 / m)
    return out


INTEGRALS_OF: dict[str, tuple[str, ...]] = {"Q1": ("q1", "ql1"), "Q2": ("q2", "ql2"), "C1": ("c1", "p1"), "C2": ("c2", "p2"), "fw": ("force",)}
"""The terms each of :func:`interval_integrals`' integrals depends on (besides the record's X)."""


def interval_integrals(terms: dict, X: np.ndarray, dt: float, edges: np.ndarray, smooth: int = 1, only=None) -> dict[str, np.ndarray]:
    """The integrals the integrated residuals (:func:`interval_residuals`) are differences of,
    boxcar'd over ``smooth`` shifts, at the interval ``edges``: ``Q1`` = ∫ (q1 − ql1) dt,
    ``Q2`` = ∫ (q2 + ql2) dt [m³], ``C1`` = ∫ c1 dp1, ``C2`` = ∫ c2 dp2 [m³], ``Xs`` = X [m], and
    at the inner edges ``fw`` = Σ_j w_j force_j (triangular w over two intervals, Σ w = 1) [N].
    ``only``: compute just these (default all); an integral depends only on its
    :data:`INTEGRALS_OF` terms, so the others of a model that changed no such term can be kept."""
    e = np.asarray(edges, dtype=np.int64)
    if e.size < 3:
        raise ValueError("need at least 3 interval edges")
    L = int(e[1] - e[0])
    if np.any(np.diff(e) != L):
        raise ValueError("interval edges must be equally spaced")
    m = int(smooth)
    if m < 1 or m % 2 != 1:
        raise ValueError("smooth must be odd and >= 1")
    want = ("Q1", "Q2", "C1", "C2", "Xs", "fw") if only is None else only
    out = {}
    # the boxcar'd running integrals and X, at the interval edges only
    if "Q1" in want:
        out["Q1"] = box_at(_cum_trapz(terms["q1"] - terms["ql1"], dt), e, m)
    if "Q2" in want:
        out["Q2"] = box_at(_cum_trapz(terms["q2"] + terms["ql2"], dt), e, m)
    if "C1" in want:
        out["C1"] = box_at(_cum_stieltjes(terms["c1"], terms["p1"]), e, m)
    if "C2" in want:
        out["C2"] = box_at(_cum_stieltjes(terms["c2"], terms["p2"]), e, m)
    if "Xs" in want:
        out["Xs"] = box_at(X, e, m)
    if "fw" in want:
        # motion: triangular weights over [e_{i-1}, e_{i+1}] (Σ w = 1), then the same boxcar, at
        # the inner edges only
        f = np.asarray(terms["force"], float)
        k = np.arange(-L, L + 1)
        w = (L - np.abs(k)) / float(L * L)
        if m > 1:
            w = np.convolve(w, np.full(m, 1.0 / m))
        c = e[1:-1]
        H = w.size // 2
        fw = np.full(c.size, np.nan)
        if f.size >= w.size:  # zeros beyond the record's ends
            fw = sliding_window_view(np.pad(f, H), w.size)[c] @ w
        out["fw"] = fw
    return out


def residuals_of_integrals(integrals: dict, mass: float, A1: float, A2: float, dt: float, edges: np.ndarray) -> IntervalResiduals:
    """The integrated residuals (module docstring) from :func:`interval_integrals`' values."""
    e = np.asarray(edges, dtype=np.int64)
    T = int(e[1] - e[0]) * dt
    Q1, Q2, C1, C2, Xs = (integrals[k] for k in ("Q1", "Q2", "C1", "C2", "Xs"))
    a, b = e[:-1], e[1:]
    dX = np.diff(Xs)
    r1 = (np.diff(Q1) - A1 * dX - np.diff(C1)) / T
    r2 = (A2 * dX - np.diff(Q2) - np.diff(C2)) / T
    ddX = Xs[2:] - 2.0 * Xs[1:-1] + Xs[:-2]
    rm = integrals["fw"] - mass * ddX / (T * T)
    return IntervalResiduals(r1=r1, r2=r2, t_cont=(a + b) * 0.5 * dt, rm=rm, t_motion=e[1:-1] * dt)


def interval_residuals(terms: dict, X: np.ndarray, A1: float, A2: float, dt: float, edges: np.ndarray, smooth: int = 1) -> IntervalResiduals:
    """Integrated residuals (module docstring) of one record over the intervals between
    ``edges`` (equally spaced sample indices). ``terms`` as from ``model.effects.equation_terms``
    (arrays over the record's samples); ``X`` the recorded cylinder position [m]; ``smooth`` the
    (odd) number of interval shifts averaged (the edges must lie ``smooth // 2`` inside the
    record)."""
    return residuals_of_integrals(interval_integrals(terms, X, dt, edges, smooth), terms["mass"], A1, A2, dt, edges)


def triangular_force_balance(force: np.ndarray, X: np.ndarray, mass: float, dt: float, length: int) -> np.ndarray:
    """At every sample k, Σ_j w_j force_{k+j} − m (X_{k+L} − 2 X_k + X_{k−L}) / T² with the
    triangular weights w over ±L samples (T = L Δt): the motion equation integrated twice, so
    it equals the (triangle-averaged) load F_l exactly when the model is right -- no
    acceleration estimate and hence no filter mismatch at the hydraulic mode. NaN within L of
    the ends. [N]"""
    L = int(length)
    n = force.size
    out = np.full(n, np.nan)
    if n < 2 * L + 1:
        return out
    k = np.arange(-L, L + 1)
    w = (L - np.abs(k)) / float(L * L)
    fw = np.convolve(np.asarray(force, float), w, mode="valid")  # centred at L … n − L − 1
    c = np.arange(L, n - L)
    T = L * dt
    out[L:n - L] = fw - mass * (X[c + L] - 2.0 * X[c] + X[c - L]) / (T * T)
    return out


def pointwise_residuals(terms: dict, v: np.ndarray, a: np.ndarray, dp1: np.ndarray, dp2: np.ndarray, A1: float, A2: float, load: np.ndarray) -> dict[str, np.ndarray]:
    """Per-sample residuals with Savitzky–Golay derivatives (module docstring): ``r1``, ``r2``
    [m³/s] and ``rm`` [N]. ``dp1``, ``dp2`` are the derivatives of the *true* pressures."""
    r1 = terms["q1"] - A1 * v - terms["ql1"] - terms["c1"] * dp1
    r2 = A2 * v - terms["q2"] - terms["ql2"] - terms["c2"] * dp2
    rm = terms["force"] - load - terms["mass"] * a
    return {"r1": r1, "r2": r2, "rm": rm}


def demean_by_group(values: np.ndarray, group: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """``values`` (shape (n,) or (n, k)) minus their (weighted) mean within each group: the
    least-squares elimination of one free constant per group (Frisch–Waugh)."""
    v = np.asarray(values, float)
    g = np.asarray(group)
    if v.shape[0] == 0:
        return v.copy()
    uniq, inv = np.unique(g, return_inverse=True)
    wts = np.ones(v.shape[0]) if weights is None else np.asarray(weights, float)
    sw = np.bincount(inv, weights=wts, minlength=uniq.size)
    if v.ndim == 1:
        m = np.bincount(inv, weights=wts * v, minlength=uniq.size) / sw
        return v - m[inv]
    out = np.empty_like(v)
    for j in range(v.shape[1]):
        m = np.bincount(inv, weights=wts * v[:, j], minlength=uniq.size) / sw
        out[:, j] = v[:, j] - m[inv]
    return out

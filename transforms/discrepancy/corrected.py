"""Least squares with a noisy regressor's expected part taken out (a corrected score).

Where a recorded position's noise ε enters both a regressor and the rows -- the moving mass m
multiplies a second difference of the recorded cylinder position, and the rows hold the same
difference -- least squares reads the coefficient short (errors in variables: by m·K / (K + I),
K the noise's power along the mass per kg², I the data's information there). Subtracting K·m²
from the sum of squares makes its expectation the noise-free one
(:func:`corrected_lstsq`); K is capped (:func:`capped_mass_noise`) so the quadratic stays convex.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CORRECTION_SHARE", "capped_mass_noise", "corrected_lstsq"]


CORRECTION_SHARE = 0.5
"""The noise's correction of the normal equations takes at most this share of the data's
information along the mass (beyond it the mass is not identifiable from the rows anyway)."""


def capped_mass_noise(k: float, A: np.ndarray, g: np.ndarray) -> float:
    """``k`` at most :data:`CORRECTION_SHARE` of the information along ``g`` of the rows ``A``."""
    if k <= 0.0 or not np.any(g):
        return 0.0
    sc = np.sqrt(np.mean(A * A, axis=0))
    sc = np.where(sc > 0, sc, 1.0)
    gs = g / sc
    return float(min(k, CORRECTION_SHARE / float(gs @ np.linalg.pinv((A / sc).T @ (A / sc)) @ gs)))


def corrected_lstsq(A: np.ndarray, b: np.ndarray, g: np.ndarray, k: float, m0: float) -> tuple[np.ndarray, float]:
    """(x, objective) minimising |A x − b|² − k (m0 + g·x)² (columns scaled to unit RMS): least
    squares with the position noise's expected part of the mass term taken out (module docstring;
    ``k`` as :func:`capped_mass_noise`, so that the quadratic stays convex)."""
    sc = np.sqrt(np.mean(A * A, axis=0))
    sc = np.where(sc > 0, sc, 1.0)
    As, gs = A / sc, g / sc
    if k <= 0.0 or not np.any(gs):
        x, *_ = np.linalg.lstsq(As, b, rcond=None)
    else:
        x = np.linalg.pinv(As.T @ As - k * np.outer(gs, gs)) @ (As.T @ b + k * m0 * gs)
    x = x / sc
    return x, float(np.sum((A @ x - b) ** 2) - k * (m0 + g @ x) ** 2)

"""The spool and cylinder positions the discrepancy workflow works with, reconstructed from the
recorded ones (:func:`transforms.discrepancy.records.prepare_record`).

Plants record positions noisily: a spool LVDT 0.1–0.3 % of its stroke (7 µm at 0.2 % of Table 1's
3.5 mm), a cylinder transducer 5–20 µm in steps of a few µm. The chamber equations and replays
take the spool position through the flows and the cylinder's through its velocity (β/V1 · A1 ·
10 µm is ~0.4 bar on Table 1's cylinder), and the load fit takes its acceleration. Savitzky–Golay
(21 samples, cubic) leaves 2.3 µm of the spool's 7 µm, and of the cylinder's 10 µm 0.9 mm/s of
velocity and 0.14 m/s² of acceleration (half of a busy cylinder's RMS acceleration, 0.3 m/s²):
the reference plant's clean valve then read as a 500–1000 kg mass change.

* **Spool** (:func:`spool_from_reference`): where the controller's output x_ref is recorded, the
  spool follows it through Eq. 1 (T, ζ, v_max of the plant's data); the recorded position only
  sets its offset, their difference smoothed over ``spool_offset_s`` (1 s: the reference
  plant's spool drifts from Eq. 1's response by 0.4–0.8 µm within a window; over 0.5 s the
  reconstruction came to 0.29–0.34 µm from the truth, 1 s 0.26–0.39, 2 s 0.33–0.91, the whole
  10 s record 0.48–1.08; Savitzky–Golay 2.3–2.4). A spool whose reading the response does not follow within its
  noise (the plant's spool is not Eq. 1 with these data) keeps its Savitzky–Golay value.
* **Cylinder** (:func:`cylinder_states`): a Rauch–Tung–Striebel smoother of X, v_X, a_X with
  white jerk, the measurement noise estimated from the record and the jerk's intensity the one
  that predicts each sample best from the others (leave-one-out; the likelihood chose a jerk
  10× too large at 1 µm). Noisy end: 0.29–0.31 mm/s and 0.054–0.062 m/s² from the truth (SG
  0.90–0.93, 0.136–0.139); at 1 µm 0.066–0.068 and 0.024–0.025 (SG 0.098–0.100, 0.035–0.038). A
  smoother on the motion equation (the recorded pressures as its input, the load a random walk)
  came to 0.20–0.31 mm/s and 0.038–0.061 m/s², but it reads the acceleration through the
  model's own mass and friction, so a changed mass or friction would be smoothed into the
  model's: not taken.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.ndimage import uniform_filter1d

from model.params import SpoolParams
from model.spool import spool_acceleration_kernel

__all__ = ["JERK_GRID", "cylinder_states", "spool_from_reference", "spool_response", "straight_lines"]

SPOOL_SUBSTEPS = 10
"""Explicit steps of Eq. 1 per sample (0.1 ms at 1 kHz, a tenth of Table 1's T)."""
SPOOL_SHIFTS = (-2, -1, 0, 1, 2)
"""Whole samples the reference's response may lead or lag the spool reading (:func:`spool_from_reference`)."""
SPOOL_FOLLOWS = 1.5
"""The reading follows the reference's response where what is left of their difference, the
offset removed, is at most this many times the reading's noise (``noise``)."""
JERK_GRID = (0.1, 1.0, 10.0, 100.0, 1.0e3, 1.0e4)
"""Intensities of the cylinder's white jerk among which the record chooses (:func:`cylinder_states`). [m²/s⁵]"""
IMPULSE_SAMPLES = 1001
"""The smoother's weight on a sample is read off its response to an impulse this long (steady state)."""


@njit(cache=True)
def _spool_kernel(x_ref, dt, T, zeta, v_max, sub):
    n = x_ref.size
    out = np.empty(n)
    x, v = x_ref[0], 0.0
    h = dt / sub
    for k in range(n):
        for _ in range(sub):
            a = spool_acceleration_kernel(x, v, x_ref[k], T, zeta, v_max)
            v += h * a
            x += h * v
        out[k] = x
    return out


def spool_response(x_ref_m: np.ndarray, dt_s: float, spool: SpoolParams) -> np.ndarray:
    """The spool position that follows the reference ``x_ref_m`` [m] through Eq. 1 from rest at
    its first value, sampled every ``dt_s`` [s]. [m]"""
    return _spool_kernel(np.ascontiguousarray(x_ref_m, dtype=float), float(dt_s), spool.T_s, spool.zeta, spool.v_max_m_s, SPOOL_SUBSTEPS)


def straight_lines(y: np.ndarray, w: int) -> np.ndarray:
    """``y`` smoothed by straight lines over ``w`` samples (odd, at most ``y.size``): what
    ``scipy.signal.savgol_filter(y, w, 1)`` gives (a straight line's least squares over a
    centred window is the window's mean; within w/2 of an end, the end window's line), in O(n)
    instead of O(n w): at 1 s of 1 kHz records it took a fifth of a diagnosis."""
    h = w // 2
    out = uniform_filter1d(y, w, mode="nearest")
    t = np.arange(w, dtype=float)
    for window, at in ((slice(0, w), slice(0, h)), (slice(y.size - w, y.size), slice(w - h, w))):
        slope, level = np.polyfit(t, y[window], 1)
        out[window][at] = level + slope * t[at]
    return out


def spool_from_reference(x_m: np.ndarray, x_ref_m: np.ndarray | None, dt_s: float, spool: SpoolParams, noise: float, offset_s: float) -> np.ndarray | None:
    """The spool position [m]: Eq. 1's response to ``x_ref_m``, shifted by the whole samples of
    ``SPOOL_SHIFTS`` that fit the reading best (recorders stamp the reference and the spool
    a sample apart either way), plus the recorded reading's offset from it (their difference
    smoothed by straight lines over ``offset_s`` [s]); None where the reading does not follow
    the response within ``SPOOL_FOLLOWS`` × its ``noise`` [m]."""
    w = min(int(round(offset_s / dt_s)), x_m.size)
    w -= 1 - w % 2  # odd
    if x_ref_m is None or w < 5 or not np.all(np.isfinite(x_ref_m)) or not noise > 0:
        return None
    response = spool_response(x_ref_m, dt_s, spool)
    reading = np.asarray(x_m, float)
    best, left = None, np.inf
    for k in SPOOL_SHIFTS:
        shifted = np.roll(response, k)
        if k > 0:
            shifted[:k] = response[0]
        elif k < 0:
            shifted[k:] = response[-1]
        diff = reading - shifted
        offset = straight_lines(diff, w)
        rms = float(np.sqrt(np.mean((diff - offset) ** 2)))
        if rms < left:
            best, left = shifted + offset, rms
    return best if left <= SPOOL_FOLLOWS * noise else None


@njit(cache=True)
def _smooth(y, dt, r, q):
    """The Rauch–Tung–Striebel smoother (forward Kalman filter, backward pass) of the white-jerk
    model of y, states (n, 3). Written out in scalars: no array is made per sample, and the
    backward pass solves with the predicted covariance's Cholesky factor instead of inverting it
    (14× faster than ``Pf A^T inv(Pp)`` per sample; the states agree to 3e-10 of their range)."""
    n = y.size
    A = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = q * np.array([[dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0], [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0], [dt**3 / 6.0, dt**2 / 2.0, dt]])
    xf = np.zeros((n, 3))
    Pf = np.zeros((n, 3, 3))
    Pp = np.zeros((n, 3, 3))
    x = np.array([y[0], 0.0, 0.0])
    xp = np.zeros(3)
    P = np.zeros((3, 3))
    P[0, 0], P[1, 1], P[2, 2] = r, 1.0, 1.0e4
    AP = np.zeros((3, 3))
    K = np.zeros(3)
    for k in range(n):
        if k > 0:
            for i in range(3):
                xp[i] = A[i, 0] * x[0] + A[i, 1] * x[1] + A[i, 2] * x[2]
            for i in range(3):
                for j in range(3):
                    AP[i, j] = A[i, 0] * P[0, j] + A[i, 1] * P[1, j] + A[i, 2] * P[2, j]
            for i in range(3):
                for j in range(3):
                    P[i, j] = AP[i, 0] * A[j, 0] + AP[i, 1] * A[j, 1] + AP[i, 2] * A[j, 2] + Q[i, j]
            x[:] = xp
        Pp[k] = P
        s = P[0, 0] + r
        nu = y[k] - x[0]
        for i in range(3):
            K[i] = P[i, 0] / s
        for i in range(3):
            x[i] += K[i] * nu
        for i in range(3):
            for j in range(3):
                AP[i, j] = P[i, j] - K[i] * P[0, j]
        P[:, :] = AP
        xf[k] = x
        Pf[k] = P
    xs = xf.copy()
    L = np.zeros((3, 3))
    d = np.zeros(3)
    c = np.zeros(3)
    for k in range(n - 2, -1, -1):
        # xs_k = xf_k + Pf_k A^T Pp_{k+1}^-1 (xs_{k+1} - A xf_k): Pp_{k+1} w = d solved with its
        # Cholesky factor (symmetric positive definite: Q is), not inverted
        S = Pp[k + 1]
        L[0, 0] = np.sqrt(S[0, 0])
        L[1, 0] = S[1, 0] / L[0, 0]
        L[2, 0] = S[2, 0] / L[0, 0]
        L[1, 1] = np.sqrt(S[1, 1] - L[1, 0] * L[1, 0])
        L[2, 1] = (S[2, 1] - L[2, 0] * L[1, 0]) / L[1, 1]
        L[2, 2] = np.sqrt(S[2, 2] - L[2, 0] * L[2, 0] - L[2, 1] * L[2, 1])
        for i in range(3):
            d[i] = xs[k + 1, i] - (A[i, 0] * xf[k, 0] + A[i, 1] * xf[k, 1] + A[i, 2] * xf[k, 2])
        w0 = d[0] / L[0, 0]
        w1 = (d[1] - L[1, 0] * w0) / L[1, 1]
        w2 = (d[2] - L[2, 0] * w0 - L[2, 1] * w1) / L[2, 2]
        w2 = w2 / L[2, 2]
        w1 = (w1 - L[2, 1] * w2) / L[1, 1]
        w0 = (w0 - L[1, 0] * w1 - L[2, 0] * w2) / L[0, 0]
        for i in range(3):
            c[i] = A[0, i] * w0 + A[1, i] * w1 + A[2, i] * w2
        for i in range(3):
            xs[k, i] = xf[k, i] + Pf[k, i, 0] * c[0] + Pf[k, i, 1] * c[1] + Pf[k, i, 2] * c[2]
    return xs


def cylinder_states(X_m: np.ndarray, dt_s: float, noise: float) -> np.ndarray:
    """(X [m], v_X [m/s], a_X [m/s²]) of the recorded cylinder position, shape (3, n): the
    Rauch–Tung–Striebel smoother of white jerk, measurement noise ``noise`` [m], the jerk's
    intensity the one of ``JERK_GRID`` that predicts each recorded sample best from the others
    (leave-one-out: the residual over 1 − h, h the smoother's weight on the sample itself)."""
    y = np.ascontiguousarray(X_m, dtype=float)
    dt, r = float(dt_s), max(float(noise), 1.0e-9) ** 2
    impulse = np.zeros(IMPULSE_SAMPLES)
    impulse[IMPULSE_SAMPLES // 2] = 1.0
    best, best_score = None, np.inf
    for q in JERK_GRID:
        xs = _smooth(y, dt, r, q)
        h = _smooth(impulse, dt, r, q)[IMPULSE_SAMPLES // 2, 0]
        score = float(np.mean(((y - xs[:, 0]) / (1.0 - h)) ** 2))
        if score < best_score:
            best, best_score = xs, score
    return best.T.copy()

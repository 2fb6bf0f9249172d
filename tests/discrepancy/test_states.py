"""The reconstructed positions (transforms/discrepancy/states.py): Eq. 1's step response against
its closed form, the smoother on a known trajectory, and both on the second reference plant at
the noisy end of plant sensors, against its true spool and cylinder."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import savgol_filter

from model.params import SpoolParams
from tests.refplant import NAMEPLATE, manufactured, noisy_end, simulate_windows
from transforms.discrepancy.records import savgol
from transforms.discrepancy.states import cylinder_states, spool_from_reference, spool_response, straight_lines

DT = 1.0e-3


def test_spool_response_is_the_critically_damped_step_response():
    """ζ = 1, T = 1 ms, a 10 µm step (peak speed 3.7 mm/s, far below v_max): x(t) = Δ (1 − (1 + t/T) e^(−t/T))."""
    sp = SpoolParams()
    ref = np.r_[np.zeros(5), np.full(60, 10e-6)]
    x = spool_response(ref, DT, sp)
    t = (np.arange(60) + 1) * DT
    exact = 10e-6 * (1 - (1 + t / sp.T_s) * np.exp(-t / sp.T_s))
    np.testing.assert_allclose(x[5:], exact, atol=0.35e-6)  # explicit steps of 0.1 ms: 0.31 µm at the first sample
    assert np.all(x[:5] == 0.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 400), st.integers(0, 1200), st.integers(0, 2**32 - 1))
def test_straight_lines_are_savitzky_golay_of_order_one(half, extra, seed):
    """The spool offset's smoothing in O(n) gives scipy's savgol_filter(y, w, 1) (interp ends) to
    rounding, on any length from one window up, for an offset, a slope and noise."""
    w = 2 * half + 1
    rng = np.random.default_rng(seed)
    n = w + extra
    y = 1e-4 + 3e-6 * np.arange(n) / n + rng.normal(0.0, 7e-6, n)
    np.testing.assert_allclose(straight_lines(y, w), savgol_filter(y, w, 1), rtol=0, atol=1e-15)


def test_spool_speed_is_limited_to_v_max():
    sp = SpoolParams()
    x = spool_response(np.r_[0.0, np.full(40, 3e-3)], DT, sp)
    assert np.max(np.diff(x)) <= sp.v_max_m_s * DT * (1 + 1e-9)


def test_a_reading_that_does_not_follow_the_reference_keeps_its_own_value():
    rng = np.random.default_rng(3)
    ref = np.sin(np.arange(4000) * DT * 2 * np.pi) * 1e-3
    follows = spool_response(ref, DT, SpoolParams()) + 2e-6 + rng.normal(0, 5e-6, ref.size)
    assert spool_from_reference(follows, ref, DT, SpoolParams(), 5e-6, 1.0) is not None
    assert spool_from_reference(-ref, ref, DT, SpoolParams(), 5e-6, 1.0) is None
    assert spool_from_reference(ref, None, DT, SpoolParams(), 5e-6, 1.0) is None


@pytest.mark.parametrize("seed", [0, 1])
def test_smoother_beats_savitzky_golay_on_a_smooth_move(seed):
    """X = 50 mm · sin(2π 0.4 t) with 10 µm of white noise: the smoother's velocity and
    acceleration errors are below half of Savitzky–Golay's (21, cubic)."""
    t = np.arange(8000) * DT
    w = 2 * np.pi * 0.4
    X, v, a = 0.05 * np.sin(w * t), 0.05 * w * np.cos(w * t), -0.05 * w * w * np.sin(w * t)
    y = X + np.random.default_rng(seed).normal(0, 10e-6, t.size)
    Xs, vs, as_ = cylinder_states(y, DT, 10e-6)
    inner = slice(50, -50)
    rms = lambda e: float(np.sqrt(np.mean(e[inner] ** 2)))  # noqa: E731
    assert rms(vs - v) < 0.5 * rms(savgol(y, 21, 3, 1, DT) - v)
    assert rms(as_ - a) < 0.5 * rms(savgol(y, 21, 3, 2, DT) - a)
    assert rms(Xs - X) < 4e-6


@pytest.mark.parametrize("noise, q", [(1e-6, 0.1), (10e-6, 1e4)])
def test_the_smoother_is_the_rauch_tung_striebel_recursion(noise, q):
    """The compiled smoother (scalars; the backward pass a Cholesky solve) against the textbook
    recursion in matrices: Kalman filter forward, then xs_k = xf_k + Pf_k Aᵀ Pp_{k+1}⁻¹ (xs_{k+1} −
    A xf_k), with np.linalg.solve; a noisy move of 400 samples, the jerk's intensities at both ends
    of the grid."""
    from transforms.discrepancy.states import _smooth

    t = np.arange(400) * DT
    y = 0.02 * np.sin(2 * np.pi * 1.5 * t) + np.random.default_rng(7).normal(0, noise, t.size)
    r = noise**2
    A = np.array([[1.0, DT, DT * DT / 2], [0.0, 1.0, DT], [0.0, 0.0, 1.0]])
    Q = q * np.array([[DT**5 / 20, DT**4 / 8, DT**3 / 6], [DT**4 / 8, DT**3 / 3, DT**2 / 2], [DT**3 / 6, DT**2 / 2, DT]])
    H = np.array([1.0, 0.0, 0.0])
    x, P = np.array([y[0], 0.0, 0.0]), np.diag([r, 1.0, 1.0e4])
    xf, Pf, Pp = [], [], []
    for k in range(y.size):
        if k:
            x, P = A @ x, A @ P @ A.T + Q
        Pp.append(P)
        K = P @ H / (H @ P @ H + r)
        x, P = x + K * (y[k] - H @ x), P - np.outer(K, H @ P)
        xf.append(x)
        Pf.append(P)
    xs = list(xf)
    for k in range(y.size - 2, -1, -1):
        xs[k] = xf[k] + Pf[k] @ A.T @ np.linalg.solve(Pp[k + 1], xs[k + 1] - A @ xf[k])
    expected = np.array(xs)
    got = _smooth(y, DT, r, q)
    for j in range(3):  # X, v_X, a_X, each to 1e-9 of its range
        np.testing.assert_allclose(got[:, j], expected[:, j], rtol=0, atol=1e-9 * np.abs(expected[:, j]).max())


def test_reference_plant_positions_at_the_noisy_end():
    """Spool 0.2 % of x_max (7 µm), cylinder 10 µm in 5 µm steps, valve seed 1: the spool within
    0.6 µm of the truth (Savitzky–Golay 2.3–2.4 µm), the cylinder's velocity within 0.45 mm/s (0.9)."""
    from transforms.discrepancy.records import noise_rms

    rec = simulate_windows(noisy_end(manufactured(NAMEPLATE, seed=1)), 1, 101)[0]
    x, X = rec.x_spool.astype(float), rec.x_cyl.astype(float)
    sd = {k: np.sqrt(np.divide(*noise_rms(y, savgol(y, 21, 3, 0, DT), 21, 3))) for k, y in (("x", x), ("X", X))}
    assert 6e-6 < sd["x"] < 8e-6 and 9e-6 < sd["X"] < 11.5e-6, sd
    inner = slice(100, -100)
    rms = lambda e: float(np.sqrt(np.mean(e[inner] ** 2)))  # noqa: E731
    spool = spool_from_reference(x, rec.x_ref.astype(float), DT, SpoolParams(), sd["x"], 1.0)
    assert spool is not None and rms(spool - rec.true["x"]) < 0.6e-6
    _, v, _ = cylinder_states(X, DT, sd["X"])
    assert rms(v - rec.true["vX"]) < 0.45e-3 < 0.5 * rms(savgol(X, 21, 3, 1, DT) - rec.true["vX"])

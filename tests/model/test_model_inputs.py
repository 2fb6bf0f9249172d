"""Controller, trajectories, load, supply and sensors."""

import numpy as np
import pytest

from model import (
    TABLE1,
    SensorChannel,
    draw_supply,
    feedforward,
    feedforward_table,
    load_profile,
    measure,
    pi_step,
    reference_trajectory,
    simulate_windows,
    standstill,
    window_inputs,
)
from model.trajectory import cosine_move

FS = 1000.0
TP = TABLE1.trajectory


def test_pi_saturation_and_anti_windup():
    x_lim = TABLE1.x_limit_m
    x_ref, integ = 0.0, 0.0
    for _ in range(5000):                       # 5 s of a huge error
        x_ref, integ = pi_step(1.0, integ, 0.0, TABLE1)
    assert x_ref == x_lim
    # back-calculation keeps the integrator near the saturation boundary
    assert integ < x_lim
    # the output leaves saturation at once when the error reverses
    x_ref, integ = pi_step(-0.01, integ, 0.0, TABLE1)
    assert x_ref < x_lim
    x_ref, _ = pi_step(-1.0, 0.0, 0.0, TABLE1)
    assert x_ref == -x_lim


def test_feedforward_table():
    grid, table = feedforward_table(TABLE1)
    assert np.all(np.diff(table) >= 0)
    assert np.all(np.abs(table) <= TABLE1.x_limit_m)
    assert feedforward(0.0, TABLE1) == pytest.approx(standstill(TABLE1).x_m, abs=1e-9)
    assert feedforward(0.2, TABLE1) > 1e-3 and feedforward(-0.1, TABLE1) < -1e-3
    assert feedforward(5.0, TABLE1) == TABLE1.x_limit_m


@pytest.mark.parametrize("seed", range(8))
def test_reference_trajectory(seed):
    rng = np.random.default_rng(seed)
    X, v = reference_trajectory(rng, 10.0, FS, TP)
    assert X.shape == v.shape == (10000,)
    assert X.min() >= TP.X_low_m - 1e-12 and X.max() <= TP.X_high_m + 1e-12
    assert np.all(v[: int(TP.first_dwell_s[0] * FS)] == 0.0)          # starts at rest
    # velocity consistent with the position, and continuous (bounded acceleration)
    np.testing.assert_allclose(np.gradient(X, 1 / FS), v, atol=2e-3)
    assert np.max(np.abs(np.diff(v))) * FS < 1.5 * np.pi * 0.24 / (2 * TP.ramp_s[0])
    assert v.max() > 0.1 and v.min() < -0.05                          # both directions
    assert np.all(v <= TP.v_extend_m_s[1] + 1e-12)
    assert np.all(v >= -TP.v_retract_m_s[1] - 1e-12)
    X2, v2 = reference_trajectory(np.random.default_rng(seed), 10.0, FS, TP)
    assert np.array_equal(X, X2) and np.array_equal(v, v2)


def test_cosine_move_profile():
    t = np.linspace(0, 5, 50001)
    p, v, T = cosine_move(t, 0.5, 0.1, 0.4, 0.2, 0.4)
    assert T == pytest.approx(0.8 + (0.3 / 0.2 - 0.4))
    assert p[0] == 0.1 and p[-1] == pytest.approx(0.4)
    assert v.max() == pytest.approx(0.2)
    np.testing.assert_allclose(np.gradient(p, t), v, atol=1e-4)
    p, v, T = cosine_move(t, 0.0, 0.4, 0.35, 0.2, 0.4)   # short move: lower peak speed
    assert T == pytest.approx(0.8) and v.min() == pytest.approx(-0.05 / 0.4, rel=1e-3)


def test_load_profile_piecewise_constant():
    rng = np.random.default_rng(1)
    F = load_profile(rng, 100.0, FS, TABLE1.load)
    assert np.all(np.abs(F) <= TABLE1.load.level_max_n)
    changes = np.count_nonzero(np.diff(F))
    assert 5 <= changes <= 40                   # ~0.2 per second
    assert np.mean(F == 0.0) > 0.2


def test_supply_profile_in_table1_range():
    rng = np.random.default_rng(2)
    t = np.arange(10000) / FS
    for _ in range(50):
        sp = draw_supply(rng, TABLE1.supply)
        ps = sp.p_s(t)
        assert 190e5 <= ps.min() and ps.max() <= 210e5
        assert 0.0 <= sp.p_r_pa <= 1e5
        assert np.ptp(ps) < 3e5


def test_sensors_noise_quantisation_and_determinism():
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 1.0, seed=5)
    m1 = measure(res, TABLE1.sensors, np.random.default_rng(0))
    m2 = measure(res, TABLE1.sensors, np.random.default_rng(0))
    for name in ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref", "t_s"):
        assert np.array_equal(getattr(m1, name), getattr(m2, name))
    s = TABLE1.sensors
    for name, true, ch in (("p1", res.p1_pa, s.p1), ("p2", res.p2_pa, s.p2),
                           ("x_spool", res.x_m, s.x_spool), ("x_cyl", res.X_m, s.x_cyl)):
        meas = getattr(m1, name)
        k = np.round(meas / ch.step)
        np.testing.assert_allclose(meas, k * ch.step, rtol=0, atol=1e-9 * ch.step)
        err = meas - true
        assert np.std(err) == pytest.approx(np.hypot(ch.noise_std, ch.step / np.sqrt(12)), rel=0.1)
        assert abs(np.mean(err)) < 0.1 * ch.noise_std
    np.testing.assert_allclose(m1.x_ref, res.x_ref_m, atol=s.x_ref.step)
    from model.sensors import measure_channel
    clipped = measure_channel(np.array([-1.0, 0.5, 2.0]), SensorChannel(0.0, 0.0, 0.0, 1.0),
                              np.random.default_rng(0))
    assert clipped.tolist() == [0.0, 0.5, 1.0]


def test_window_inputs_deterministic():
    a = window_inputs(TABLE1, 2.0, np.random.default_rng([1, 2]))
    b = window_inputs(TABLE1, 2.0, np.random.default_rng([1, 2]))
    assert np.array_equal(a.X_ref_m, b.X_ref_m) and np.array_equal(a.F_l_n, b.F_l_n)
    assert a.supply == b.supply

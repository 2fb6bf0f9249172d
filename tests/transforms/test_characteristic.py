"""Step 4a (piecewise-linear least squares) and step 5a (plausibility against the nominal)."""

import numpy as np
import pytest
import synth_valve as sv

from transforms.baseline import choose_knots, fit_characteristic, plausibility
from transforms.characteristic import Characteristic

UG = np.linspace(-3.5e-3, 3.5e-3, 701)
ALPHA_NOM = 0.675


def _nominal(edge_phi=sv.PHI1, underlap=4e-5):
    return Characteristic.from_arrays(UG, ALPHA_NOM * sv.eq3_area(UG, underlap, edge_phi))


def test_evaluate_slope_and_extrapolation():
    c = Characteristic([0.0, 1.0, 3.0], [0.0, 2.0, 3.0])
    np.testing.assert_allclose(c.evaluate([0.5, 1.0, 2.0, 3.0]), [1.0, 2.0, 2.5, 3.0])
    np.testing.assert_allclose(c.evaluate([-1.0, 5.0]), [-2.0, 4.0])  # linear beyond the ends
    np.testing.assert_allclose(c.slope([-1.0, 0.5, 1.0, 2.0, 9.0]), [2.0, 2.0, 0.5, 0.5, 0.5])
    with pytest.raises(ValueError):
        Characteristic([0.0, 0.0, 1.0], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError):
        Characteristic([0.0], [1.0])
    assert Characteristic.from_dict(c.to_dict()) == c
    assert hash(Characteristic.from_dict(c.to_dict())) == hash(c)
    assert not c.knots_u_m.flags.writeable


def test_least_squares_recovers_a_piecewise_linear_function_exactly():
    rng = np.random.default_rng(3)
    knots = np.array([1.0e-3, 1.4e-3, 2.0e-3, 2.3e-3, 3.5e-3])
    vals = np.array([8e-6, 12e-6, 17e-6, 21e-6, 33e-6])
    truth = Characteristic(knots, vals)
    u = rng.uniform(1.0e-3, 3.5e-3, 3000)
    fitted = fit_characteristic(u, truth.evaluate(u), knots=knots)
    np.testing.assert_allclose(fitted.values_m2, vals, rtol=1e-10)


def test_adaptive_knots_follow_the_points_and_recover_a_line():
    rng = np.random.default_rng(4)
    # dense near 1.2 mm, sparse towards 3.4 mm
    u = np.concatenate([rng.normal(1.4e-3, 0.15e-3, 3000), rng.uniform(1.0e-3, 3.4e-3, 600)])
    line = 5e-6 + 7e-3 * u
    c = fit_characteristic(u, line)
    k = c.knots_u_m
    assert k[0] == pytest.approx(u.min()) and k[-1] == pytest.approx(u.max())
    assert 3 <= k.shape[0] <= 12
    assert np.diff(k).min() >= 1e-4 - 1e-15
    # more knots where the points are dense
    assert np.sum((k > 1.1e-3) & (k < 1.7e-3)) > np.sum((k > 2.4e-3) & (k < 3.0e-3))
    np.testing.assert_allclose(c.evaluate(k), 5e-6 + 7e-3 * k, rtol=1e-9)


def test_choose_knots_limits():
    u = np.linspace(0.0, 1e-3, 100_000)
    k = choose_knots(u, max_knots=5)
    assert k.shape[0] == 5
    with pytest.raises(ValueError):
        choose_knots(np.array([1e-3, 1.05e-3]), min_spacing_m=1e-4)
    assert choose_knots(u, points_per_interval=10**6).shape[0] == 2


def _baseline_from_points(alpha_factor, shift_m, underlap=4e-5, seed=0):
    """What step 4a would see: noisy Eq. 7 points of α·A(u + Δ) over the usable spool range."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(1.04e-3, 3.5e-3, 4000)
    a = alpha_factor * ALPHA_NOM * sv.eq3_area(u + shift_m, underlap, sv.PHI1)
    a = a + rng.normal(0, 0.02 * a.mean(), a.shape)
    return fit_characteristic(u, a)


def test_plausibility_flags_the_broken_edge_of_table_2():
    res = plausibility(_baseline_from_points(2.5, 0.41e-3), _nominal())
    assert not res.ok
    assert res.scale > 2.0 and res.slope_ratio > 2.0
    assert res.alpha_vs_nominal == pytest.approx(2.5, rel=0.05)
    assert res.x_hat_vs_nominal_m == pytest.approx(0.41e-3, abs=0.05e-3)
    assert len(res.reasons) >= 3


@pytest.mark.parametrize("seed", range(8))
def test_plausibility_passes_healthy_scatter(seed):
    rng = np.random.default_rng(100 + seed)
    alpha = 1.0 + rng.uniform(-0.05, 0.05)
    dunder = rng.uniform(-0.01e-3, 0.01e-3)
    res = plausibility(_baseline_from_points(alpha, dunder, seed=seed), _nominal())
    assert res.ok, res.reasons
    assert res.alpha_vs_nominal == pytest.approx(alpha, abs=0.03)


def test_plausibility_flags_shape_and_monotonicity():
    nom = _nominal()
    k = np.linspace(1.1e-3, 3.5e-3, 9)
    v = nom.evaluate(k).copy()
    v[4] *= 0.5  # a dent: same scale on average, wrong shape, decreasing segment
    res = plausibility(Characteristic(k, v), nom)
    assert not res.ok
    assert any("monotone" in r for r in res.reasons)
    assert any("shape" in r for r in res.reasons)
    assert plausibility(Characteristic(k, nom.evaluate(k)), nom).ok

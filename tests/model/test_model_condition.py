"""Valve condition scenarios: wear (Table 3 calibration), broken edge (Table 2), scatter."""

import numpy as np
import pytest

from model import BROKEN_1R, EDGES, HEALTHY, TABLE1, WEAR, Scenario, broken_edge, condition_arrays, condition_at, healthy, wear

X_MAX = TABLE1.geometry.x_max_m
BASE = TABLE1.nominal_condition


def test_wear_monotone_and_alpha_rate_falling():
    hours = np.linspace(0, 20000, 201)
    xu, al = condition_arrays(WEAR, hours, BASE)
    assert np.all(np.diff(xu, axis=0) > 0)
    d_xu = np.diff(xu, axis=0)
    np.testing.assert_allclose(d_xu, np.broadcast_to(d_xu[0], d_xu.shape), rtol=1e-6)  # constant rate
    d_al = np.diff(al, axis=0)
    assert np.all(d_al > 0)
    assert np.all(np.diff(d_al, axis=0) < 0)          # rate falls over time


def test_wear_magnitudes_like_table3():
    xu, al = condition_arrays(WEAR, [700.0, 16700.0, 20000.0], BASE)
    rel_alpha = al / np.asarray(BASE.alpha)
    dx = (xu - np.asarray(BASE.underlap_m)) / X_MAX
    assert rel_alpha[0] == pytest.approx(1.04, abs=0.01)
    assert rel_alpha[1] == pytest.approx(1.17, abs=0.015)
    assert np.all(rel_alpha[2] < 1.2)
    assert dx[1] == pytest.approx(0.037, abs=0.002)
    assert 0.02 < dx[2, 0] < 0.06


def test_broken_edge_table2():
    sc = broken_edge("1r", from_hours=500.0)
    before, after = condition_at(sc, [499.9, 500.0], BASE)
    assert before == BASE
    i = EDGES.index("1r")
    assert after.alpha[i] == pytest.approx(2.5 * BASE.alpha[i])
    assert (after.underlap_m[i] - BASE.underlap_m[i]) / X_MAX == pytest.approx(0.118)
    assert after.underlap_m[i] - BASE.underlap_m[i] == pytest.approx(0.413e-3, abs=1e-6)
    for j in range(4):
        if j != i:
            assert after.alpha[j] == BASE.alpha[j] and after.underlap_m[j] == BASE.underlap_m[j]
    assert condition_at(BROKEN_1R, [0.0])[0].alpha[i] == pytest.approx(2.5 * 0.675)


def test_healthy_constant_and_scatter_deterministic():
    assert condition_at(HEALTHY, [0.0, 1e4], BASE) == [BASE, BASE]
    a = condition_at(healthy(3), [0.0, 5000.0], BASE)
    b = condition_at(healthy(3), [0.0], BASE)
    c = condition_at(healthy(4), [0.0], BASE)
    assert a[0] == a[1] == b[0]
    assert a[0] != c[0] and a[0] != BASE
    dev = np.asarray(a[0].underlap_m) - np.asarray(BASE.underlap_m)
    assert np.all(np.abs(dev) < 30e-6)
    # wear starts from the scattered valve
    w = condition_at(wear(scatter_seed=3), [0.0], BASE)[0]
    assert w == a[0]


def test_scenario_validation():
    with pytest.raises(ValueError):
        Scenario("x", broken_edge="3r")
    with pytest.raises(ValueError):
        condition_arrays(WEAR, [-1.0])

"""Eq. 3 opening areas: continuity, monotonicity, underlap shift, magnitudes of model.md."""

import dataclasses
import math

import numpy as np
import pytest

from model import EDGES, TABLE1, ValveCondition, edge_area, opening_coordinate, valve_areas

G = TABLE1.geometry
R, r = G.bore_radius_m, G.spool_radius_m
PHIS = {1: G.taper_angle_port1_rad, 2: G.taper_angle_port2_rad}
MM2 = 1e-6


def area(u, xu, port, x_l=None):
    return edge_area(u, xu, PHIS[port], R, r, x_l)


def branch_points(xu, port, frac=0.5):
    delta = (R - r) * math.tan(PHIS[port])
    return -xu + delta, -xu + frac * delta


@pytest.mark.parametrize("port", [1, 2])
@pytest.mark.parametrize("xu", [0.0, 4e-5, 1.5e-4, 4.5e-4])
@pytest.mark.parametrize("frac", [0.05, 0.5, 1.0])
def test_continuous_at_branch_points(port, xu, frac):
    delta = (R - r) * math.tan(PHIS[port])
    x_l = -xu + frac * delta
    for b in branch_points(xu, port, frac):
        eps = 1e-13
        a_lo, a_hi = area(np.array([b - eps, b + eps]), xu, port, x_l)
        assert abs(a_hi - a_lo) <= 1e-7 * a_hi, (b, a_lo, a_hi)
        # slopes either side agree closely (model.md: < 0.2 % at x_l; open/transition differ
        # only by pi (R - r) sin(phi))
        h = 1e-10
        s_lo = (area(b - eps, xu, port, x_l) - area(b - h, xu, port, x_l)) / (h - eps)
        s_hi = (area(b + h, xu, port, x_l) - area(b + eps, xu, port, x_l)) / (h - eps)
        assert abs(s_hi - s_lo) <= 0.01 * abs(s_hi) + math.pi * (R - r) * math.sin(PHIS[port]) * 1.01


@pytest.mark.parametrize("port", [1, 2])
@pytest.mark.parametrize("xu", [0.0, 4e-5, 1e-4, 4.5e-4])
def test_monotone_over_whole_stroke(port, xu):
    u = np.linspace(-G.x_max_m, G.x_max_m, 200_001)
    a = area(u, xu, port)
    assert np.all(np.diff(a) > 0)
    assert np.all(a > 0)


@pytest.mark.parametrize("port", [1, 2])
@pytest.mark.parametrize("dxu", [1e-6, 5e-5, 4.13e-4])
def test_underlap_change_is_exact_shift(port, dxu):
    xu = 4e-5
    u = np.linspace(-G.x_max_m, G.x_max_m - dxu, 5001)
    a_shifted = area(u, xu + dxu, port)
    a_moved = area(u + dxu, xu, port)
    np.testing.assert_allclose(a_shifted, a_moved, rtol=1e-9)


def test_magnitudes_of_model_md():
    xu = 5e-5
    # port 1: ~40 mm^2 fully open, ~1.2 mm^2 at u = 0, ~0.02 mm^2 closed at -x_max
    assert area(G.x_max_m, xu, 1) / MM2 == pytest.approx(40.0, rel=0.03)
    assert area(0.0, xu, 1) / MM2 == pytest.approx(1.2, rel=0.05)
    assert area(-G.x_max_m, xu, 1) / MM2 == pytest.approx(0.02, rel=0.1)
    # port 2 closed: ~0.03 mm^2 (0.037 with Eq. 3 as written)
    assert 0.025 < area(-G.x_max_m, xu, 2) / MM2 < 0.045
    # port 2 opens at half the taper angle: about half the fully open area of port 1
    assert area(G.x_max_m, xu, 2) / area(G.x_max_m, xu, 1) == pytest.approx(
        math.sin(PHIS[2]) / math.sin(PHIS[1]), rel=0.05)


def test_scalar_and_array_shapes():
    assert isinstance(area(0.0, 4e-5, 1), float)
    assert area(np.zeros((3, 2)), 4e-5, 1).shape == (3, 2)


def test_x_l_outside_interval_rejected():
    delta = (R - r) * math.tan(PHIS[1])
    with pytest.raises(ValueError):
        area(0.0, 4e-5, 1, x_l=-4e-5)          # x_l = -x_u: open end excluded
    with pytest.raises(ValueError):
        area(0.0, 4e-5, 1, x_l=-4e-5 + 1.01 * delta)
    area(0.0, 4e-5, 1, x_l=-4e-5 + delta)       # closed end allowed


def test_opening_coordinate_signs():
    assert opening_coordinate(1e-3, "s1") == 1e-3
    assert opening_coordinate(1e-3, "2r") == 1e-3
    assert opening_coordinate(1e-3, "1r") == -1e-3
    assert opening_coordinate(1e-3, "s2") == -1e-3
    with pytest.raises(ValueError):
        opening_coordinate(0.0, "s3")


def test_valve_areas_order_and_edges():
    cond = ValveCondition(underlap_m=(3e-5, 5e-5, 7e-5, 9e-5))
    x = np.linspace(-G.x_max_m, G.x_max_m, 101)
    A = valve_areas(x, G, cond)
    assert A.shape == (4, x.size)
    x_l = cond.x_l_m(G)
    for i, e in enumerate(EDGES):
        port = 1 if e in ("s1", "1r") else 2
        expected = area(opening_coordinate(x, e), cond.underlap_m[i], port, x_l[i])
        np.testing.assert_allclose(A[i], expected, rtol=1e-12)
    # x > 0 opens s1 and 2r, closes 1r and s2
    assert A[0, -1] > 30 * MM2 and A[3, -1] > 15 * MM2
    assert A[1, -1] < 0.1 * MM2 and A[2, -1] < 0.1 * MM2


def test_edge_constants_are_those_of_each_condition_and_a_fresh_array_each_call():
    """valve_edge_constants is computed once per (geometry, condition): a changed underlap gives
    its own constants, and what a caller does to the array it got does not reach the next one."""
    from model.area import valve_edge_constants

    cond = ValveCondition(underlap_m=(3e-5, 5e-5, 7e-5, 9e-5))
    a = valve_edge_constants(G, cond)
    a[:] = np.nan
    b = valve_edge_constants(G, cond)
    assert np.all(np.isfinite(b)) and b is not valve_edge_constants(G, cond)
    c = valve_edge_constants(G, dataclasses.replace(cond, underlap_m=(3e-5, 5e-5, 7e-5, 1e-4)))
    assert np.array_equal(b[:3], c[:3]) and not np.array_equal(b[3], c[3])


# --- the valve families: sharp-edged law and worn lands (model.area docstring) ---------------

@pytest.mark.parametrize("port", [1, 2])
@pytest.mark.parametrize("xu", [0.0, 4e-5, 1.5e-4])
def test_sharp_edged_law_is_zero_below_the_underlap_and_linear_above(port, xu):
    u = np.linspace(-3.5e-3, 3.5e-3, 2001)
    a = edge_area(u, xu, PHIS[port], R, r, area_law="sharp")
    assert np.all(a[u <= -xu] == 0.0)
    slope = 2 * math.pi * R * math.sin(PHIS[port])
    np.testing.assert_allclose(a[u > -xu], slope * (u[u > -xu] + xu), rtol=1e-12, atol=1e-20)
    # Eq. 3's open-branch gradient at its start, without the clearance intercept
    eq3 = area(u, xu, port)
    near = (u > -xu + 0.2e-3) & (u < -xu + 1e-3)
    assert np.all(eq3[near] > a[near])
    assert np.all(np.abs(np.diff(eq3[near]) / np.diff(a[near]) - 1) < 0.02)


@pytest.mark.parametrize("port", [1, 2])
@pytest.mark.parametrize("k", [0.5, 3.0, 6.0])
def test_leakage_factor_scales_the_far_leakage_and_keeps_the_rest(port, k):
    xu = 4e-5
    x_open, x_l = branch_points(xu, port)
    u_open = np.linspace(x_l, 3.5e-3, 500)
    np.testing.assert_array_equal(edge_area(u_open, xu, PHIS[port], R, r, leakage_factor=k), area(u_open, xu, port))
    eps = 1e-13
    below = edge_area(x_l - eps, xu, PHIS[port], R, r, leakage_factor=k)
    assert abs(below - area(x_l + eps, xu, port)) <= 1e-7 * below  # continuous at x_l
    u_far = np.array([-1e-3, -2e-3, -3.5e-3, -1.0])
    ratio = edge_area(u_far, xu, PHIS[port], R, r, leakage_factor=k) / area(u_far, xu, port)
    w = x_l + xu
    c = (R - r) ** 2 + w**2
    np.testing.assert_allclose(ratio, (c + (x_l - u_far) * w) / (c + (x_l - u_far) * w / k), rtol=1e-12)
    assert np.all(np.diff(ratio) * (k - 1) > 0) and abs(ratio[-1] / k - 1) < 5e-3  # towards k far out
    u_closed = np.linspace(-3.5e-3, x_l - 1e-9, 300)
    assert np.all(np.diff(edge_area(u_closed, xu, PHIS[port], R, r, leakage_factor=k)) > 0)


def test_family_arguments_are_checked():
    with pytest.raises(ValueError, match="area_law"):
        edge_area(0.0, 4e-5, PHIS[1], R, r, area_law="round")
    with pytest.raises(ValueError, match="leakage_factor"):
        edge_area(0.0, 4e-5, PHIS[1], R, r, leakage_factor=0.0)
    with pytest.raises(ValueError, match="area_law"):
        dataclasses.replace(G, area_law="round")
    with pytest.raises(ValueError, match="leakage_factor"):
        dataclasses.replace(G, leakage_factor=-1.0)


@pytest.mark.parametrize("geometry", [dataclasses.replace(G, area_law="sharp"), dataclasses.replace(G, leakage_factor=4.0)])
def test_valve_areas_follow_the_geometry_family(geometry):
    cond = ValveCondition(underlap_m=(4e-5, 5e-5, 3e-5, 6e-5))
    x = np.linspace(-3.5e-3, 3.5e-3, 301)
    A = valve_areas(x, geometry, cond)
    for i, e in enumerate(EDGES):
        u = opening_coordinate(x, e)
        expect = edge_area(u, cond.underlap_m[i], G.taper_angle(e), R, r, cond.x_l_m(G)[i],
                           geometry.area_law, geometry.leakage_factor)
        np.testing.assert_array_equal(A[i], expect)

"""Standstill pressures and Eq. 9 (model.md: healthy ~33/146 bar, broken edge ~2/82 bar)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from model import (
    BROKEN_1R,
    TABLE1,
    ValveGeometry,
    condition_at,
    eq9_residual,
    friction_force,
    port_flows,
    resultant_force,
    standstill,
    steady_state,
)

BAR = 1e5


def test_healthy_standstill_table1():
    s = standstill(TABLE1, p_s_pa=200 * BAR, p_r_pa=0.0)
    assert s.p2_pa > 3 * s.p1_pa
    assert s.p1_pa / BAR == pytest.approx(33.0, abs=1.0)
    assert s.p2_pa / BAR == pytest.approx(146.0, abs=2.0)
    # at rest the spool sits inside the underlap (all four edges open), towards 1r/s2
    assert -TABLE1.nominal_condition.underlap_m[0] < s.x_m < 0.0
    q1, q2 = port_flows([s.x_m], s.p1_pa, s.p2_pa, 200 * BAR, 0.0, TABLE1.geometry,
                        TABLE1.nominal_condition, TABLE1.fluid)
    assert abs(q1[0]) < 1e-12 and abs(q2[0]) < 1e-12
    assert resultant_force(s.p1_pa, s.p2_pa, 0.0, TABLE1.cylinder) == pytest.approx(0, abs=1e-3)


def test_eq9_holds_without_clearance_and_equal_tapers():
    geo = ValveGeometry(spool_radius_m=10.0e-3 - 1e-10, taper_angle_port1_rad=math.radians(8.0),
                        taper_angle_port2_rad=math.radians(8.0))
    params = replace(TABLE1, geometry=geo)
    for p_r in (0.0, 0.5 * BAR):
        s = standstill(params, p_s_pa=200 * BAR, p_r_pa=p_r)
        assert abs(eq9_residual(s.p1_pa, s.p2_pa, 200 * BAR, p_r)) < 2e-3
        if p_r == 0.0:
            assert (s.p1_pa + s.p2_pa) / (200 * BAR) == pytest.approx(1.0, abs=5e-4)
            assert s.p1_pa / BAR == pytest.approx(40.1, abs=0.3)


def test_eq9_residual_broken_edge_far_larger():
    healthy = standstill(TABLE1, p_s_pa=200 * BAR, p_r_pa=0.0)
    broken = standstill(TABLE1, condition_at(BROKEN_1R, [0.0])[0], p_s_pa=200 * BAR, p_r_pa=0.0)
    r_h = eq9_residual(healthy.p1_pa, healthy.p2_pa, 200 * BAR, 0.0)
    r_b = eq9_residual(broken.p1_pa, broken.p2_pa, 200 * BAR, 0.0)
    assert abs(r_h) < 0.25
    assert abs(r_b) > 5 * abs(r_h)
    assert broken.p1_pa / BAR == pytest.approx(2.0, abs=1.5)
    assert broken.p2_pa / BAR == pytest.approx(82.0, abs=3.0)


def test_standstill_with_load_and_friction_band():
    s0 = standstill(TABLE1, p_s_pa=200 * BAR, p_r_pa=0.0)
    s_load = standstill(TABLE1, F_l_n=10e3, p_s_pa=200 * BAR, p_r_pa=0.0)
    assert s_load.p1_pa > s0.p1_pa          # a load against extension raises p1
    s_f = standstill(TABLE1, F_R_n=5e3, p_s_pa=200 * BAR, p_r_pa=0.0)
    assert resultant_force(s_f.p1_pa, s_f.p2_pa, 0.0, TABLE1.cylinder) == pytest.approx(5e3, abs=1e-2)
    with pytest.raises(ValueError):
        standstill(TABLE1, F_l_n=1e7)


@pytest.mark.parametrize("v", [-0.12, -0.03, 0.05, 0.2])
def test_steady_motion_balances(v):
    s = steady_state(v, TABLE1)
    c = TABLE1.cylinder
    q1, q2 = port_flows([s.x_m], s.p1_pa, s.p2_pa, TABLE1.supply.p_s_nominal_pa,
                        TABLE1.supply.p_r_nominal_pa, TABLE1.geometry, TABLE1.nominal_condition,
                        TABLE1.fluid)
    assert q1[0] == pytest.approx(c.A1 * v, rel=1e-6)
    assert q2[0] == pytest.approx(c.A2 * v, rel=1e-6)
    assert resultant_force(s.p1_pa, s.p2_pa, 0.0, c) == pytest.approx(friction_force(v, c), rel=1e-6)
    assert np.sign(s.x_m) == np.sign(v)


def test_retraction_needs_more_spool_than_extension():
    # lifting the load needs a larger spool stroke than lowering it (paper Sec. 5.1)
    for v in (0.03, 0.1):
        assert abs(steady_state(-v, TABLE1).x_m) > 1.5 * abs(steady_state(v, TABLE1).x_m)


def test_unreachable_speed_raises():
    with pytest.raises(ValueError):
        steady_state(-0.5, TABLE1)

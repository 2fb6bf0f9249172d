"""Eqs. 1, 2, 4, 5, 6 as pure functions: signs, saturation, sticking, regularisation."""

import math

import numpy as np
import pytest

from model import (
    TABLE1,
    ValveCondition,
    chamber_volumes,
    cylinder_acceleration,
    friction_force,
    orifice_flow,
    port_flows,
    pressure_derivatives,
    resultant_force,
    spool_acceleration,
    valve_areas,
)

RHO = TABLE1.fluid.density_kg_m3
C = TABLE1.cylinder
BAR = 1e5


def test_orifice_exact_law():
    dp = np.array([-50e5, -1.0, 0.0, 1.0, 3e4, 150e5])
    q = orifice_flow(2e-5, dp, 0.675, RHO)
    expected = 0.675 * 2e-5 * np.sign(dp) * np.sqrt(2 * np.abs(dp) / RHO)
    np.testing.assert_allclose(q, expected, rtol=1e-14, atol=0)


def test_orifice_regularisation_band():
    band = 1e4
    dp = np.linspace(-3 * band, 3 * band, 60001)
    q = orifice_flow(1.0, dp, 1.0, 2.0, reg_band_pa=band)   # rho = 2: q = ssqrt(dp)
    exact = np.sign(dp) * np.sqrt(np.abs(dp))
    outside = np.abs(dp) >= band
    np.testing.assert_allclose(q[outside], exact[outside], rtol=1e-14)
    assert np.all(np.diff(q) > 0)                          # monotone
    np.testing.assert_allclose(q, -q[::-1], atol=1e-12)    # odd
    # C1 at the band edge: one-sided slopes agree
    h = 1e-3
    s_in = (orifice_flow(1.0, band, 1.0, 2.0, band) - orifice_flow(1.0, band - h, 1.0, 2.0, band)) / h
    s_out = (orifice_flow(1.0, band + h, 1.0, 2.0, band) - orifice_flow(1.0, band, 1.0, 2.0, band)) / h
    assert s_in == pytest.approx(s_out, rel=1e-3)
    # finite slope 5 / (4 sqrt b) at 0; largest deviation 0.2 sqrt(b), at |dp| = 0.16 b
    dev = np.abs(q - exact)
    assert np.max(dev) == pytest.approx(0.2 * math.sqrt(band), rel=0.01)
    assert abs(dp[np.argmax(dev)]) == pytest.approx(0.16 * band, rel=0.05)


def test_port_flow_directions():
    g, c = TABLE1.geometry, TABLE1.nominal_condition
    p1, p2, ps, pr = 40 * BAR, 140 * BAR, 200 * BAR, 0.5 * BAR
    q1, q2 = port_flows([2e-3, -2e-3], p1, p2, ps, pr, g, c, TABLE1.fluid)
    assert q1[0] > 0 and q2[0] > 0      # extend: supply -> chamber 1, chamber 2 -> return
    assert q1[1] < 0 and q2[1] < 0      # retract: chamber 1 -> return, supply -> chamber 2


def test_port_flows_per_edge_alpha():
    g = TABLE1.geometry
    base = ValveCondition.nominal()
    x = np.array([2e-3])
    p = (40 * BAR, 140 * BAR, 200 * BAR, 0.5 * BAR)
    A = valve_areas(x, g, base)
    k = math.sqrt(2 / RHO)
    s1_part = 0.675 * A[0, 0] * k * math.sqrt(p[2] - p[0])
    q1a, _ = port_flows(x, *p, g, base, TABLE1.fluid)
    q1b, q2b = port_flows(x, *p, g, base.with_edge("s1", alpha=2 * 0.675), TABLE1.fluid)
    assert q1b[0] - q1a[0] == pytest.approx(s1_part, rel=1e-12)
    _, q2a = port_flows(x, *p, g, base, TABLE1.fluid)
    assert q2b[0] == q2a[0]


def test_spool_eq1_and_velocity_saturation():
    s = TABLE1.spool
    a = spool_acceleration(0.0, 0.0, 1e-3, s)
    assert a == pytest.approx(1e-3 / s.T_s**2)
    assert spool_acceleration(0.0, s.v_max_m_s, 1e-3, s) == 0.0     # saturated, pushing on
    assert spool_acceleration(0.0, -s.v_max_m_s, -1e-3, s) == 0.0
    assert spool_acceleration(0.0, s.v_max_m_s, -1e-3, s) < 0.0     # may slow down
    assert spool_acceleration(0.0, 0.1, 0.0, s) == pytest.approx(-2 * s.zeta / s.T_s * 0.1)


def test_stribeck_friction():
    v = np.array([1e-9, C.v0_m_s, 0.5])
    f = friction_force(v, C)
    assert f[0] == pytest.approx(C.d_s_n, rel=1e-6)
    assert f[1] == pytest.approx(C.d_v_n_s_m * C.v0_m_s + C.d_c_n + (C.d_s_n - C.d_c_n) / math.e)
    assert f[2] == pytest.approx(C.d_v_n_s_m * 0.5 + C.d_c_n, rel=1e-9)
    np.testing.assert_allclose(friction_force(-v, C), -f)


def test_sticking_and_breakaway():
    d_s, m = C.d_s_n, C.mass_kg
    assert cylinder_acceleration(0.0, 0.99 * d_s, C) == 0.0
    assert cylinder_acceleration(0.0, -d_s, C) == 0.0
    assert cylinder_acceleration(0.0, d_s + 600.0, C) == pytest.approx(600.0 / m)
    assert cylinder_acceleration(0.0, -d_s - 600.0, C) == pytest.approx(-600.0 / m)
    assert cylinder_acceleration(0.1, 0.0, C) == pytest.approx(-friction_force(0.1, C) / m)


def test_forces_volumes_pressure_derivatives():
    assert C.A1 == pytest.approx(math.pi * 0.14**2 / 4)
    assert C.A2 == pytest.approx(math.pi * (0.14**2 - 0.1**2) / 4)
    # idealised rest (p1 + p2 = p_s, F_R = 0): p1 ~ 40 bar, p2 ~ 160 bar (model.md)
    p1 = (C.A2 * 200 * BAR - C.weight_n) / (C.A1 + C.A2)
    assert p1 / BAR == pytest.approx(40.1, abs=0.2)
    assert resultant_force(p1, 200 * BAR - p1, 0.0, C) == pytest.approx(0.0, abs=1e-6)
    V1, V2 = chamber_volumes(np.array([0.0, C.stroke_m]), C)
    assert V1[0] == C.v01_m3 and V2[0] == C.v02_m3
    assert V2[1] > 2e-3
    d1, d2 = pressure_derivatives(1e-3, 0.0, 0.3, 0.0, C, TABLE1.fluid)
    assert d1 == pytest.approx(TABLE1.fluid.bulk_modulus_pa / (C.v01_m3 + C.A1 * 0.3) * 1e-3)
    assert d2 == 0.0
    d1, d2 = pressure_derivatives(0.0, 0.0, 0.3, 0.1, C, TABLE1.fluid)   # extending, no flow
    assert d1 < 0 < d2

"""Physical invariants of the second reference plant, each of which a wrong equation breaks."""

import math
from dataclasses import replace

import numpy as np
import pytest

from . import (NAMEPLATE, Edge, Effects, Load, Trajectory, Valve, edge_area, family, manufactured, simulate, without_noise, worn)
from .params import idealised
from .sensors import first_order_lag

QUIET = without_noise(NAMEPLATE)
NO_RIPPLE = (200e5, 0.0, 0.0, 225.0, 0.0, 0.5e5)


def _sealed(plant, d_c=0.0, d_s=0.0):
    """An overlapped linear-gradient valve (every edge closed at x = 0, no leakage), spool held at 0."""
    return replace(family(plant, "linear"), valve=plant.valve.with_edges(law="linear", underlap_m=-0.1e-3),
                   cylinder=replace(plant.cylinder, d_c_n=d_c, d_s_n=d_s, karnopp_band_m_s=1e-6))


def test_sealed_chambers_settle_where_the_forces_balance_and_keep_their_oil():
    plant = _sealed(without_noise(idealised(NAMEPLATE)))
    c, beta = plant.cylinder, plant.fluid.bulk_modulus_pa
    F_l, X0, p10, p20 = 4.0e3, 0.30, 50e5, 150e5
    n = 2000
    rec = simulate(plant, n / 1000, 0, load=Load.constant(F_l), trajectory=Trajectory.hold(X0), supply=NO_RIPPLE,
                   spool_command=np.zeros(n), initial_state=np.array([0.0, 0.0, X0, 0.0, p10, p20, 0.0]))
    T = rec.true
    p1, p2, X = T["p1"][-1], T["p2"][-1], T["X"][-1]
    assert abs(T["vX"][-1]) < 1e-6
    # Eq. 5 at rest: m g + A1 p1 - A2 p2 - F_l = 0 (to 1 N of a 59 kN weight)
    assert abs(c.mass_kg * c.g_m_s2 + c.A1 * p1 - c.A2 * p2 - F_l) < 1.0
    # Eq. 6 with no flow: dp = -beta dV / V, so p_end = p_0 - beta ln(V_end / V_0) in each chamber
    V1 = lambda x: c.v01_m3 + c.A1 * x  # noqa: E731
    V2 = lambda x: c.v02_m3 - c.A2 * x  # noqa: E731
    assert p1 == pytest.approx(p10 - beta * math.log(V1(X) / V1(X0)), abs=50.0)
    assert p2 == pytest.approx(p20 - beta * math.log(V2(X) / V2(X0)), abs=50.0)
    assert abs(X - X0) > 1e-4  # the start was far from the balance: the rod did move


def test_chamber_1_volume_balance_over_a_move():
    """Integral of q1 = change of V1 + compression, integral of V1 / beta dp1 (Eq. 6)."""
    plant = replace(QUIET, sensors=replace(QUIET.sensors, sample_rate_hz=10_000.0, fine_per_sample=1))
    traj = Trajectory.moves(0.2, [(0.1, 0.8, 0.35)])
    rec = simulate(plant, 1.2, 0, load=Load.constant(0.0), trajectory=traj, supply=NO_RIPPLE)
    T, c, beta = rec.true, plant.cylinder, plant.fluid.bulk_modulus_pa
    inflow = np.trapezoid(T["q1"], rec.t_s)
    V1 = c.v01_m3 + c.A1 * T["X"]
    stored = c.A1 * (T["X"][-1] - T["X"][0]) + np.sum(0.5 * (V1[1:] + V1[:-1]) / beta * np.diff(T["p1"]))
    assert T["X"][-1] - T["X"][0] > 0.14
    assert inflow == pytest.approx(stored, rel=1e-4)


def test_linear_gradient_edge_is_exactly_g_times_the_opening():
    valve = Valve().with_edges(law="linear", underlap_m=(30e-6, 50e-6, -20e-6, 0.0))
    u = np.linspace(-3.5e-3, 3.5e-3, 1401)
    for i, edge in enumerate(("s1", "1r", "s2", "2r")):
        f = math.sin(math.radians(10.48 if i < 2 else 5.24))
        g = f * math.pi * 0.020
        np.testing.assert_array_equal(edge_area(valve, edge, u), g * np.maximum(u + valve.edges[i].underlap_m, 0.0))
    own = Valve(edges=(Edge(law="linear", gradient_m=0.005),) * 4)
    assert edge_area(own, "s2", 1e-3) == pytest.approx(0.005 * 1.04e-3, rel=1e-12)


def test_eq3_edge_magnitudes_and_continuity():
    """model.md's magnitudes for x_u = 0.05 mm; Eq. 3 continuous and increasing across its branches."""
    valve = Valve().with_edges(underlap_m=0.05e-3)
    assert edge_area(valve, "s1", 3.5e-3) * 1e6 == pytest.approx(40, rel=0.05)
    assert edge_area(valve, "s1", 0.0) * 1e6 == pytest.approx(1.2, rel=0.1)
    assert edge_area(valve, "s1", -3.5e-3) * 1e6 == pytest.approx(0.02, rel=0.25)
    assert edge_area(valve, "s2", -3.5e-3) * 1e6 == pytest.approx(0.03, rel=0.25)
    u = np.linspace(-3.5e-3, 3.5e-3, 700_001)
    a = edge_area(valve, "2r", u)
    assert np.all(np.diff(a) > 0)
    assert np.max(np.abs(np.diff(a))) < 2e-10  # no jump: 0.01 um steps change A by < 2e-4 mm^2
    sharp = edge_area(family(NAMEPLATE, "sharp").valve, "s1", u)
    assert np.all(sharp[u <= -40e-6] == 0) and np.all(sharp[u > -40e-6] > 0)


def test_lag_step_response_reaches_63_percent_at_one_time_constant():
    tau, h = 1e-3, 1e-6
    u = np.ones(3001)
    u[0] = 0.0
    y = first_order_lag(u, h, tau, y0=0.0)
    # the input ramps over the first step, so the response is that of a step delayed by h / 2
    assert np.interp(tau + h / 2, np.arange(u.size) * h, y) == pytest.approx(1 - math.exp(-1), abs=1e-6)
    assert y[-1] == pytest.approx(1 - math.exp(-(3 * tau - h / 2) / tau), abs=1e-8)


def test_recorded_pressure_lags_and_is_one_sample_late():
    """The p1 channel: the true p1 through a 1 ms lag, stored one sample late."""
    rec = simulate(QUIET, 3.0, 4, supply=NO_RIPPLE)
    p_true, p_rec = rec.true["p1"], rec.p1
    lagged = first_order_lag(p_true, 1e-3, 1e-3)
    err = {name: np.abs(p_rec[1:] - ref).max() for name, ref in
           (("raw", p_true[1:]), ("lagged only", lagged[1:]), ("late only", p_true[:-1]), ("lagged, late", lagged[:-1]))}
    # the lag recomputed on the 1 kHz grid (linear between samples) differs from the plant's on its
    # fine grid by ~1 mbar; leaving out either the lag or the skew costs bars
    assert err["lagged, late"] < 0.02 * min(err["raw"], err["lagged only"], err["late only"]), err


@pytest.mark.parametrize("load_n,moves", [(5.0e3, False), (7.5e3, True)])
def test_karnopp_rod_sticks_below_static_friction(load_n, moves):
    plant = replace(QUIET, valve=QUIET.valve.with_edges(law="linear", underlap_m=-0.1e-3))
    X0 = 0.3
    load = Load(np.array([0.0, 0.2, 0.4]), np.array([0.0, 0.0, load_n]))
    n = 1500
    c = plant.cylinder
    p1 = (0.0 - c.mass_kg * c.g_m_s2 + c.A2 * 200e5) / (c.A1 + c.A2)
    rec = simulate(plant, n / 1000, 0, load=load, trajectory=Trajectory.hold(X0), supply=NO_RIPPLE,
                   spool_command=np.zeros(n), initial_state=np.array([0.0, 0.0, X0, 0.0, p1, 200e5 - p1, 0.0]))
    dX = np.abs(rec.true["X"] - X0).max()
    if moves:
        assert dX > 10e-6
    else:
        assert dX < 1e-9
        assert abs(rec.true["p1"][-1] - p1) < 1.0  # nothing moved, so the chambers did not change


def test_wear_moves_the_named_edge_only():
    plant = worn(family(NAMEPLATE, "linear"), alpha_scale={"s2": 1.15}, underlap_shift_m={"s2": 0.03e-3})
    truth = {e["edge"]: e for e in simulate(plant, 0.01, 0).edge_truth()}
    assert truth["s2"]["alpha"] == pytest.approx(0.675 * 1.15) and truth["s2"]["underlap_m"] == pytest.approx(0.07e-3)
    assert all(truth[e]["alpha"] == 0.675 and truth[e]["underlap_m"] == 0.04e-3 for e in ("s1", "1r", "2r"))
    assert truth["s2"]["gradient_m"] == pytest.approx(math.sin(math.radians(5.24)) * math.pi * 0.02)
    with pytest.raises(ValueError, match="unknown edges"):
        worn(NAMEPLATE, alpha_scale={"s3": 1.1})


def _window_inputs(plant, seed, duration_s=2.0):
    """(inputs, rest state, 10 kHz grid) of a window as :func:`simulate` draws it."""
    from .plant import Inputs, rest_state
    from .recording import draw_window

    trajectory, load, supply = draw_window(plant, duration_s, seed)
    inp = Inputs.build(plant, Effects(), supply, trajectory, load)
    return inp, rest_state(inp), np.arange(int(duration_s * 10_000) + 1) / 10_000


@pytest.mark.parametrize("law", ["eq3", "sharp"])
def test_lsoda_stepped_by_hand_is_solve_ivps_dense_output(law):
    """integrate() steps LSODA itself and evaluates the grid from the kept Nordsieck arrays: the
    same states as solve_ivp's dense output on a 10 kHz grid over moves and load steps (a wrong
    column, order or step size in the interpolation is off by far more than rounding)."""
    from scipy.integrate import solve_ivp

    from .plant import absolute_tolerance, integrate

    plant = family(manufactured(NAMEPLATE, 3), law)
    inp, y0, t = _window_inputs(plant, 5)
    ours, nfev = integrate(inp, y0, t, plant)
    it = plant.integration
    sol = solve_ivp(inp.rhs, (t[0], t[-1]), y0, method="LSODA", rtol=it.rtol, atol=absolute_tolerance(it), dense_output=True, max_step=it.max_step_s)
    assert nfev == sol.nfev
    ref = sol.sol(t)
    scale = np.abs(ref).max(axis=1, keepdims=True)
    np.testing.assert_allclose(ours / scale, ref / scale, rtol=0, atol=1e-13)
    assert np.ptp(ours[2]) > 1e-3  # the window moved the rod


def test_a_failed_integration_says_when():
    from .plant import _BETA, integrate

    inp, y0, t = _window_inputs(NAMEPLATE, 5, 0.1)
    P = inp.P.copy()
    P[_BETA] = np.nan  # the chambers' derivatives NaN from the start
    with pytest.raises(RuntimeError, match=r"integration failed at t = 0\.0000 s"):
        integrate(replace(inp, P=P), y0, t, NAMEPLATE)

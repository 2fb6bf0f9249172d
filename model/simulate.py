"""Closed-loop simulation of the valve and positioning unit (Eqs. 1-6) with the digital PI
position controller in the loop.

State (order 6): ``(x, v, X, v_X, p1, p2)`` -- spool position [m] and velocity [m/s],
cylinder position [m] and velocity [m/s], chamber pressures [Pa]. Inputs:
``(x_ref, F_l, p_s, p_r)`` [m, N, Pa, Pa].

* :func:`rhs` -- the right-hand side, python-control style ``rhs(t, state, inputs, params)``,
  the readable reference; it calls the same scalar numba kernel :func:`rhs_kernel` the
  integrator uses.
* :func:`simulate_windows` -- a batch of windows: per window its own trajectory, load and
  supply drawn from ``numpy.random.default_rng([seed, window_index])``, the controller
  sampled at the acquisition rate (zero-order hold on x_ref; F_l changes at sample instants),
  and a fixed-step classical RK4 with ``substeps`` steps per sample (default 2, i.e. 0.5 ms).

Numerics.

* Orifice law: sign(dp) sqrt|dp| is regularised within ``reg_band_pa`` (default 0.1 bar;
  :mod:`model.orifice`) so the pressure equations stay non-stiff when an open edge carries
  (almost) no pressure drop.
* Stick-slip (Karnopp-style, with event location): each step is taken on one branch of
  Eq. 5b -- sticking (v_X = 0 held exactly, dv_X/dt = 0) or moving in a fixed direction (the
  Stribeck friction's sign held, a smooth continuation across v_X = 0). If a moving step ends
  with v_X of the other sign, the zero crossing is located by regula falsi (re-integrating
  from the step start), v_X is set to exactly 0 there and the cylinder sticks if
  |F_R| <= d_s, or else moves on in the direction of F_R. If a sticking step ends with
  |F_R| > d_s, the breakaway instant (|F_R| = d_s) is located the same way and the rest of
  the step is moving. So the cylinder sticks exactly when v_X reaches 0 with |F_R| <= d_s and
  stays stuck until |F_R| exceeds d_s.
* Every window starts at the exact rest state of its valve (:func:`model.standstill.standstill`,
  F_R = 0) at the reference's first position, with the controller's integrator set so that
  x_ref equals the rest spool position: no start-up transient.
* The supply pressure is evaluated at every RK4 stage time (its ripple is continuous).

Accuracy (measured on 10 s windows of healthy, worn and broken-1r valves against 16 steps
per sample): with the events located, the integration converges at RK4's order; 2 steps per
sample (0.5 ms) are within ~1e-4 bar in p1, p2 and ~0.03 um in X, 1 step (1 ms) within
~4e-3 bar. Without event location the stick-slip switching would limit the method to first
order (errors of bars at 0.25 ms). 0.5 ms also keeps RK4 stable for the stiffest states seen
(spool: lambda = -1/T; chambers: beta A1 v_X / (2 V1 dp) for small pressure drops).

Model limits (as in the paper's model): no cavitation, relief valves or end stops. With the
paper's broken edge 1r the head-side pressure can dip a few bar below p_r during fast
gravity-driven extension (down to ~p_r - 8 bar in the test windows); a healthy or worn valve
stays well inside [p_r, p_s]. The default trajectories keep X 40 mm away from the end stops.

The recorded ``dp1_dt`` and ``dp2_dt`` are the right-hand side (with the regularised law) at
the recorded state, i.e. the exact derivatives of the simulated pressures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from .area import edge_area_kernel, edge_tuple_kernel, valve_edge_constants
from .controller import feedforward_table, interp_kernel, pi_step_kernel
from .cylinder import (chamber_volumes_kernel, cylinder_acceleration_mode_kernel,
                       friction_mode_kernel, pressure_derivatives_kernel, resultant_force_kernel)
from .effects import (Effects, apply_to_params, effective_bulk_modulus_kernel,
                      supply_valve_pressure_kernel)
from .orifice import port_flows_kernel
from .params import PlantParams, ValveCondition
from .spool import spool_acceleration_kernel
from .standstill import standstill
from .trajectory import WindowInputs, supply_pressure_kernel, window_inputs

#: Default regularisation band of the orifice law in the simulator. [Pa]
DEFAULT_REG_BAND_PA = 1.0e4
#: A pressure beyond this multiple of the supply level counts as divergence.
P_LIMIT_FACTOR = 20.0
#: Default number of RK4 steps per sample (0.5 ms at 1 kHz; see the module docstring).
DEFAULT_SUBSTEPS = 2

# Layout of the packed parameter vector of the kernels. Beyond the base model's 16 entries:
# the kernel terms of the effects of model.effects (0 = off) and the prescribed-spool flag of
# the replay (model.replay; 1 = the spool follows its recorded path, dv/dt = 0 inside a sample).
(_T, _ZETA, _VMAX, _M, _WEIGHT, _A1, _A2, _V01, _V02, _BETA, _KRHO, _DV, _DC, _DS, _V0,
 _BAND, _KI, _KE, _AIR, _DXS, _RS, _PRESC) = range(22)
_N_P = 22


def pack_params(params: PlantParams, reg_band_pa: float = DEFAULT_REG_BAND_PA,
                effects: Effects | None = None, prescribed_spool: bool = False) -> np.ndarray:
    """Plant parameters as the flat float64 vector the kernels take.

    ``effects`` (default none): the library effects of :mod:`model.effects`; friction and mass
    changes are applied to the plant, leakage, air, the spool sensor offset and the supply line
    become kernel terms (the pressure sensor effects act on the recorded signals only).
    ``prescribed_spool``: the spool state is not integrated (the replay drives it)."""
    params = apply_to_params(params, effects)
    s, c, f = params.spool, params.cylinder, params.fluid
    P = np.zeros(_N_P)
    P[_T], P[_ZETA], P[_VMAX] = s.T_s, s.zeta, s.v_max_m_s
    P[_M], P[_WEIGHT], P[_A1], P[_A2] = c.mass_kg, c.weight_n, c.A1, c.A2
    P[_V01], P[_V02] = c.v01_m3, c.v02_m3
    P[_BETA], P[_KRHO] = f.bulk_modulus_pa, math.sqrt(2.0 / f.density_kg_m3)
    P[_DV], P[_DC], P[_DS], P[_V0] = c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.v0_m_s
    P[_BAND] = reg_band_pa
    if effects is not None:
        P[_KI] = effects.internal_leakage_m3_s_pa
        P[_KE] = effects.external_leakage_m3_s_pa
        P[_AIR] = effects.air_fraction
        P[_DXS] = effects.spool_sensor_offset_m
        P[_RS] = effects.supply_resistance_pa_s2_m6
    P[_PRESC] = 1.0 if prescribed_spool else 0.0
    return P


@njit(cache=True)
def params_tuple(P):
    """The packed parameter vector of :func:`pack_params` as a tuple (passed by value)."""
    return (P[0], P[1], P[2], P[3], P[4], P[5], P[6], P[7], P[8], P[9], P[10], P[11], P[12],
            P[13], P[14], P[15], P[16], P[17], P[18], P[19], P[20], P[21])


@njit(cache=True)
def _valve_tuples(ecs, alpha):
    return ((edge_tuple_kernel(ecs[0]), edge_tuple_kernel(ecs[1]), edge_tuple_kernel(ecs[2]),
             edge_tuple_kernel(ecs[3])), (alpha[0], alpha[1], alpha[2], alpha[3]))


@njit(cache=True)
def rhs_mode_kernel(x, v, X, vX, p1, p2, mode, x_ref, F_l, p_s, p_r, ecs, alpha, P):
    """Eqs. 1-6 for one instant on a given friction branch: ``mode`` 0 = sticking, +-1 =
    moving in that direction (Stribeck friction with that sign), 2 = choose by Eq. 5b.

    ``ecs`` tuple of the 4 edge-constant tuples, ``alpha`` tuple of the 4 contraction
    coefficients, ``P`` the packed parameters as a tuple (:func:`params_tuple`). Returns the time derivatives of
    (x, v, X, v_X, p1, p2).

    The effects of :mod:`model.effects` enter where their entries of ``P`` are non-zero: the
    spool sensor offset shifts the spool's set point (the valve's inner loop regulates the
    reading x + delta_x), the supply line lowers the supply pressure at the valve, leakage and
    entrained air change Eq. 6. With all of them zero the base model is evaluated unchanged."""
    if P[_PRESC] != 0.0:
        dv = 0.0
    elif P[_DXS] != 0.0:
        dv = spool_acceleration_kernel(x, v, x_ref - P[_DXS], P[_T], P[_ZETA], P[_VMAX])
    else:
        dv = spool_acceleration_kernel(x, v, x_ref, P[_T], P[_ZETA], P[_VMAX])
    a_s1 = edge_area_kernel(x, ecs[0])
    a_1r = edge_area_kernel(-x, ecs[1])
    a_s2 = edge_area_kernel(-x, ecs[2])
    a_2r = edge_area_kernel(x, ecs[3])
    if P[_RS] != 0.0:
        p_s = supply_valve_pressure_kernel(p_s, p1, p2, alpha[0] * a_s1, alpha[2] * a_s2,
                                           P[_KRHO], P[_BAND], P[_RS])
    q1, q2 = port_flows_kernel(a_s1, a_1r, a_s2, a_2r, alpha[0], alpha[1], alpha[2], alpha[3],
                               p1, p2, p_s, p_r, P[_KRHO], P[_BAND])
    F_R = resultant_force_kernel(p1, p2, F_l, P[_WEIGHT], P[_A1], P[_A2])
    if mode == 2.0:
        mode = friction_mode_kernel(vX, F_R, P[_DS])
    dvX = cylinder_acceleration_mode_kernel(vX, F_R, mode, P[_M], P[_DV], P[_DC], P[_DS], P[_V0])
    if P[_KI] == 0.0 and P[_KE] == 0.0 and P[_AIR] == 0.0:
        dp1, dp2 = pressure_derivatives_kernel(q1, q2, X, vX, P[_A1], P[_A2], P[_V01], P[_V02],
                                               P[_BETA])
    else:
        V1, V2 = chamber_volumes_kernel(X, P[_A1], P[_A2], P[_V01], P[_V02])
        qi = P[_KI] * (p1 - p2)
        dp1 = effective_bulk_modulus_kernel(p1, P[_BETA], P[_AIR]) / V1 * (q1 - P[_A1] * vX - qi)
        dp2 = (effective_bulk_modulus_kernel(p2, P[_BETA], P[_AIR]) / V2
               * (P[_A2] * vX - q2 + qi - P[_KE] * p2))
    return v, dv, vX, dvX, dp1, dp2


@njit(cache=True)
def rhs_kernel(x, v, X, vX, p1, p2, x_ref, F_l, p_s, p_r, ecs, alpha, P):
    """Eqs. 1-6 for one instant (Eq. 5b decides sticking): time derivatives of
    (x, v, X, v_X, p1, p2)."""
    return rhs_mode_kernel(x, v, X, vX, p1, p2, 2.0, x_ref, F_l, p_s, p_r, ecs, alpha, P)


@njit(cache=True)
def _rk4(s, mode, k1, x_ref, F_l, ps0, psh, ps1, p_r, ecs, alpha, P, h):
    """One classical RK4 step of length h on friction branch ``mode``; ``k1`` = rhs at s."""
    x, v, X, vX, p1, p2 = s
    a1, b1, c1, d1, e1, f1 = k1
    hh = 0.5 * h
    a2, b2, c2, d2, e2, f2 = rhs_mode_kernel(x + hh * a1, v + hh * b1, X + hh * c1,
                                             vX + hh * d1, p1 + hh * e1, p2 + hh * f1, mode,
                                             x_ref, F_l, psh, p_r, ecs, alpha, P)
    a3, b3, c3, d3, e3, f3 = rhs_mode_kernel(x + hh * a2, v + hh * b2, X + hh * c2,
                                             vX + hh * d2, p1 + hh * e2, p2 + hh * f2, mode,
                                             x_ref, F_l, psh, p_r, ecs, alpha, P)
    a4, b4, c4, d4, e4, f4 = rhs_mode_kernel(x + h * a3, v + h * b3, X + h * c3,
                                             vX + h * d3, p1 + h * e3, p2 + h * f3, mode,
                                             x_ref, F_l, ps1, p_r, ecs, alpha, P)
    h6 = h / 6.0
    return (x + h6 * (a1 + 2.0 * a2 + 2.0 * a3 + a4),
            v + h6 * (b1 + 2.0 * b2 + 2.0 * b3 + b4),
            X + h6 * (c1 + 2.0 * c2 + 2.0 * c3 + c4),
            vX + h6 * (d1 + 2.0 * d2 + 2.0 * d3 + d4),
            p1 + h6 * (e1 + 2.0 * e2 + 2.0 * e3 + e4),
            p2 + h6 * (f1 + 2.0 * f2 + 2.0 * f3 + f4))


@njit(cache=True)
def _rk4_at(s, mode, t0, h, x_ref, F_l, sup, ecs, alpha, P):
    """RK4 over [t0, t0 + h] with the supply pressure evaluated from its formula."""
    ps0 = supply_pressure_kernel(t0, sup[0], sup[1], sup[2], sup[3], sup[4])
    psh = supply_pressure_kernel(t0 + 0.5 * h, sup[0], sup[1], sup[2], sup[3], sup[4])
    ps1 = supply_pressure_kernel(t0 + h, sup[0], sup[1], sup[2], sup[3], sup[4])
    k1 = rhs_mode_kernel(s[0], s[1], s[2], s[3], s[4], s[5], mode, x_ref, F_l, ps0, sup[5],
                         ecs, alpha, P)
    return _rk4(s, mode, k1, x_ref, F_l, ps0, psh, ps1, sup[5], ecs, alpha, P, h)


@njit(cache=True)
def _F_R(s, F_l, P):
    return resultant_force_kernel(s[4], s[5], F_l, P[_WEIGHT], P[_A1], P[_A2])


@njit(cache=True)
def _with_vX(s, vX):
    return (s[0], s[1], s[2], vX, s[4], s[5])


@njit(cache=True)
def _mode_of(s, F_l, P):
    if s[3] != 0.0:
        return 1.0 if s[3] > 0.0 else -1.0
    F = _F_R(s, F_l, P)
    if F > P[_DS]:
        return 1.0
    if F < -P[_DS]:
        return -1.0
    return 0.0


@njit(cache=True)
def _event_step(s, t0, h, x_ref, F_l, sup, ecs, alpha, P):
    """Advance over [t0, t0 + h] locating every stick, slip and reversal event inside.

    Sticking (mode 0) lasts until |F_R| reaches d_s (located by regula falsi on F_R); moving
    (mode +-1, friction sign held) lasts until v_X reaches 0 (regula falsi on v_X), where the
    cylinder sticks if |F_R| <= d_s or else moves on in the direction of F_R."""
    d_s = P[_DS]
    rem = h
    t = t0
    mode = _mode_of(s, F_l, P)
    for _ in range(8):
        if rem <= 0.0:
            return s
        new = _rk4_at(s, mode, t, rem, x_ref, F_l, sup, ecs, alpha, P)
        target = 0.0
        if mode == 0.0:
            F1 = _F_R(new, F_l, P)
            if abs(F1) <= d_s:
                return new
            target = d_s if F1 > 0.0 else -d_s
            ga = _F_R(s, F_l, P) - target
            gb = F1 - target
        else:
            if new[3] * mode > 0.0:
                return new
            if s[3] == 0.0:
                # A breakaway that does not get going: F_R fell back inside the band.
                s = _with_vX(new, 0.0)
                if abs(_F_R(s, F_l, P)) <= d_s:
                    return s
                return s
            ga = s[3]
            gb = new[3]
        # Regula falsi (Illinois) for the event time theta * rem in [0, 1].
        ta, tb = 0.0, 1.0
        theta = 0.0
        mid = s
        if ga * gb < 0.0:
            side = 0
            for _it in range(6):
                theta = ta - ga * (tb - ta) / (gb - ga)
                mid = _rk4_at(s, mode, t, theta * rem, x_ref, F_l, sup, ecs, alpha, P)
                g = (_F_R(mid, F_l, P) - target) if mode == 0.0 else mid[3]
                if g == 0.0:
                    break
                if g * ga > 0.0:
                    ta, ga = theta, g
                    if side == -1:
                        gb *= 0.5
                    side = -1
                else:
                    tb, gb = theta, g
                    if side == 1:
                        ga *= 0.5
                    side = 1
        elif gb == 0.0:
            theta = 1.0
            mid = new
        s = _with_vX(mid, 0.0)
        t += theta * rem
        rem -= theta * rem
        if mode == 0.0:
            mode = 1.0 if target > 0.0 else -1.0     # breakaway
        else:
            F = _F_R(s, F_l, P)                        # v_X reached 0: stick or reverse
            mode = 0.0 if abs(F) <= d_s else (1.0 if F > 0.0 else -1.0)
    if rem > 0.0:
        new = _rk4_at(s, mode, t, rem, x_ref, F_l, sup, ecs, alpha, P)
        if mode != 0.0 and new[3] * mode < 0.0:
            new = _with_vX(new, 0.0)
        return new
    return s


@njit(cache=True)
def _simulate_kernel(X_ref, v_ref, F_l, supply, ecs_all, alpha_all, state0, integ0,
                     ff_grid, ff_table, ff_weight, kp, ki_t0, aw_t0, x_lim, P, fs, n_sub,
                     p_limit, out, end):
    """Integrate every window; ``out`` (13, W, N) receives x, v, X, vX, p1, p2, ps, pr,
    x_ref, F_l, dp1, dp2, t and ``end`` (W, 7) the state and the controller's integrator
    after the last sample. Returns w * N + k for the first window w that diverged in sample k
    (a pressure beyond +-p_limit, |v_X| > 1000 m/s, |x| > 1 m or NaN), or -1."""
    n_win, n_samp = X_ref.shape
    P = params_tuple(P)
    T0 = 1.0 / fs
    h = T0 / n_sub
    d_s = P[_DS]
    for w in range(n_win):
        ecs, alpha = _valve_tuples(ecs_all[w], alpha_all[w])
        sup = (supply[w, 0], supply[w, 1], supply[w, 2], supply[w, 3], supply[w, 4],
               supply[w, 5])
        p_s0, drift, amp, om, ph, p_r = sup[0], sup[1], sup[2], sup[3], sup[4], sup[5]
        # The ripple is advanced by rotation over half steps, re-synchronised every sample.
        cr = math.cos(0.5 * om * h)
        sr = math.sin(0.5 * om * h)
        s = (state0[w, 0], state0[w, 1], state0[w, 2], state0[w, 3], state0[w, 4], state0[w, 5])
        integ = integ0[w]
        for k in range(n_samp):
            t = k * T0
            sn = math.sin(om * t + ph)
            cs = math.cos(om * t + ph)
            ps_t = p_s0 + drift * t + amp * sn
            e = X_ref[w, k] - s[2]
            ff = ff_weight * interp_kernel(v_ref[w, k], ff_grid, ff_table)
            x_ref, integ = pi_step_kernel(e, integ, ff, kp, ki_t0, aw_t0, x_lim)
            fl = F_l[w, k]
            k1 = rhs_kernel(s[0], s[1], s[2], s[3], s[4], s[5], x_ref, fl, ps_t, p_r, ecs,
                            alpha, P)
            out[0, w, k] = s[0]
            out[1, w, k] = s[1]
            out[2, w, k] = s[2]
            out[3, w, k] = s[3]
            out[4, w, k] = s[4]
            out[5, w, k] = s[5]
            out[6, w, k] = ps_t
            out[7, w, k] = p_r
            out[8, w, k] = x_ref
            out[9, w, k] = fl
            out[10, w, k] = k1[4]
            out[11, w, k] = k1[5]
            out[12, w, k] = t
            for j in range(n_sub):
                tj = t + j * h
                sn, cs = sn * cr + cs * sr, cs * cr - sn * sr
                ps_h = p_s0 + drift * (tj + 0.5 * h) + amp * sn
                sn, cs = sn * cr + cs * sr, cs * cr - sn * sr
                ps_1 = p_s0 + drift * (tj + h) + amp * sn
                mode = _mode_of(s, fl, P)
                if j > 0 or mode == 0.0:
                    k1 = rhs_mode_kernel(s[0], s[1], s[2], s[3], s[4], s[5], mode, x_ref, fl,
                                         ps_t, p_r, ecs, alpha, P)
                new = _rk4(s, mode, k1, x_ref, fl, ps_t, ps_h, ps_1, p_r, ecs, alpha, P, h)
                if mode != 0.0:
                    ok = new[3] * mode > 0.0
                else:
                    ok = abs(_F_R(new, fl, P)) <= d_s
                if ok:
                    s = new
                else:
                    s = _event_step(s, tj, h, x_ref, fl, sup, ecs, alpha, P)
                ps_t = ps_1
            # divergence: non-finite or absurd states (RK4 beyond its stability limit)
            if not (abs(s[4]) < p_limit and abs(s[5]) < p_limit and abs(s[3]) < 1.0e3
                    and abs(s[0]) < 1.0):
                return w * n_samp + k
        for i in range(6):
            end[w, i] = s[i]
        end[w, 6] = integ
    return -1


@dataclass(frozen=True)
class SimulationResult:
    """True signals of a batch of simulated windows at the sample rate.

    Every array has shape (n_windows, n_samples); sample k of a window is at t = k / f_s
    (window-relative time).

    Attributes
    ----------
    t_s : Time since the window's start. [s]
    x_m : Spool displacement x. [m]
    v_m_s : Spool velocity v. [m/s]
    X_m : Cylinder position X. [m]
    vX_m_s : Cylinder velocity v_X (exactly 0 while sticking). [m/s]
    p1_pa, p2_pa : Chamber pressures. [Pa]
    ps_pa, pr_pa : Supply and return pressure. [Pa]
    x_ref_m : Spool reference from the controller, held until the next sample. [m]
    F_l_n : External load, held until the next sample. [N]
    dp1_dt_pa_s, dp2_dt_pa_s : Exact time derivatives of p1, p2 from the rhs. [Pa/s]
    X_ref_m : Reference cylinder position. [m]
    v_ref_m_s : Reference cylinder velocity. [m/s]
    conditions : The valve condition of each window.
    sample_rate_hz : Sample rate. [Hz]
    effects : The library effects simulated (:mod:`model.effects`), None = none. The arrays
        hold the true signals; :func:`model.sensors.measure` applies the sensor effects.
    end_state : (n_windows, 7): the state (x, v, X, v_X, p1, p2) one sample period after the
        last sample and the controller's integrator after it; a window continued from it
        (``simulate_inputs(initial_states=end_state[:, :6],
        initial_integrators=end_state[:, 6])``) is seamless. None if not recorded.
    """

    t_s: np.ndarray
    x_m: np.ndarray
    v_m_s: np.ndarray
    X_m: np.ndarray
    vX_m_s: np.ndarray
    p1_pa: np.ndarray
    p2_pa: np.ndarray
    ps_pa: np.ndarray
    pr_pa: np.ndarray
    x_ref_m: np.ndarray
    F_l_n: np.ndarray
    dp1_dt_pa_s: np.ndarray
    dp2_dt_pa_s: np.ndarray
    X_ref_m: np.ndarray
    v_ref_m_s: np.ndarray
    conditions: tuple[ValveCondition, ...]
    sample_rate_hz: float
    effects: Effects | None = None
    end_state: np.ndarray | None = None

    @property
    def dp1_dt(self) -> np.ndarray:
        """Alias of ``dp1_dt_pa_s``. [Pa/s]"""
        return self.dp1_dt_pa_s

    @property
    def dp2_dt(self) -> np.ndarray:
        """Alias of ``dp2_dt_pa_s``. [Pa/s]"""
        return self.dp2_dt_pa_s

    @property
    def n_windows(self) -> int:
        return self.x_m.shape[0]

    @property
    def n_samples(self) -> int:
        return self.x_m.shape[1]


def rhs(t: float, state, inputs, params: PlantParams, condition: ValveCondition | None = None,
        reg_band_pa: float = 0.0, effects: Effects | None = None) -> np.ndarray:
    """Right-hand side of the plant, Eqs. 1-6 (python-control ``updfcn`` convention).

    Parameters
    ----------
    t : float
        Time (unused: the plant is time-invariant). [s]
    state : array_like, shape (6,)
        (x [m], v [m/s], X [m], v_X [m/s], p1 [Pa], p2 [Pa]).
    inputs : array_like, shape (4,)
        (x_ref [m], F_l [N], p_s [Pa], p_r [Pa]).
    params : PlantParams
    condition : ValveCondition, optional
        Default ``params.nominal_condition``.
    reg_band_pa : float
        Regularisation band of the orifice law; 0 = exact Eq. 4. [Pa]
    effects : Effects, optional
        Library effects (:mod:`model.effects`) switched on; default none (the base model).
        The state is the true state (sensor effects do not enter the plant, except the spool
        sensor offset through the valve's inner position loop).

    Returns
    -------
    ndarray, shape (6,)
        (dx/dt, dv/dt, dX/dt, dv_X/dt, dp1/dt, dp2/dt) in SI units. At v_X = 0 the cylinder
        sticks while |F_R| <= d_s (Eq. 5b).
    """
    cond = params.nominal_condition if condition is None else condition
    s = np.asarray(state, dtype=np.float64)
    u = np.asarray(inputs, dtype=np.float64)
    return _rhs_arrays(s, u, valve_edge_constants(params.geometry, cond),
                       np.asarray(cond.alpha, float), pack_params(params, reg_band_pa, effects))


@njit(cache=True)
def _rhs_arrays(s, u, ecs, alpha, P):
    e, a = _valve_tuples(ecs, alpha)
    d = rhs_kernel(s[0], s[1], s[2], s[3], s[4], s[5], u[0], u[1], u[2], u[3], e, a,
                   params_tuple(P))
    out = np.empty(6)
    for i in range(6):
        out[i] = d[i]
    return out


class SimulationDiverged(FloatingPointError):
    """The integration left the physical range (module docstring): in window ``window`` of
    the batch, ``time_s`` after its start."""

    def __init__(self, window: int, time_s: float):
        super().__init__(window, time_s)
        self.window = window
        self.time_s = time_s

    def __str__(self) -> str:
        return (f"simulation diverged in window {self.window} at t = {self.time_s:.3f} s; "
                "reduce the step (more substeps) or check the inputs")


def window_seed(seed: int, window_index: int) -> np.random.Generator:
    """The random generator of window ``window_index`` of a batch simulated with ``seed``."""
    return np.random.default_rng([int(seed), int(window_index)])


def _check_rates(params: PlantParams) -> float:
    fs = params.sensors.sample_rate_hz
    if abs(params.controller.sample_time_s * fs - 1.0) > 1e-9:
        raise ValueError("the controller sample time must equal the acquisition period 1/f_s")
    return fs


def simulate_inputs(params: PlantParams, conditions: Sequence[ValveCondition],
                    inputs: Sequence[WindowInputs], *, substeps: int = DEFAULT_SUBSTEPS,
                    reg_band_pa: float = DEFAULT_REG_BAND_PA,
                    initial_states: np.ndarray | None = None,
                    effects: Effects | None = None,
                    initial_integrators: np.ndarray | None = None) -> SimulationResult:
    """Simulate windows with given inputs (see :func:`simulate_windows`).

    Parameters
    ----------
    params : PlantParams
    conditions : sequence of ValveCondition
        One per window.
    inputs : sequence of WindowInputs
        One per window, all of the same length.
    substeps : int
        RK4 steps per sample.
    reg_band_pa : float
        Orifice-law regularisation band. [Pa]
    initial_states : ndarray (n_windows, 6), optional
        Start states; default the rest state of each window (module docstring). The
        controller's integrator then starts so that x_ref = x at t = 0 (x_ref = x + delta_x
        with a spool sensor offset, so that the spool rests there).
    effects : Effects, optional
        Library effects (:mod:`model.effects`) of every window; default none, which is the
        base model exactly. The controller's feed-forward stays that of the nominal plant.
        With leakage or a supply line the rest state is that of the model with the effect.
    initial_integrators : ndarray (n_windows,), optional
        Start values of the controller's integrator (with ``initial_states``: a window that
        continues another from its ``end_state``); default as above. [m]

    Returns
    -------
    SimulationResult
    """
    fs = _check_rates(params)
    conditions = tuple(conditions)
    if len(conditions) != len(inputs):
        raise ValueError("need one condition per window")
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    n_win = len(inputs)
    n_samp = inputs[0].X_ref_m.size
    X_ref = np.empty((n_win, n_samp))
    v_ref = np.empty((n_win, n_samp))
    F_l = np.empty((n_win, n_samp))
    supply = np.empty((n_win, 6))
    ecs = np.empty((n_win, 4, valve_edge_constants(params.geometry, conditions[0]).shape[1]))
    alpha = np.empty((n_win, 4))
    state0 = np.zeros((n_win, 6))
    integ0 = np.empty(n_win)
    ff_grid, ff_table = feedforward_table(params)
    ffw = params.controller.feedforward
    plant = apply_to_params(params, effects)
    P = pack_params(params, reg_band_pa, effects)
    dxs = 0.0 if effects is None else effects.spool_sensor_offset_m
    for w, (cond, inp) in enumerate(zip(conditions, inputs)):
        if inp.X_ref_m.size != n_samp:
            raise ValueError("all windows must have the same number of samples")
        if not (np.all(np.isfinite(inp.X_ref_m)) and np.all(np.isfinite(inp.v_ref_m_s))
                and np.all(np.isfinite(inp.F_l_n))
                and np.all(np.isfinite(inp.supply.as_array()))):
            raise ValueError(f"window {w}: inputs must be finite")
        X_ref[w], v_ref[w], F_l[w] = inp.X_ref_m, inp.v_ref_m_s, inp.F_l_n
        supply[w] = inp.supply.as_array()
        ecs[w] = valve_edge_constants(params.geometry, cond)
        alpha[w] = cond.alpha
        if initial_states is None:
            p_s0 = float(inp.supply.p_s(0.0))
            rest = standstill(plant, cond, F_l_n=F_l[w, 0], p_s_pa=p_s0,
                              p_r_pa=inp.supply.p_r_pa)
            state0[w] = (rest.x_m, 0.0, X_ref[w, 0], 0.0, rest.p1_pa, rest.p2_pa)
            if effects is not None and effects.has_flow_terms:
                state0[w] = _rest_with_effects(state0[w], F_l[w, 0], p_s0, inp.supply.p_r_pa,
                                               ecs[w], alpha[w], P)
        else:
            state0[w] = initial_states[w]
        ff0 = ffw * np.interp(v_ref[w, 0], ff_grid, ff_table)
        integ0[w] = (state0[w, 0] + dxs - ff0
                     - params.controller.kp_m_per_m * (X_ref[w, 0] - state0[w, 2]))
    if initial_integrators is not None:
        integ0[:] = initial_integrators
    c = params.controller
    out = np.empty((13, n_win, n_samp))
    end = np.empty((n_win, 7))
    bad = _simulate_kernel(X_ref, v_ref, F_l, supply, ecs, alpha, state0, integ0,
                           ff_grid, ff_table, ffw, c.kp_m_per_m,
                           c.kp_m_per_m * c.sample_time_s / c.ti_s, c.sample_time_s / c.tt_s,
                           params.x_limit_m, P, fs, int(substeps),
                           P_LIMIT_FACTOR * float(np.max(supply[:, 0])), out, end)
    if bad >= 0:
        w, k = divmod(bad, n_samp)
        raise SimulationDiverged(w, k / fs)
    return SimulationResult(
        t_s=out[12], x_m=out[0], v_m_s=out[1], X_m=out[2], vX_m_s=out[3], p1_pa=out[4],
        p2_pa=out[5], ps_pa=out[6], pr_pa=out[7], x_ref_m=out[8], F_l_n=out[9],
        dp1_dt_pa_s=out[10], dp2_dt_pa_s=out[11], X_ref_m=X_ref, v_ref_m_s=v_ref,
        conditions=conditions, sample_rate_hz=fs, effects=effects, end_state=end)


def _rest_with_effects(state, F_l, p_s, p_r, ecs, alpha, P, iterations: int = 30) -> np.ndarray:
    """The rest state (v_X = 0, dp1/dt = dp2/dt = 0, F_R = 0) of the model with leakage, air
    or a supply line, by Newton's method on (x, p1, p2) from the base model's rest ``state``;
    returns ``state`` unchanged if it does not converge."""
    s = np.array(state, dtype=np.float64)
    u = np.array([0.0, F_l, p_s, p_r])
    A1, A2, weight = P[_A1], P[_A2], P[_WEIGHT]
    scale = np.array([1.0e-9, 1.0, 1.0])  # dp/dt [Pa/s] is ~1e9 x the flow imbalance [m^3/s]

    def g(z):
        s[0], s[4], s[5] = z
        u[0] = z[0] + P[_DXS]  # x_ref that holds the spool at x
        d = _rhs_arrays(s, u, ecs, alpha, P)
        return np.array([d[4], d[5], (weight + A1 * z[1] - A2 * z[2] - F_l) * 1.0e3]) * scale

    z = np.array([state[0], state[4], state[5]], dtype=np.float64)
    steps = np.array([1.0e-9, 1.0, 1.0])
    for _ in range(iterations):
        f = g(z)
        J = np.empty((3, 3))
        for j in range(3):
            dz = np.zeros(3)
            dz[j] = steps[j]
            J[:, j] = (g(z + dz) - f) / steps[j]
        try:
            step = np.linalg.solve(J, -f)
        except np.linalg.LinAlgError:
            return np.asarray(state, dtype=np.float64)
        z = z + step
        if abs(step[0]) < 1.0e-13 and abs(step[1]) < 1.0e-3 and abs(step[2]) < 1.0e-3:
            out = np.array(state, dtype=np.float64)
            out[0], out[4], out[5] = z
            return out
    return np.asarray(state, dtype=np.float64)


def simulate_windows(params: PlantParams, conditions: Sequence[ValveCondition],
                     duration_s: float, seed: int, *, substeps: int = DEFAULT_SUBSTEPS,
                     reg_band_pa: float = DEFAULT_REG_BAND_PA,
                     effects: Effects | None = None) -> SimulationResult:
    """Simulate one window per entry of ``conditions``, each ``duration_s`` long.

    Window i draws its trajectory, load and supply profile from
    ``numpy.random.default_rng([seed, i])`` (:func:`window_seed`), so a window depends only on
    (params, its condition, duration, seed, i) -- not on the batch it is simulated in.

    Parameters
    ----------
    params : PlantParams
    conditions : sequence of ValveCondition
        Valve condition of each window.
    duration_s : float
        Window length. [s]
    seed : int
        Base seed.
    substeps : int
        RK4 steps per sample (default 2: 0.5 ms at 1 kHz).
    reg_band_pa : float
        Orifice-law regularisation band (default 0.1 bar). [Pa]
    effects : Effects, optional
        Library effects (:mod:`model.effects`); default none (the base model).

    Returns
    -------
    SimulationResult
        Arrays of shape (len(conditions), round(duration_s * f_s)).
    """
    inputs = [window_inputs(params, duration_s, window_seed(seed, i))
              for i in range(len(conditions))]
    return simulate_inputs(params, conditions, inputs, substeps=substeps,
                           reg_band_pa=reg_band_pa, effects=effects)

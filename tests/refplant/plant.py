"""The reference plant's equations and their integration.

State (7): spool x [m], v [m/s]; cylinder X [m], v_X [m/s]; chamber pressures p1, p2 [Pa]; the
PI controller's integral z [m]. Right-hand side (:func:`rhs_kernel`, numba):

* controller (continuous time): e = X_ref - X, u = w_ff x_ff(v_ref) + K_p e + z,
  x_ref = sat(u), dz/dt = K_p e / T_i + (x_ref - u) / T_t; or a prescribed spool command;
* spool, Eq. 1: a = -(2 zeta / T) v - (x - x_cmd) / T^2, dv/dt = 0 at the velocity limit in the
  direction of a; x_cmd = x_ref - delta_x (the inner loop regulates the transducer's reading);
* orifices, Eqs. 2 and 4, each edge its own law (:mod:`.edges`) and alpha; the supply pressure at
  the valve solves p_v = p_s - R q_s|q_s| when there is a supply line;
* cylinder, Eq. 5: F_R = m g + A1 p1 - A2 p2 - F_l; sliding: F_f = d_v v_X + (d_c + (d_s - d_c)
  exp(-v_X^2/v_0^2)) sign(v_X); Karnopp: for |v_X| < band the rod sticks (dv_X/dt = -v_X / t_stick)
  while |F_R| <= d_s, else it breaks away in the direction of F_R against the same Stribeck force
  (|F_f(v_X)|, about d_s there), so the law is continuous across the band's edge and a force just
  above d_s gives a slow creep inside the band rather than chattering at its edge;
* chambers, Eq. 6 with leakage and air: dp1/dt = beta_e(p1)/V1 (q1 - A1 v_X - q_i),
  dp2/dt = beta_e(p2)/V2 (A2 v_X - q2 + q_i - q_e), V1 = V01 + A1 X, V2 = V02 - A2 X.

:func:`integrate` runs scipy's LSODA (or ``solve_ivp``'s BDF or Radau) once per segment (a 10 s
window is one segment) and returns the dense solution on a fine time grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.integrate import LSODA, solve_ivp
from scipy.optimize import root

from .edges import area_kernel, edge_rows, laminar_factor
from .params import Integration, RefPlant
from .scenarios import Effects, Load, Trajectory

P_ATM = 1.013e5
AIR_N = 1.4
N_STATE = 7

(_T, _ZETA, _VMAX, _M, _W, _A1, _A2, _V01, _V02, _BETA, _KRHO, _DPT, _DV, _DC, _DS, _V0, _BAND,
 _TST, _KI, _KE, _AIR, _DXS, _RS, _KSEAL, _KP, _TI, _TT, _XLIM, _WFF, _FFS, _FFM, _FFDV, _FFDC,
 _PSN, _PRN, _PS0, _DRIFT, _RIP, _OMEGA, _PHASE, _PR, _FS, _X0, _NP) = range(44)


def pack(plant: RefPlant, effects: Effects, supply: tuple, X0_m: float) -> np.ndarray:
    """Flat parameter vector of the kernels. ``supply`` = (p_s0, drift, ripple, f, phase, p_r)."""
    s, c, f, k = plant.spool, plant.cylinder, plant.fluid, plant.controller
    v = plant.valve
    P = np.zeros(_NP)
    m = c.mass_kg + effects.delta_mass_kg
    d_v = c.d_v_n_s_m + effects.delta_viscous_n_s_m
    if m <= 0 or d_v < 0:
        raise ValueError("the mass or friction change leaves m <= 0 or d_v < 0")
    P[[_T, _ZETA, _VMAX]] = s.T_s, s.zeta, s.v_max_m_s
    P[[_M, _W, _A1, _A2, _V01, _V02]] = m, m * c.g_m_s2, c.A1, c.A2, c.v01_m3, c.v02_m3
    P[[_BETA, _KRHO, _DPT]] = f.bulk_modulus_pa, math.sqrt(2.0 / f.density_kg_m3), f.dp_transition_pa
    P[[_DV, _DC, _DS, _V0, _BAND, _TST]] = d_v, c.d_c_n, c.d_s_n, c.v0_m_s, c.karnopp_band_m_s, c.stick_time_s
    e = effects
    P[[_KI, _KE, _AIR, _DXS, _RS, _KSEAL]] = (e.internal_leakage_m3_s_pa, e.external_leakage_m3_s_pa,
                                              e.air_fraction, e.spool_sensor_offset_m,
                                              e.supply_resistance_pa_s2_m6, e.seal_friction_m2)
    P[[_KP, _TI, _TT, _XLIM, _WFF]] = k.kp_m_per_m, k.ti_s, k.tt_s, plant.x_limit_m, k.feedforward
    # feed-forward of the clean plant's data (tuned at commissioning): S = A1^3/g1^2 + A2^3/g2^2
    alpha = np.mean([ed.alpha for ed in v.edges])
    g1, g2 = alpha * v.port_gradient(0), alpha * v.port_gradient(2)
    P[_FFS] = c.A1**3 / g1**2 + c.A2**3 / g2**2
    P[[_FFM, _FFDV, _FFDC]] = c.mass_kg * c.g_m_s2, c.d_v_n_s_m, c.d_c_n
    P[[_PSN, _PRN]] = plant.supply.p_s_pa, plant.supply.p_r_pa
    P[[_PS0, _DRIFT, _RIP]] = supply[0], supply[1], supply[2]
    P[[_OMEGA, _PHASE, _PR]] = 2.0 * math.pi * supply[3], supply[4], supply[5]
    P[_FS] = plant.sensors.sample_rate_hz
    P[_X0] = X0_m
    return P


@njit(cache=True)
def ssqrt(dp, dpt):
    """sign(dp) sqrt|dp|, smooth through 0: dp / (dp^2 + dp_t^2)^(1/4). [sqrt(Pa)]"""
    return dp / (dp * dp + dpt * dpt) ** 0.25


@njit(cache=True)
def reference_kernel(t, X0, ts, dur, xa, xb):
    """(X_ref, v_ref) of the minimum-jerk moves at t."""
    j = np.searchsorted(ts, t, side="right") - 1
    if j < 0:
        return X0, 0.0
    T = dur[j]
    s = (t - ts[j]) / T
    if s >= 1.0:
        return xb[j], 0.0
    d = xb[j] - xa[j]
    return xa[j] + d * s * s * s * (10.0 - 15.0 * s + 6.0 * s * s), d / T * 30.0 * s * s * (1.0 - s) * (1.0 - s)


@njit(cache=True)
def feedforward_kernel(v, P):
    """Steady spool opening of a linear-gradient valve at cylinder speed v, no load (closed form:
    extension (v/(k x))^2 S = A1 p_s - A2 p_r + m g - F_f(v), retraction
    (v/(k x))^2 S = A2 p_s - A1 p_r - m g + F_f(v)). [m]"""
    if v == 0.0:
        return 0.0
    if v > 0.0:
        D = P[_A1] * P[_PSN] - P[_A2] * P[_PRN] + P[_FFM] - P[_FFDV] * v - P[_FFDC]
    else:
        D = P[_A2] * P[_PSN] - P[_A1] * P[_PRN] - P[_FFM] + P[_FFDV] * v - P[_FFDC]
    if D <= 0.0:
        return P[_XLIM] if v > 0 else -P[_XLIM]
    x = v / P[_KRHO] * math.sqrt(P[_FFS] / D)
    return min(max(x, -P[_XLIM]), P[_XLIM])


@njit(cache=True)
def supply_at_valve(ps, p1, p2, gs1, gs2, k, dpt, R, x, rows):
    """p_v with p_v = p_s - R q_s|q_s|, q_s = k (gs1 ssqrt(p_v - p1) c1 + gs2 ssqrt(p_v - p2) c2),
    c the edges' :func:`laminar_factor` at spool position x: bisection on the bracket, 60 halvings
    (f(p_v) rises with p_v). [Pa]"""
    if R <= 0.0:
        return ps
    lo = min(ps, p1, p2)
    hi = max(ps, p1, p2)
    for _ in range(60):
        pv = 0.5 * (lo + hi)
        q = k * (gs1 * ssqrt(pv - p1, dpt) * laminar_factor(x, pv - p1, rows[0])
                 + gs2 * ssqrt(pv - p2, dpt) * laminar_factor(-x, pv - p2, rows[2]))
        if pv - ps + R * q * abs(q) > 0.0:
            hi = pv
        else:
            lo = pv
        if hi - lo < 1.0e-3:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def flows_kernel(x, p1, p2, ps, pr, rows, P):
    """(q1 into chamber 1, q2 out of chamber 2 through the valve [m^3/s], supply at the valve [Pa])."""
    k, dpt = P[_KRHO], P[_DPT]
    g0 = rows[0, 2] * area_kernel(x, rows[0])
    g1 = rows[1, 2] * area_kernel(-x, rows[1])
    g2 = rows[2, 2] * area_kernel(-x, rows[2])
    g3 = rows[3, 2] * area_kernel(x, rows[3])
    pv = supply_at_valve(ps, p1, p2, g0, g2, k, dpt, P[_RS], x, rows)
    q1 = k * (g0 * ssqrt(pv - p1, dpt) * laminar_factor(x, pv - p1, rows[0]) + g1 * ssqrt(pr - p1, dpt) * laminar_factor(-x, pr - p1, rows[1]))
    q2 = k * (g2 * ssqrt(p2 - pv, dpt) * laminar_factor(-x, p2 - pv, rows[2]) + g3 * ssqrt(p2 - pr, dpt) * laminar_factor(x, p2 - pr, rows[3]))
    return q1, q2, pv


@njit(cache=True)
def bulk_kernel(p, beta, eps):
    """beta_e(p): 1/beta_e = 1/beta + eps (p_atm/(p+p_atm))^(1/n) / (n (p+p_atm)). [Pa]"""
    if eps == 0.0:
        return beta
    pa = max(p + P_ATM, 0.05 * P_ATM)
    return 1.0 / (1.0 / beta + eps * (P_ATM / pa) ** (1.0 / AIR_N) / (AIR_N * pa))


@njit(cache=True)
def controller_kernel(t, X, z, P, ts, dur, xa, xb, xcmd):
    """(x_ref, dz/dt, X_ref, v_ref) at t: the PI law, or the prescribed command ``xcmd`` (held per sample)."""
    Xr, vr = reference_kernel(t, P[_X0], ts, dur, xa, xb)
    if xcmd.size > 0:
        k = min(max(int(math.floor(t * P[_FS] + 1e-9)), 0), xcmd.size - 1)
        return xcmd[k], 0.0, Xr, vr
    e = Xr - X
    u = P[_WFF] * feedforward_kernel(vr, P) + P[_KP] * e + z
    xr = min(max(u, -P[_XLIM]), P[_XLIM])
    return xr, P[_KP] * e / P[_TI] + (xr - u) / P[_TT], Xr, vr


@njit(cache=True)
def rhs_kernel(t, y, P, rows, ts, dur, xa, xb, lt, lf, xcmd):
    """dy/dt of the 7 states (module docstring)."""
    x, v, X, vX, p1, p2, z = y[0], y[1], y[2], y[3], y[4], y[5], y[6]
    xr, dz, _, _ = controller_kernel(t, X, z, P, ts, dur, xa, xb, xcmd)
    a = -(2.0 * P[_ZETA] / P[_T]) * v - (x - (xr - P[_DXS])) / (P[_T] * P[_T])
    dv = 0.0 if (a >= 0.0 and v >= P[_VMAX]) or (a <= 0.0 and v <= -P[_VMAX]) else a
    ps = P[_PS0] + P[_DRIFT] * t + P[_RIP] * math.sin(P[_OMEGA] * t + P[_PHASE])
    q1, q2, _ = flows_kernel(x, p1, p2, ps, P[_PR], rows, P)
    F_l = np.interp(t, lt, lf)
    F_R = P[_W] + P[_A1] * p1 - P[_A2] * p2 - F_l
    seal = P[_KSEAL] * (p1 + p2)
    F_c, F_s = P[_DC] + seal, P[_DS] + seal
    r = vX / P[_V0]
    slide = P[_DV] * abs(vX) + F_c + (F_s - F_c) * math.exp(-r * r)
    if abs(vX) >= P[_BAND]:
        dvX = (F_R - math.copysign(slide, vX)) / P[_M]
    elif abs(F_R) <= F_s:
        dvX = -vX / P[_TST]
    else:
        dvX = (F_R - math.copysign(slide, F_R)) / P[_M]
    qi = P[_KI] * (p1 - p2)
    qe = P[_KE] * p2
    V1 = P[_V01] + P[_A1] * X
    V2 = P[_V02] - P[_A2] * X
    out = np.empty(7)
    out[0] = v
    out[1] = dv
    out[2] = vX
    out[3] = dvX
    out[4] = bulk_kernel(p1, P[_BETA], P[_AIR]) / V1 * (q1 - P[_A1] * vX - qi)
    out[5] = bulk_kernel(p2, P[_BETA], P[_AIR]) / V2 * (P[_A2] * vX - q2 + qi - qe)
    out[6] = dz
    return out


@dataclass(frozen=True)
class Inputs:
    """Everything exogenous of one run, in the kernels' layout."""

    P: np.ndarray
    rows: np.ndarray
    traj: tuple
    load: tuple
    xcmd: np.ndarray

    @classmethod
    def build(cls, plant: RefPlant, effects: Effects, supply: tuple, trajectory: Trajectory,
              load: Load, spool_command: np.ndarray | None = None) -> "Inputs":
        return cls(pack(plant, effects, supply, trajectory.X0_m), edge_rows(plant.valve, plant.fluid), trajectory.arrays(),
                   (np.ascontiguousarray(load.t_s, float), np.ascontiguousarray(load.force_n, float)),
                   np.ascontiguousarray(np.empty(0) if spool_command is None else spool_command, float))

    def rhs(self, t, y):
        return rhs_kernel(t, y, self.P, self.rows, *self.traj, *self.load, self.xcmd)

    def supply_pressure(self, t) -> np.ndarray:
        P = self.P
        return P[_PS0] + P[_DRIFT] * t + P[_RIP] * np.sin(P[_OMEGA] * t + P[_PHASE])

    @property
    def p_r(self) -> float:
        return float(self.P[_PR])


def rest_state(inp: Inputs) -> np.ndarray:
    """The start state at t = 0: the cylinder at rest at X_ref(0) with F_R = 0 and no flow into
    either chamber (q1 = q_i, q2 = q_i - q_e), the spool where that holds, the integral so that the
    controller commands that spool position (scipy ``root`` on (x, p1, p2))."""
    P = inp.P
    X0 = P[_X0]
    ps, pr = float(inp.supply_pressure(0.0)), inp.p_r
    F_l = float(np.interp(0.0, *inp.load))
    A1, A2, W = P[_A1], P[_A2], P[_W]

    def g(z):
        x, p1, p2 = z[0] * 1e-4, z[1] * 1e7, z[2] * 1e7
        q1, q2, _ = flows_kernel(x, p1, p2, ps, pr, inp.rows, P)
        qi, qe = P[_KI] * (p1 - p2), P[_KE] * p2
        return [(q1 - qi) * 1e5, (q2 - qi + qe) * 1e5, (W + A1 * p1 - A2 * p2 - F_l) * 1e-4]

    p1 = (F_l - W + A2 * ps) / (A1 + A2)
    sol = root(g, [0.0, p1 * 1e-7, (ps - p1) * 1e-7], method="hybr", options={"xtol": 1e-12})
    if not sol.success:
        raise RuntimeError(f"no rest state found: {sol.message}")
    x, p1, p2 = sol.x[0] * 1e-4, sol.x[1] * 1e7, sol.x[2] * 1e7
    y = np.array([x, 0.0, X0, 0.0, p1, p2, 0.0])
    if inp.xcmd.size == 0:
        Xr, vr = reference_kernel(0.0, X0, *inp.traj)
        y[6] = x + P[_DXS] - P[_WFF] * feedforward_kernel(vr, P) - P[_KP] * (Xr - X0)
    return y


def absolute_tolerance(it: Integration) -> np.ndarray:
    """The absolute tolerance per state (x, v, X, v_X, p1, p2, z) at ``it.rtol``."""
    return np.array([1e-9, 1e-6, 1e-8, 1e-6, 1.0, 1.0, 1e-9]) * (it.rtol / 1e-6)


def integrate(inp: Inputs, y0: np.ndarray, t_grid: np.ndarray, plant: RefPlant) -> tuple[np.ndarray, int]:
    """States (7, len(t_grid)) on ``t_grid`` (increasing, from the start time t_grid[0]) from
    one integration with dense output; returns (states, number of rhs evaluations)."""
    it = plant.integration
    atol = absolute_tolerance(it)
    span = (float(t_grid[0]), float(t_grid[-1]))
    if it.method == "LSODA":
        out, nfev = _integrate_lsoda(inp, y0, t_grid, span, it.rtol, atol, it.max_step_s)
    else:
        sol = solve_ivp(inp.rhs, span, y0, method=it.method, rtol=it.rtol, atol=atol, dense_output=True, max_step=it.max_step_s)
        if not sol.success:
            raise RuntimeError(f"integration failed at t = {sol.t[-1]:.4f} s: {sol.message}")
        out, nfev = sol.sol(t_grid), int(sol.nfev)
    bad = ~np.isfinite(out).all(axis=0)
    if bad.any():  # LSODA steps on through NaN derivatives (its error test never fails on them)
        raise RuntimeError(f"integration failed at t = {t_grid[np.argmax(bad)]:.4f} s: a state is not finite")
    return out, nfev


LSODA_MAX_ORDER = 12
"""LSODA's highest order (Adams); its Nordsieck array has at most this many + 1 columns."""


def _integrate_lsoda(inp: Inputs, y0, t_grid, span, rtol, atol, max_step) -> tuple[np.ndarray, int]:
    """:func:`integrate` with scipy's LSODA stepped by hand: each step's Nordsieck array is kept
    as scipy's own dense output reads it (``LSODA._dense_output_impl``), and the grid is evaluated
    from them at once, not through one interpolant object per step (``solve_ivp``'s dense output:
    the same values to the last bits, 42 % less CPU for a 10 s window on its 10 kHz grid)."""
    solver = LSODA(inp.rhs, span[0], y0, span[1], rtol=rtol, atol=atol, max_step=max_step)
    iwork, rwork = solver._lsoda_solver._integrator.iwork, solver._lsoda_solver._integrator.rwork
    n = y0.size
    ends, hs, yhs = [], [], []
    while solver.status == "running":
        message = solver.step()
        if solver.status == "failed":
            raise RuntimeError(f"integration failed at t = {solver.t:.4f} s: {message}")
        order, h = int(iwork[13]), rwork[11]  # the last step's order; the step size it scales to
        yh = np.zeros((n, LSODA_MAX_ORDER + 1))
        yh[:, :order + 1] = np.reshape(rwork[20:20 + (order + 1) * n], (n, order + 1), order="F")
        if iwork[14] < order:  # the order falls next: the last column was not rescaled to h
            yh[:, order] *= (h / rwork[10]) ** order
        ends.append(solver.t)
        hs.append(h)
        yhs.append(yh)
    ends, hs, yhs = np.asarray(ends), np.asarray(hs), np.stack(yhs)
    step = np.minimum(np.searchsorted(ends, t_grid, side="left"), ends.size - 1)
    u = (t_grid - ends[step]) / hs[step]
    out, power = np.zeros((n, t_grid.size)), np.ones(t_grid.size)
    for j in range(LSODA_MAX_ORDER + 1):
        out += yhs[step, :, j].T * power
        power = power * u
    return out, int(solver.nfev)


def controller_output(inp: Inputs, t: np.ndarray, X: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, ...]:
    """(x_ref, X_ref, v_ref) at samples of (t, X, z)."""
    out = np.empty((3, t.size))
    for k in range(t.size):
        xr, _, Xr, vr = controller_kernel(t[k], X[k], z[k], inp.P, *inp.traj, inp.xcmd)
        out[:, k] = xr, Xr, vr
    return out[0], out[1], out[2]


def port_flows(inp: Inputs, x, p1, p2, ps, pr) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q1, q2, supply at the valve) at samples of true states (Eq. 4 with this plant's edges)."""
    n = np.size(x)
    out = np.empty((3, n))
    b = np.broadcast_arrays(*(np.ravel(np.asarray(a, float)) for a in (x, p1, p2, ps, pr)))
    for k in range(n):
        out[:, k] = flows_kernel(b[0][k], b[1][k], b[2][k], b[3][k], b[4][k], inp.rows, inp.P)
    return out[0], out[1], out[2]

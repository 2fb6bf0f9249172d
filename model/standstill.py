"""Standstill and steady motion of the positioning unit; the quick check of Eq. 9.

Eq. 9 (paper Sec. 5.1): at standstill with x ~ 0, symmetric underlap and a linear opening
characteristic on every edge, q1 = q2 = 0 gives

    (p1 - p_r) / (p_s - p1) = (p_s - p2) / (p2 - p_r)        (p_r = 0: p1 + p2 = p_s)

With Eq. 3 the radial clearance acts like an extra underlap (R - r) cot(phi), different on
the two ports, so a healthy valve of Table 1 does not satisfy Eq. 9 exactly (model.md); use
:func:`eq9_residual` against a tolerance or a healthy baseline.

:func:`standstill` solves the exact rest state of the model for a given valve: v_X = 0,
q1 = q2 = 0 (so dp/dt = 0) and the force balance F_R = F_R,target (0 by default; any
|F_R| <= d_s is a rest state because of sticking). q1 = 0 fixes p1 and q2 = 0 fixes p2 for
each spool position x in closed form; F_R(x) is then increasing in x and its root is found
by bisection. :func:`steady_state` does the same for steady motion at v_X != 0
(q1 = A1 v_X, q2 = A2 v_X, F_R = F_f(v_X)); the controller's feed-forward table uses it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .area import edge_area_kernel, edge_tuple_kernel, valve_edge_constants
from .cylinder import friction_force_kernel
from .orifice import port_flows_kernel
from .params import PlantParams, ValveCondition, TABLE1


def eq9_residual(p1_pa, p2_pa, p_s_pa, p_r_pa=0.0):
    """Residual of Eq. 9: (p1 - p_r)/(p_s - p1) - (p_s - p2)/(p2 - p_r).

    Parameters
    ----------
    p1_pa, p2_pa : array_like
        Chamber pressures at standstill. [Pa]
    p_s_pa, p_r_pa : array_like
        Supply and return pressure. [Pa]

    Returns
    -------
    ndarray
        Dimensionless residual; 0 for the idealised symmetric linear valve. Table 1's healthy
        valve at rest gives about -0.17, the paper's broken edge 1r about -1.4. [-]
    """
    p1 = np.asarray(p1_pa, float)
    p2 = np.asarray(p2_pa, float)
    ps = np.asarray(p_s_pa, float)
    pr = np.asarray(p_r_pa, float)
    return (p1 - pr) / (ps - p1) - (ps - p2) / (p2 - pr)


@dataclass(frozen=True)
class RestState:
    """Rest or steady-motion state of the valve and cylinder.

    Attributes
    ----------
    x_m : float
        Spool displacement. [m]
    p1_pa, p2_pa : float
        Chamber pressures. [Pa]
    v_X_m_s : float
        Cylinder velocity (0 at standstill). [m/s]
    """

    x_m: float
    p1_pa: float
    p2_pa: float
    v_X_m_s: float = 0.0


@njit(cache=True)
def _areas_at(x, ecs):
    return (edge_area_kernel(x, edge_tuple_kernel(ecs[0])),
            edge_area_kernel(-x, edge_tuple_kernel(ecs[1])),
            edge_area_kernel(-x, edge_tuple_kernel(ecs[2])),
            edge_area_kernel(x, edge_tuple_kernel(ecs[3])))


@njit(cache=True)
def _pressures_for_flow(x, ecs, alpha, p_s, p_r, k_rho, q1_target, q2_target):
    """p1 with q1(x, p1) = q1_target and p2 with q2(x, p2) = q2_target (exact Eq. 4).

    q1 falls and q2 rises strictly with its chamber pressure, so bisection converges."""
    a_s1, a_1r, a_s2, a_2r = _areas_at(x, ecs)
    if q1_target == 0.0 and q2_target == 0.0:
        a = (alpha[0] * a_s1) ** 2
        b = (alpha[1] * a_1r) ** 2
        c = (alpha[2] * a_s2) ** 2
        d = (alpha[3] * a_2r) ** 2
        return (a * p_s + b * p_r) / (a + b), (c * p_s + d * p_r) / (c + d)
    span = 1.0e9
    lo, hi = p_r - span, p_s + span
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        q1, _q2 = port_flows_kernel(a_s1, a_1r, a_s2, a_2r, alpha[0], alpha[1], alpha[2],
                                    alpha[3], mid, 0.0, p_s, p_r, k_rho, 0.0)
        if q1 > q1_target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-6:
            break
    p1 = 0.5 * (lo + hi)
    lo, hi = p_r - span, p_s + span
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        _q1, q2 = port_flows_kernel(a_s1, a_1r, a_s2, a_2r, alpha[0], alpha[1], alpha[2],
                                    alpha[3], 0.0, mid, p_s, p_r, k_rho, 0.0)
        if q2 < q2_target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-6:
            break
    return p1, 0.5 * (lo + hi)


@njit(cache=True)
def _solve_rest(ecs, alpha, p_s, p_r, k_rho, A1, A2, weight, F_l, v_X, F_target, x_lo, x_hi):
    """Spool position x in [x_lo, x_hi] where F_R(x) = F_target with q1 = A1 v_X and
    q2 = A2 v_X; returns (x, p1, p2, ok)."""
    q1t = A1 * v_X
    q2t = A2 * v_X
    lo, hi = x_lo, x_hi
    p1, p2 = _pressures_for_flow(lo, ecs, alpha, p_s, p_r, k_rho, q1t, q2t)
    f_lo = weight + A1 * p1 - A2 * p2 - F_l - F_target
    p1, p2 = _pressures_for_flow(hi, ecs, alpha, p_s, p_r, k_rho, q1t, q2t)
    f_hi = weight + A1 * p1 - A2 * p2 - F_l - F_target
    if f_lo > 0.0 or f_hi < 0.0:
        return math.nan, math.nan, math.nan, False
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        p1, p2 = _pressures_for_flow(mid, ecs, alpha, p_s, p_r, k_rho, q1t, q2t)
        f = weight + A1 * p1 - A2 * p2 - F_l - F_target
        if f < 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-13:
            break
    x = 0.5 * (lo + hi)
    p1, p2 = _pressures_for_flow(x, ecs, alpha, p_s, p_r, k_rho, q1t, q2t)
    return x, p1, p2, True


@njit(cache=True)
def _rest_table(ecs, alpha, p_s, p_r, k_rho, A1, A2, weight, F_l, v_grid, d_v, d_c, d_s, v0,
                x_max):
    n = v_grid.size
    out = np.empty((n, 3))
    for i in range(n):
        v = v_grid[i]
        F_t = friction_force_kernel(v, d_v, d_c, d_s, v0)
        x, p1, p2, ok = _solve_rest(ecs, alpha, p_s, p_r, k_rho, A1, A2, weight, F_l, v, F_t,
                                    -x_max, x_max)
        out[i, 0] = x
        out[i, 1] = p1
        out[i, 2] = p2
    return out


def _pressures(params, p_s_pa, p_r_pa):
    p_s = params.supply.p_s_nominal_pa if p_s_pa is None else float(p_s_pa)
    p_r = params.supply.p_r_nominal_pa if p_r_pa is None else float(p_r_pa)
    return p_s, p_r


def steady_states(v_X_m_s, params: PlantParams = TABLE1, condition: ValveCondition | None = None,
                  *, F_l_n: float = 0.0, p_s_pa: float | None = None,
                  p_r_pa: float | None = None) -> np.ndarray:
    """Steady motion states for an array of cylinder velocities (vectorised :func:`steady_state`).

    At v_X = 0 the standstill with F_R = 0 is returned. Velocities the valve cannot reach
    within +-x_max give NaN rows.

    Returns
    -------
    ndarray, shape (n, 3)
        Columns x [m], p1 [Pa], p2 [Pa].
    """
    cond = params.nominal_condition if condition is None else condition
    p_s, p_r = _pressures(params, p_s_pa, p_r_pa)
    c = params.cylinder
    v = np.ascontiguousarray(np.asarray(v_X_m_s, dtype=np.float64).ravel())
    return _rest_table(valve_edge_constants(params.geometry, cond), np.asarray(cond.alpha),
                       p_s, p_r, math.sqrt(2.0 / params.fluid.density_kg_m3), c.A1, c.A2,
                       c.weight_n, float(F_l_n), v, c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.v0_m_s,
                       params.geometry.x_max_m)


def steady_state(v_X_m_s: float, params: PlantParams = TABLE1,
                 condition: ValveCondition | None = None, *, F_l_n: float = 0.0,
                 p_s_pa: float | None = None, p_r_pa: float | None = None) -> RestState:
    """Steady motion at constant cylinder velocity: q1 = A1 v_X, q2 = A2 v_X, F_R = F_f(v_X).

    Parameters
    ----------
    v_X_m_s : float
        Cylinder velocity (0 gives the standstill with F_R = 0). [m/s]
    params : PlantParams
    condition : ValveCondition, optional
        Default: ``params.nominal_condition``.
    F_l_n : float
        External load. [N]
    p_s_pa, p_r_pa : float, optional
        Supply and return pressure; default the nominal values of ``params.supply``. [Pa]

    Returns
    -------
    RestState
        Raises ``ValueError`` if no spool position in [-x_max, x_max] achieves it.
    """
    row = steady_states([v_X_m_s], params, condition, F_l_n=F_l_n, p_s_pa=p_s_pa,
                        p_r_pa=p_r_pa)[0]
    if not np.all(np.isfinite(row)):
        raise ValueError(f"no steady state within +-x_max for v_X = {v_X_m_s} m/s")
    return RestState(float(row[0]), float(row[1]), float(row[2]), float(v_X_m_s))


def standstill(params: PlantParams = TABLE1, condition: ValveCondition | None = None, *,
               F_l_n: float = 0.0, p_s_pa: float | None = None, p_r_pa: float | None = None,
               F_R_n: float = 0.0) -> RestState:
    """Exact rest state of the model: v_X = 0, q1 = q2 = 0 and F_R = ``F_R_n``.

    Parameters
    ----------
    params : PlantParams
    condition : ValveCondition, optional
        Default: ``params.nominal_condition``.
    F_l_n : float
        External load. [N]
    p_s_pa, p_r_pa : float, optional
        Supply and return pressure; default the nominal values of ``params.supply``. [Pa]
    F_R_n : float
        Remaining resultant force held by static friction, |F_R| <= d_s (0: the centre of the
        sticking band, the state the model settles in when it rests without friction). [N]

    Returns
    -------
    RestState
        Spool position x and pressures p1, p2 (Table 1's healthy valve, p_s = 200 bar,
        p_r = 0: x = -0.036 mm, inside the 0.04 mm underlap, p1 = 33.1 bar, p2 = 145.7 bar).
    """
    cond = params.nominal_condition if condition is None else condition
    p_s, p_r = _pressures(params, p_s_pa, p_r_pa)
    c = params.cylinder
    x, p1, p2, ok = _solve_rest(valve_edge_constants(params.geometry, cond),
                                np.asarray(cond.alpha), p_s, p_r,
                                math.sqrt(2.0 / params.fluid.density_kg_m3), c.A1, c.A2,
                                c.weight_n, float(F_l_n), 0.0, float(F_R_n),
                                -params.geometry.x_max_m, params.geometry.x_max_m)
    if not ok:
        raise ValueError("no standstill within +-x_max for this load and supply pressure")
    return RestState(float(x), float(p1), float(p2), 0.0)

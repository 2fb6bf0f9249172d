"""Cylinder mechanics (Eq. 5) and chamber pressures (Eq. 6) of Steinboeck et al. (2013).

    F_R = m g + A1 p1 - A2 p2 - F_l                       (+ m g: the load hangs from the rod)
    F_f = d_v v_X + (d_c + (d_s - d_c) exp(-v_X^2 / v_0^2)) sign(v_X)      for v_X != 0
    dv_X/dt = (F_R - F_f) / m   if v_X != 0 or |F_R| > d_s
              0                 if v_X = 0 and |F_R| <= d_s                 (sticking)

At breakaway (v_X = 0, |F_R| > d_s) the motion starts in the direction of F_R against the
static friction d_s sign(F_R), the limit of the Stribeck curve for v_X -> 0 from that side,
so dv_X/dt is continuous at |F_R| = d_s.

    V1 = V_01 + A1 X,     V2 = V_02 - A2 X
    dp1/dt = beta / V1 (q1 - A1 v_X),     dp2/dt = beta / V2 (A2 v_X - q2)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import CylinderParams, FluidParams


@njit(cache=True)
def stribeck_kernel(v_X, direction, d_v, d_c, d_s, v0):
    """Eq. 5 Stribeck curve F_f [N] at v_X [m/s] for the motion direction ``direction`` (+1
    or -1): d_v v_X + (d_c + (d_s - d_c) exp(-v_X^2/v_0^2)) direction. With direction =
    sign(v_X) this is Eq. 5; the simulator also uses it with the direction held fixed while
    it locates a zero crossing of v_X (a smooth continuation across v_X = 0)."""
    r2 = (v_X / v0) * (v_X / v0)
    f = d_c
    if r2 < 36.0:  # beyond, (d_s - d_c) exp(-r2) < 1e-12 N: below the rounding of F_R
        f += (d_s - d_c) * math.exp(-r2)
    return d_v * v_X + f * direction


@njit(cache=True)
def friction_force_kernel(v_X, d_v, d_c, d_s, v0):
    """Eq. 5 Stribeck friction F_f [N] for v_X [m/s] != 0 (returns 0 at v_X = 0, where F_f is
    only bounded by |F_f| <= d_s)."""
    if v_X == 0.0:
        return 0.0
    return stribeck_kernel(v_X, 1.0 if v_X > 0.0 else -1.0, d_v, d_c, d_s, v0)


@njit(cache=True)
def friction_mode_kernel(v_X, F_R, d_s):
    """Which branch of Eq. 5b applies: sign(v_X) when moving; at v_X = 0, 0 (sticking) if
    |F_R| <= d_s, else sign(F_R) (breakaway)."""
    if v_X > 0.0:
        return 1.0
    if v_X < 0.0:
        return -1.0
    if F_R > d_s:
        return 1.0
    if F_R < -d_s:
        return -1.0
    return 0.0


@njit(cache=True)
def cylinder_acceleration_mode_kernel(v_X, F_R, mode, m, d_v, d_c, d_s, v0):
    """dv_X/dt [m/s^2] on a given branch of Eq. 5b: mode 0 sticking (0), mode +-1 moving in
    that direction against the Stribeck friction."""
    if mode == 0.0:
        return 0.0
    return (F_R - stribeck_kernel(v_X, mode, d_v, d_c, d_s, v0)) / m


@njit(cache=True)
def cylinder_acceleration_kernel(v_X, F_R, m, d_v, d_c, d_s, v0):
    """Eq. 5b: dv_X/dt [m/s^2] from v_X [m/s] and the resultant force F_R [N]. At breakaway
    (v_X = 0, |F_R| > d_s) the friction is d_s sign(F_R), the Stribeck limit at v_X -> 0."""
    return cylinder_acceleration_mode_kernel(v_X, F_R, friction_mode_kernel(v_X, F_R, d_s),
                                             m, d_v, d_c, d_s, v0)


@njit(cache=True)
def resultant_force_kernel(p1, p2, F_l, weight, A1, A2):
    """Eq. 5: F_R = m g + A1 p1 - A2 p2 - F_l [N] from p1, p2 [Pa], F_l [N], m g [N], A1, A2
    [m^2]."""
    return weight + A1 * p1 - A2 * p2 - F_l


@njit(cache=True)
def chamber_volumes_kernel(X, A1, A2, V01, V02):
    """Eq. 6: (V1, V2) [m^3] = (V_01 + A1 X, V_02 - A2 X) for X [m]."""
    return V01 + A1 * X, V02 - A2 * X


@njit(cache=True)
def pressure_derivatives_kernel(q1, q2, X, v_X, A1, A2, V01, V02, beta):
    """Eq. 6: (dp1/dt, dp2/dt) [Pa/s] from q1, q2 [m^3/s], X [m], v_X [m/s]."""
    V1, V2 = chamber_volumes_kernel(X, A1, A2, V01, V02)
    return beta / V1 * (q1 - A1 * v_X), beta / V2 * (A2 * v_X - q2)


@njit(cache=True)
def _friction_array(v, d_v, d_c, d_s, v0):
    out = np.empty(v.size)
    for i in range(v.size):
        out[i] = friction_force_kernel(v[i], d_v, d_c, d_s, v0)
    return out


@njit(cache=True)
def _accel_array(v, F, m, d_v, d_c, d_s, v0):
    out = np.empty(v.size)
    for i in range(v.size):
        out[i] = cylinder_acceleration_kernel(v[i], F[i], m, d_v, d_c, d_s, v0)
    return out


@njit(cache=True)
def _resultant_array(p1, p2, F_l, weight, A1, A2):
    out = np.empty(p1.size)
    for i in range(p1.size):
        out[i] = resultant_force_kernel(p1[i], p2[i], F_l[i], weight, A1, A2)
    return out


@njit(cache=True)
def _volumes_array(X, A1, A2, V01, V02):
    V1 = np.empty(X.size)
    V2 = np.empty(X.size)
    for i in range(X.size):
        V1[i], V2[i] = chamber_volumes_kernel(X[i], A1, A2, V01, V02)
    return V1, V2


@njit(cache=True)
def _pdot_array(q1, q2, X, v, A1, A2, V01, V02, beta):
    n = q1.size
    d1 = np.empty(n)
    d2 = np.empty(n)
    for i in range(n):
        d1[i], d2[i] = pressure_derivatives_kernel(q1[i], q2[i], X[i], v[i], A1, A2, V01, V02, beta)
    return d1, d2


def _flat(*arrays):
    b = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in arrays))
    return b[0].shape, [np.ascontiguousarray(a).ravel() for a in b]


def _shape(out, shape):
    return out.reshape(shape) if len(shape) else float(out[0])


def friction_force(v_X_m_s, cylinder: CylinderParams = CylinderParams()):
    """Eq. 5: Stribeck friction force F_f for a moving cylinder.

    Parameters
    ----------
    v_X_m_s : array_like
        Cylinder velocity v_X. [m/s]

    Returns
    -------
    ndarray
        F_f, opposing the motion; 0 where v_X = 0 (there |F_f| <= d_s, set by sticking). [N]
    """
    shape, (v,) = _flat(v_X_m_s)
    c = cylinder
    return _shape(_friction_array(v, c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.v0_m_s), shape)


def resultant_force(p1_pa, p2_pa, F_l_n, cylinder: CylinderParams = CylinderParams()):
    """Eq. 5: F_R = m g + A1 p1 - A2 p2 - F_l.

    Parameters
    ----------
    p1_pa, p2_pa : array_like
        Chamber pressures. [Pa]
    F_l_n : array_like
        External load (> 0 opposes extension). [N]

    Returns
    -------
    ndarray
        Resultant force on the piston, > 0 pushes towards extension. [N]
    """
    shape, (p1, p2, F) = _flat(p1_pa, p2_pa, F_l_n)
    c = cylinder
    return _shape(_resultant_array(p1, p2, F, c.weight_n, c.A1, c.A2), shape)


def cylinder_acceleration(v_X_m_s, F_R_n, cylinder: CylinderParams = CylinderParams()):
    """Eq. 5b with sticking: dv_X/dt.

    Parameters
    ----------
    v_X_m_s : array_like
        Cylinder velocity. [m/s]
    F_R_n : array_like
        Resultant force F_R. [N]

    Returns
    -------
    ndarray
        Cylinder acceleration; 0 where v_X = 0 and |F_R| <= d_s. [m/s^2]
    """
    shape, (v, F) = _flat(v_X_m_s, F_R_n)
    c = cylinder
    return _shape(_accel_array(v, F, c.mass_kg, c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.v0_m_s), shape)


def chamber_volumes(X_m, cylinder: CylinderParams = CylinderParams()):
    """Eq. 6: V1 = V_01 + A1 X and V2 = V_02 - A2 X.

    Parameters
    ----------
    X_m : array_like
        Cylinder position. [m]

    Returns
    -------
    (V1, V2)
        Head-side and rod-side fluid volumes. [m^3]
    """
    shape, (X,) = _flat(X_m)
    c = cylinder
    V1, V2 = _volumes_array(X, c.A1, c.A2, c.v01_m3, c.v02_m3)
    return _shape(V1, shape), _shape(V2, shape)


def pressure_derivatives(q1_m3_s, q2_m3_s, X_m, v_X_m_s,
                         cylinder: CylinderParams = CylinderParams(),
                         fluid: FluidParams = FluidParams()):
    """Eq. 6: chamber pressure derivatives.

    Parameters
    ----------
    q1_m3_s : array_like
        Volume flow into chamber 1. [m^3/s]
    q2_m3_s : array_like
        Volume flow out of chamber 2. [m^3/s]
    X_m : array_like
        Cylinder position. [m]
    v_X_m_s : array_like
        Cylinder velocity. [m/s]

    Returns
    -------
    (dp1_dt, dp2_dt)
        [Pa/s]
    """
    shape, (q1, q2, X, v) = _flat(q1_m3_s, q2_m3_s, X_m, v_X_m_s)
    c = cylinder
    d1, d2 = _pdot_array(q1, q2, X, v, c.A1, c.A2, c.v01_m3, c.v02_m3, fluid.bulk_modulus_pa)
    return _shape(d1, shape), _shape(d2, shape)

"""Orifice flows, Eqs. 2 and 4 of Steinboeck et al. (2013).

Eq. 2 (one edge):   q = alpha A sign(dp) sqrt(2 |dp| / rho)

Eq. 4 (ports):      q1 = sqrt(2/rho) [alpha_s1 A_s1 ssqrt(p_s - p1) + alpha_1r A_1r ssqrt(p_r - p1)]
                    q2 = sqrt(2/rho) [alpha_s2 A_s2 ssqrt(p2 - p_s) + alpha_2r A_2r ssqrt(p2 - p_r)]

with ssqrt(dp) = sign(dp) sqrt(|dp|); q1 flows *into* chamber 1, q2 *out of* chamber 2.

Regularisation (numerics only). d ssqrt / d dp is infinite at dp = 0, which makes the
pressure equations arbitrarily stiff when an open edge carries almost no pressure drop. The
simulator therefore may replace ssqrt inside a tiny band |dp| < b by the odd cubic

    ssqrt_b(dp) = sqrt(b) (5 y - y^3) / 4,   y = dp / b,

which matches sqrt(|dp|) in value and slope at |dp| = b (C1), is odd and monotone and has
the finite slope 5 / (4 sqrt b) at 0. Outside the band the law is exact. The simulator uses
b = 0.1 bar (1e4 Pa): only pressure drops below 0.1 bar are affected, and the largest flow
deviation, at |dp| = 0.16 b, is 0.2 sqrt(b) sqrt(2/rho) alpha A -- 2 % of the flow the same
edge carries at 10 bar (for a fully open edge of port 1, 1.6 L/min, i.e. 1.7 mm/s of piston
velocity). The public functions default to b = 0 (the exact law).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .area import _valve_areas_array, valve_edge_constants
from .params import FluidParams, ValveCondition, ValveGeometry


@njit(cache=True)
def signed_sqrt_kernel(dp, band):
    """sign(dp) sqrt(|dp|) [sqrt(Pa)], regularised for |dp| < band [Pa] (band = 0: exact)."""
    if dp >= band:
        return math.sqrt(dp)
    if dp <= -band:
        return -math.sqrt(-dp)
    y = dp / band
    return math.sqrt(band) * (5.0 * y - y * y * y) * 0.25


@njit(cache=True)
def port_flows_kernel(a_s1, a_1r, a_s2, a_2r, al_s1, al_1r, al_s2, al_2r,
                      p1, p2, p_s, p_r, k_rho, band):
    """Eq. 4 for one instant: (q1, q2) [m^3/s] from the edge areas [m^2], contraction
    coefficients [-], pressures [Pa], k_rho = sqrt(2 / rho) and the band [Pa]."""
    q1 = k_rho * (al_s1 * a_s1 * signed_sqrt_kernel(p_s - p1, band)
                  + al_1r * a_1r * signed_sqrt_kernel(p_r - p1, band))
    q2 = k_rho * (al_s2 * a_s2 * signed_sqrt_kernel(p2 - p_s, band)
                  + al_2r * a_2r * signed_sqrt_kernel(p2 - p_r, band))
    return q1, q2


@njit(cache=True)
def _orifice_flow_array(area, dp, alpha, k_rho, band):
    out = np.empty(area.size)
    for i in range(area.size):
        out[i] = alpha[i] * area[i] * k_rho * signed_sqrt_kernel(dp[i], band)
    return out


@njit(cache=True)
def _port_flows_array(areas, alpha, p1, p2, p_s, p_r, k_rho, band):
    n = p1.size
    q1 = np.empty(n)
    q2 = np.empty(n)
    for i in range(n):
        q1[i], q2[i] = port_flows_kernel(areas[0, i], areas[1, i], areas[2, i], areas[3, i],
                                         alpha[0], alpha[1], alpha[2], alpha[3],
                                         p1[i], p2[i], p_s[i], p_r[i], k_rho, band)
    return q1, q2


def orifice_flow(area_m2, dp_pa, alpha, density_kg_m3: float = 870.0, reg_band_pa: float = 0.0):
    """Eq. 2: volume flow through one orifice.

    Parameters
    ----------
    area_m2 : array_like
        Opening area A. [m^2]
    dp_pa : array_like
        Pressure difference across the orifice (flow is positive from high to low). [Pa]
    alpha : array_like
        Contraction coefficient. [-]
    density_kg_m3 : float
        Mass density rho. [kg/m^3]
    reg_band_pa : float
        Regularisation band b (module docstring); 0 = the exact law. [Pa]

    Returns
    -------
    ndarray
        Volume flow q. [m^3/s]
    """
    a, d, al = np.broadcast_arrays(np.asarray(area_m2, float), np.asarray(dp_pa, float),
                                   np.asarray(alpha, float))
    out = _orifice_flow_array(np.ascontiguousarray(a).ravel(), np.ascontiguousarray(d).ravel(),
                              np.ascontiguousarray(al).ravel(),
                              math.sqrt(2.0 / density_kg_m3), float(reg_band_pa))
    return out.reshape(a.shape) if a.ndim else float(out[0])


def port_flows_from_areas(areas_m2, alpha, p1_pa, p2_pa, p_s_pa, p_r_pa,
                          density_kg_m3: float = 870.0, reg_band_pa: float = 0.0):
    """Eq. 4 from given edge areas.

    Parameters
    ----------
    areas_m2 : array_like, shape (4, n)
        A_s1, A_1r, A_s2, A_2r in EDGES order. [m^2]
    alpha : sequence of 4 float
        Contraction coefficients in EDGES order. [-]
    p1_pa, p2_pa, p_s_pa, p_r_pa : array_like, broadcastable to (n,)
        Chamber, supply and return pressures. [Pa]

    Returns
    -------
    (q1, q2) : tuple of ndarray, shape (n,)
        Flow into chamber 1 and flow out of chamber 2. [m^3/s]
    """
    areas = np.ascontiguousarray(np.asarray(areas_m2, dtype=np.float64).reshape(4, -1))
    n = areas.shape[1]
    p1, p2, ps, pr = (np.ascontiguousarray(np.broadcast_to(np.asarray(p, float).ravel()
                                                           if np.ndim(p) else float(p), (n,)))
                      for p in (p1_pa, p2_pa, p_s_pa, p_r_pa))
    return _port_flows_array(areas, np.asarray(alpha, dtype=np.float64), p1, p2, ps, pr,
                             math.sqrt(2.0 / density_kg_m3), float(reg_band_pa))


def port_flows(x_m, p1_pa, p2_pa, p_s_pa, p_r_pa, geometry: ValveGeometry,
               condition: ValveCondition, fluid: FluidParams = FluidParams(),
               reg_band_pa: float = 0.0):
    """Eq. 4: flows at the valve ports for spool displacement(s) ``x_m``.

    Parameters
    ----------
    x_m : array_like, shape (n,)
        Spool displacement x. [m]
    p1_pa, p2_pa : array_like
        Head-side and rod-side chamber pressures. [Pa]
    p_s_pa, p_r_pa : array_like
        Supply and return pressures. [Pa]
    geometry, condition, fluid
        Valve geometry, edge condition (underlaps, per-edge alpha) and fluid.
    reg_band_pa : float
        Regularisation band of sign(dp) sqrt|dp| (module docstring); 0 = exact Eq. 4. [Pa]

    Returns
    -------
    (q1, q2) : tuple of ndarray, shape (n,)
        q1 volume flow into chamber 1, q2 volume flow out of chamber 2. [m^3/s]
    """
    x = np.ascontiguousarray(np.asarray(x_m, dtype=np.float64).ravel())
    areas = _valve_areas_array(x, valve_edge_constants(geometry, condition))
    return port_flows_from_areas(areas, condition.alpha, p1_pa, p2_pa, p_s_pa, p_r_pa,
                                 fluid.density_kg_m3, reg_band_pa)

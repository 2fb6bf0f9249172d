"""Edge laws of the reference plant: opening area A(u) of one control edge in its opening
coordinate u, for four valve families (each edge carries its own law and parameters).

* ``eq3`` (Eq. 3 of the method, written from the equations): with gap = R - r,
  delta = gap tan(phi), s = u + x_u, x_l = -x_u + f delta:
  open (u >= -x_u + delta): h = gap cos(phi) + s sin(phi), A = pi h (2R - h cos(phi));
  transition (x_l <= u < -x_u + delta): A = pi (R + r) sqrt(gap^2 + s^2);
  closed (u < x_l): A = pi (R + r) c^(3/2) / (c + (x_l - u)(x_l + x_u)), c = gap^2 + (x_l + x_u)^2.
* ``sharp``: the conical gap of a sharp edge without radial clearance: h = max(s, 0) sin(phi),
  A = pi h (2R - h cos(phi)); zero when closed.
* ``linear``: A = g max(s, 0), a linear gradient g [m] and a hard corner (issue: the third-party
  valve family, alpha A = C_q f pi d max(u + x_u, 0)).
* ``laminar``: the linear gradient, and an orifice law that leaves Eq. 4's near the corner: the
  discharge coefficient alpha tanh(2 lambda / lambda_t) of the flow number
  lambda = (D_h / nu) sqrt(2 |dp| / rho), D_h = 2 s the slot's hydraulic diameter
  (:func:`laminar_factor`; q ~ s^2 dp where lambda << lambda_t, Eq. 4's beyond).

Each edge is packed into a row of :data:`N_CONST` floats (:func:`edge_rows`) for the numba kernels.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import EDGES, LAWS, OPENING, Fluid, Valve

N_CONST = 11
_LAW, _XU, _ALPHA, _SIN, _COS, _R, _r, _XL, _G, _DELTA, _LAM = range(N_CONST)


def edge_rows(valve: Valve, fluid: Fluid | None = None) -> np.ndarray:
    """(4, N_CONST) constants of the valve's edges in EDGES order (law code, x_u, alpha, sin phi,
    cos phi, R, r, x_l, g, delta, and for the laminar law 2 lambda / lambda_t per m sqrt(Pa):
    4 sqrt(2 / rho) / (nu lambda_t), of ``fluid``, default :class:`Fluid`)."""
    f = fluid or Fluid()
    out = np.zeros((4, N_CONST))
    R, r = valve.bore_radius_m, valve.spool_radius_m
    for i, e in enumerate(valve.edges):
        phi = valve.taper(i)
        delta = (R - r) * math.tan(phi)
        out[i] = (LAWS.index(e.law), e.underlap_m, e.alpha, math.sin(phi), math.cos(phi), R, r,
                  -e.underlap_m + e.x_l_fraction * delta, valve.gradient(i), delta,
                  4.0 * math.sqrt(2.0 / f.density_kg_m3) / (f.kinematic_viscosity_m2_s * e.transition_flow_number))
    return out


@njit(cache=True)
def area_kernel(u, row):
    """Opening area [m^2] of the edge ``row`` at opening coordinate u [m]."""
    law = row[_LAW]
    xu = row[_XU]
    s = u + xu
    if law >= 2.0:  # linear, laminar
        return row[_G] * s if s > 0.0 else 0.0
    R = row[_R]
    if law == 1.0:  # sharp, no clearance
        if s <= 0.0:
            return 0.0
        h = s * row[_SIN]
        return math.pi * h * (2.0 * R - h * row[_COS])
    gap = R - row[_r]
    if u >= -xu + row[_DELTA]:
        h = gap * row[_COS] + s * row[_SIN]
        return math.pi * h * (2.0 * R - h * row[_COS])
    xl = row[_XL]
    if u >= xl:
        return math.pi * (R + row[_r]) * math.sqrt(gap * gap + s * s)
    w = xl + xu
    c = gap * gap + w * w
    return math.pi * (R + row[_r]) * c * math.sqrt(c) / (c + (xl - u) * w)


@njit(cache=True)
def laminar_factor(u, dp, row):
    """The discharge coefficient over alpha of the edge ``row`` at opening coordinate u [m] and
    pressure drop dp [Pa]: tanh(2 lambda / lambda_t) for the laminar law, else 1. [-]"""
    if row[_LAW] != 3.0:
        return 1.0
    s = u + row[_XU]
    if s <= 0.0:
        return 1.0
    return math.tanh(row[_LAM] * s * math.sqrt(abs(dp)))


@njit(cache=True)
def _areas(x, rows, out):
    for k in range(x.size):
        out[0, k] = area_kernel(x[k], rows[0])
        out[1, k] = area_kernel(-x[k], rows[1])
        out[2, k] = area_kernel(-x[k], rows[2])
        out[3, k] = area_kernel(x[k], rows[3])


def edge_area(valve: Valve, edge: str, u_m) -> np.ndarray:
    """Area [m^2] of ``edge`` at opening coordinates ``u_m`` [m] (alpha not included)."""
    i = EDGES.index(edge)
    u = np.atleast_1d(np.asarray(u_m, float)).ravel()
    x = u * OPENING[i]
    out = np.empty((4, u.size))
    _areas(np.ascontiguousarray(x), edge_rows(valve), out)
    return out[i].reshape(np.shape(u_m))


def valve_areas(valve: Valve, x_m) -> np.ndarray:
    """Areas (4, n) [m^2] of all edges, EDGES order, at spool positions ``x_m`` [m]."""
    x = np.ascontiguousarray(np.atleast_1d(np.asarray(x_m, float)).ravel())
    out = np.empty((4, x.size))
    _areas(x, edge_rows(valve), out)
    return out

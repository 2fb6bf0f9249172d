"""Opening area of a control edge, Eq. 3 of Steinboeck et al. (2013), with the signs of
``docs/model.md``.

Every edge is described in its own opening coordinate u (u = +x for s1 and 2r, u = -x for
1r and s2), in which the area is the same increasing function of u for all four edges, with
that edge's underlap x_u and taper angle phi. With delta = (R - r) tan(phi) and s = u + x_u:

    A(u) = A_o = pi h (2R - h cos phi),  h = (R - r) cos phi + s sin phi   if u >= -x_u + delta
           A_t = pi (R + r) sqrt((R - r)^2 + s^2)                          if x_l <= u < -x_u + delta
           A_l = pi (R + r) c^(3/2) / (c + (x_l - u)(x_l + x_u))           if u < x_l
    c = (R - r)^2 + (x_l + x_u)^2,   x_l in (-x_u, -x_u + delta]

Two variants beside Eq. 3 (:class:`model.params.ValveGeometry` ``area_law``, ``leakage_factor``):

* worn lands, ``leakage_factor`` k: A_l = pi (R + r) c^(3/2) / (c + (x_l - u)(x_l + x_u) / k), equal
  to Eq. 3 at u = x_l (continuous) and k times Eq. 3's leakage far from the edge;
* the sharp-edged family (``area_law = "sharp"``): A(u) = 2 pi R sin(phi) (u + x_u) for u >= -x_u,
  0 below -- the slope of Eq. 3's open branch at h = 0, no radial-clearance intercept, no leakage;
* the linear-gradient, hard-corner family (``area_law = "linear"``), the edge of hydraulic system
  simulators' servo-valve components: A(u) = f pi d max(u + x_u, 0) with the area gradient
  f = sin(phi) of the edge's port and the spool diameter d = 2 r -- the sharp-edged law with the
  spool's diameter for the bore's (a gradient 0.1 % smaller on Table 1), likewise without
  radial-clearance intercept or leakage.

The scalar kernel :func:`edge_area_kernel` works on a precomputed constant vector (see
:func:`edge_constants`), so the simulator evaluates the equation without trigonometry; the
array functions below are built on that one kernel.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from .params import AREA_LAWS, EDGES, OPENING_SIGN, ValveCondition, ValveGeometry, edge_index

# Layout of an edge-constant vector (float64[N_EDGE_CONST]).
_XU, _XL, _SIN, _COS, _A0, _DELTA, _TWO_R, _KT, _D2, _C, _C15, _W, _KS = range(13)
N_EDGE_CONST = 13


@njit(cache=True)
def edge_constants_kernel(underlap_m, taper_angle_rad, bore_radius_m, spool_radius_m, x_l_m,
                          sharp=False, leakage_factor=1.0, linear=False):
    """Constants of Eq. 3 (or of the sharp-edged law, ``sharp``, or the linear-gradient law,
    ``linear``) for one edge, as a tuple of N_EDGE_CONST floats (layout private to this module;
    a tuple so that numba passes it by value). ``leakage_factor`` [-] scales the leakage branch
    (module docstring)."""
    gap = bore_radius_m - spool_radius_m
    w = x_l_m + underlap_m
    c = gap * gap + w * w
    ks = 0.0
    if sharp:
        ks = 2.0 * math.pi * bore_radius_m * math.sin(taper_angle_rad)
    elif linear:
        ks = math.pi * 2.0 * spool_radius_m * math.sin(taper_angle_rad)
    return (underlap_m, x_l_m, math.sin(taper_angle_rad), math.cos(taper_angle_rad),
            gap * math.cos(taper_angle_rad), gap * math.tan(taper_angle_rad),
            2.0 * bore_radius_m, math.pi * (bore_radius_m + spool_radius_m), gap * gap, c,
            c * math.sqrt(c), w / leakage_factor, ks)


@njit(cache=True)
def edge_tuple_kernel(row):
    """An edge-constant tuple from a row of :func:`valve_edge_constants`."""
    return (row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7], row[8], row[9],
            row[10], row[11], row[12])


@njit(cache=True)
def edge_area_kernel(u, ec):
    """Eq. 3 (or the sharp-edged or linear-gradient law): opening area [m^2] of one edge at opening coordinate
    ``u`` [m].

    ``ec`` is the edge's constant tuple from :func:`edge_constants_kernel`.
    """
    xu = ec[_XU]
    if ec[_KS] > 0.0:
        s = u + xu
        return ec[_KS] * s if s > 0.0 else 0.0
    if u >= -xu + ec[_DELTA]:
        h = ec[_A0] + (u + xu) * ec[_SIN]
        return math.pi * h * (ec[_TWO_R] - h * ec[_COS])
    if u >= ec[_XL]:
        s = u + xu
        return ec[_KT] * math.sqrt(ec[_D2] + s * s)
    return ec[_KT] * ec[_C15] / (ec[_C] + (ec[_XL] - u) * ec[_W])


@njit(cache=True)
def _edge_area_array(u, ec):
    out = np.empty(u.size)
    for i in range(u.size):
        out[i] = edge_area_kernel(u[i], ec)
    return out


def _default_x_l(underlap_m: float, taper_angle_rad: float, bore_radius_m: float,
                 spool_radius_m: float, fraction: float = 0.5) -> float:
    return -underlap_m + fraction * (bore_radius_m - spool_radius_m) * math.tan(taper_angle_rad)


def edge_constants(underlap_m: float, taper_angle_rad: float, bore_radius_m: float,
                   spool_radius_m: float, x_l_m: float | None = None, area_law: str = "eq3",
                   leakage_factor: float = 1.0) -> tuple:
    """Precomputed constants of Eq. 3 for one edge (the tuple :func:`edge_area_kernel` takes).

    Parameters are those of :func:`edge_area`. Raises ``ValueError`` if x_l is outside
    (-x_u, -x_u + delta], for an unknown ``area_law`` or a ``leakage_factor`` <= 0.
    """
    if area_law not in AREA_LAWS:
        raise ValueError(f"area_law must be one of {AREA_LAWS}, got {area_law!r}")
    if not leakage_factor > 0:
        raise ValueError(f"leakage_factor must be > 0, got {leakage_factor!r}")
    if x_l_m is None:
        x_l_m = _default_x_l(underlap_m, taper_angle_rad, bore_radius_m, spool_radius_m)
    delta = (bore_radius_m - spool_radius_m) * math.tan(taper_angle_rad)
    w = x_l_m + underlap_m
    if not (w > 0.0 and w <= delta * (1 + 1e-12)):
        raise ValueError(
            f"x_l = {x_l_m:.6g} m outside (-x_u, -x_u + delta] = "
            f"({-underlap_m:.6g}, {-underlap_m + delta:.6g}] m (model.md, Eq. 3)")
    return edge_constants_kernel(float(underlap_m), float(taper_angle_rad),
                                 float(bore_radius_m), float(spool_radius_m), float(x_l_m),
                                 area_law == "sharp", float(leakage_factor), area_law == "linear")


def edge_area(u, underlap_m: float, taper_angle_rad: float, bore_radius_m: float,
              spool_radius_m: float, x_l_m: float | None = None, area_law: str = "eq3",
              leakage_factor: float = 1.0):
    """Opening area of one control edge, Eq. 3 (or a variant: module docstring).

    Parameters
    ----------
    u : array_like
        Opening coordinate of the edge (u = +x for s1 and 2r, u = -x for 1r and s2). [m]
    underlap_m : float
        Underlap x_u of the edge (> 0: open at u = 0). [m]
    taper_angle_rad : float
        Taper angle phi of the edge's port. [rad]
    bore_radius_m, spool_radius_m : float
        Bore radius R and spool radius r. [m]
    x_l_m : float, optional
        Onset of the leakage branch, in (-x_u, -x_u + delta]; default -x_u + delta/2. [m]
    area_law : str
        ``"eq3"`` (default), ``"sharp"`` or ``"linear"`` (module docstring). [-]
    leakage_factor : float
        Eq. 3's leakage branch far from the edge times this (continuous at x_l); default 1. [-]

    Returns
    -------
    ndarray or float
        Opening area A(u), same shape as ``u``. [m^2]
    """
    ec = edge_constants(underlap_m, taper_angle_rad, bore_radius_m, spool_radius_m, x_l_m,
                        area_law, leakage_factor)
    ua = np.asarray(u, dtype=np.float64)
    out = _edge_area_array(np.ascontiguousarray(ua).ravel(), ec).reshape(ua.shape)
    return out if out.ndim else float(out)


def opening_coordinate(x, edge: str):
    """Opening coordinate u of ``edge`` for spool displacement ``x`` [m]: u = +x for s1 and
    2r, u = -x for 1r and s2. [m]"""
    edge_index(edge)
    return OPENING_SIGN[edge] * np.asarray(x, dtype=np.float64) if np.ndim(x) else \
        OPENING_SIGN[edge] * float(x)


def valve_edge_constants(geometry: ValveGeometry, condition: ValveCondition) -> np.ndarray:
    """Edge constants of all four edges, shape (4, N_EDGE_CONST), in :data:`EDGES` order, for
    the geometry's ``area_law`` and ``leakage_factor`` (a fresh array each call)."""
    return _valve_edge_constants(geometry, condition).copy()


@functools.lru_cache(maxsize=256)
def _valve_edge_constants(geometry: ValveGeometry, condition: ValveCondition) -> np.ndarray:
    """:func:`valve_edge_constants`, computed once per (geometry, condition): the replays and the
    flows of one model ask for them thousands of times (58 µs each, a hash lookup ~2 µs)."""
    x_l = condition.x_l_m(geometry)
    return np.array([
        edge_constants(condition.underlap_m[i], geometry.taper_angle(e),
                       geometry.bore_radius_m, geometry.spool_radius_m, x_l[i],
                       geometry.area_law, geometry.leakage_factor)
        for i, e in enumerate(EDGES)
    ])


@njit(cache=True)
def _valve_areas_array(x, ecs):
    e0 = edge_tuple_kernel(ecs[0])
    e1 = edge_tuple_kernel(ecs[1])
    e2 = edge_tuple_kernel(ecs[2])
    e3 = edge_tuple_kernel(ecs[3])
    n = x.size
    out = np.empty((4, n))
    for i in range(n):
        out[0, i] = edge_area_kernel(x[i], e0)
        out[1, i] = edge_area_kernel(-x[i], e1)
        out[2, i] = edge_area_kernel(-x[i], e2)
        out[3, i] = edge_area_kernel(x[i], e3)
    return out


def valve_areas(x, geometry: ValveGeometry, condition: ValveCondition) -> np.ndarray:
    """Opening areas of the four edges at spool displacement(s) ``x`` [m], Eq. 3 (or the
    geometry's ``area_law`` and ``leakage_factor``).

    Returns
    -------
    ndarray, shape (4, n)
        A_s1(x), A_1r(x), A_s2(x), A_2r(x) in :data:`EDGES` order. [m^2]
        (n = number of elements of ``x``; a scalar ``x`` gives shape (4, 1).)
    """
    xa = np.ascontiguousarray(np.asarray(x, dtype=np.float64).ravel())
    return _valve_areas_array(xa, valve_edge_constants(geometry, condition))

"""Spool dynamics, Eq. 1 of Steinboeck et al. (2013).

    dx/dt = v
    dv/dt = 0 if a >= 0 and v >= v_max;  0 if a <= 0 and v <= -v_max;  a otherwise
    a = -(2 zeta / T) v - (x - x_ref) / T^2
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .params import SpoolParams


@njit(cache=True)
def spool_acceleration_kernel(x, v, x_ref, T, zeta, v_max):
    """Eq. 1b/1c for one instant: dv/dt [m/s^2] from x [m], v [m/s], x_ref [m], T [s],
    zeta [-] and v_max [m/s]."""
    a = -(2.0 * zeta / T) * v - (x - x_ref) / (T * T)
    if a >= 0.0 and v >= v_max:
        return 0.0
    if a <= 0.0 and v <= -v_max:
        return 0.0
    return a


@njit(cache=True)
def _spool_acceleration_array(x, v, x_ref, T, zeta, v_max):
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = spool_acceleration_kernel(x[i], v[i], x_ref[i], T, zeta, v_max)
    return out


def spool_acceleration(x_m, v_m_s, x_ref_m, spool: SpoolParams = SpoolParams()):
    """Eq. 1: spool acceleration dv/dt with velocity saturation.

    Parameters
    ----------
    x_m : array_like
        Spool displacement x. [m]
    v_m_s : array_like
        Spool velocity v. [m/s]
    x_ref_m : array_like
        Spool reference x_ref. [m]
    spool : SpoolParams
        T, zeta and v_max.

    Returns
    -------
    ndarray
        dv/dt. [m/s^2]
    """
    x, v, r = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(v_m_s, float),
                                  np.asarray(x_ref_m, float))
    out = _spool_acceleration_array(np.ascontiguousarray(x).ravel(), np.ascontiguousarray(v).ravel(),
                                    np.ascontiguousarray(r).ravel(),
                                    spool.T_s, spool.zeta, spool.v_max_m_s)
    return out.reshape(x.shape) if x.ndim else float(out[0])

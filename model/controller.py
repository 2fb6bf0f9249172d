"""Digital PI position controller of the cylinder with saturation, anti-windup and velocity
feed-forward (see :class:`~model.params.ControllerParams` for the gains and their reasons).

At each sample k (period T_0), with e = X_ref - X:

    u[k]     = w_ff x_ff(v_ref[k]) + K_p e[k] + I[k]
    x_ref[k] = min(max(u[k], -x_lim), x_lim)
    I[k+1]   = I[k] + (K_p T_0 / T_i) e[k] + (T_0 / T_t) (x_ref[k] - u[k])

x_ref is held constant until the next sample. The feed-forward x_ff(v) is the steady-state
spool position of the *nominal* valve at cylinder velocity v (nominal supply pressure, no
load), tabulated once per parameter set by :func:`model.standstill.steady_states` and
interpolated linearly; velocities beyond the valve's reach map to +-x_lim.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit

from .params import PlantParams
from .standstill import steady_states


@njit(cache=True)
def pi_step_kernel(error, integral, feedforward, kp, ki_t0, aw_t0, x_lim):
    """One controller sample: returns (x_ref [m], next integral state [m]).

    error [m]; integral [m]; feedforward [m]; kp [m/m]; ki_t0 = K_p T_0 / T_i [m/m];
    aw_t0 = T_0 / T_t [-]; x_lim [m]."""
    u = feedforward + kp * error + integral
    x_ref = u
    if x_ref > x_lim:
        x_ref = x_lim
    elif x_ref < -x_lim:
        x_ref = -x_lim
    return x_ref, integral + ki_t0 * error + aw_t0 * (x_ref - u)


@njit(cache=True)
def interp_kernel(v, grid, values):
    """Linear interpolation on a uniform ``grid`` (clamped at both ends)."""
    n = grid.size
    step = grid[1] - grid[0]
    f = (v - grid[0]) / step
    if f <= 0.0:
        return values[0]
    if f >= n - 1:
        return values[n - 1]
    i = int(f)
    w = f - i
    return values[i] * (1.0 - w) + values[i + 1] * w


@lru_cache(maxsize=16)
def feedforward_table(params: PlantParams, v_step_m_s: float = 0.005,
                      v_abs_max_m_s: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """Feed-forward table of the nominal valve: (v_grid [m/s], x_ff [m]), uniform grid.

    Unreachable velocities give +-x_lim (saturated feed-forward)."""
    n = int(round(v_abs_max_m_s / v_step_m_s))
    grid = np.linspace(-n * v_step_m_s, n * v_step_m_s, 2 * n + 1)
    table = steady_states(grid, params)[:, 0]
    x_lim = params.x_limit_m
    bad = ~np.isfinite(table)
    table[bad & (grid > 0)] = x_lim
    table[bad & (grid < 0)] = -x_lim
    table = np.clip(table, -x_lim, x_lim)
    grid.setflags(write=False)
    table.setflags(write=False)
    return grid, table


def feedforward(v_ref_m_s, params: PlantParams):
    """Feed-forward spool position x_ff for reference velocities ``v_ref_m_s`` [m/s]. [m]"""
    grid, table = feedforward_table(params)
    return np.interp(np.asarray(v_ref_m_s, float), grid, table)


def pi_step(error_m: float, integral_m: float, feedforward_m: float,
            params: PlantParams) -> tuple[float, float]:
    """One sample of the PI controller (module docstring).

    Parameters
    ----------
    error_m : float
        Position error X_ref - X. [m]
    integral_m : float
        Integral state I[k]. [m]
    feedforward_m : float
        Already weighted feed-forward w_ff x_ff. [m]

    Returns
    -------
    (x_ref_m, next_integral_m)
    """
    c = params.controller
    return pi_step_kernel(float(error_m), float(integral_m), float(feedforward_m),
                          c.kp_m_per_m, c.kp_m_per_m * c.sample_time_s / c.ti_s,
                          c.sample_time_s / c.tt_s, params.x_limit_m)

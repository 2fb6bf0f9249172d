"""Replay of the plant on recorded inputs: the simulator of :mod:`model.simulate` driven by a
recorded spool position instead of the spool model and the position controller.

Inputs per sample: the spool position x (the true one: recorded minus a known sensor offset),
the supply and return pressures and the external load F_l (estimated by the caller). Between
samples x and p_s are interpolated linearly (the spool state of the kernel moves at the constant
slope of the sample interval, dv/dt = 0), p_r and F_l are held. The state (X, v_X, p1, p2) is
integrated with the simulator's RK4 and its located stick/slip events (same numerics, same
``substeps`` and regularisation band), with any library effect of :mod:`model.effects`.

A replay may restart from given states at chosen samples (multiple shooting): the caller passes
``restart`` indices and their states, so a long record is replayed in segments that each start
from the measured state, and a position drift from a small flow error does not accumulate over
a whole window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .area import valve_edge_constants
from .effects import Effects
from .params import PlantParams, ValveCondition
from .simulate import (_AIR, _BETA, _DS, _KE, _KI, _RS, DEFAULT_REG_BAND_PA, DEFAULT_SUBSTEPS, P_LIMIT_FACTOR, _event_step,
                       _F_R, _mode_of, _rk4, _valve_tuples, pack_params, params_tuple,
                       rhs_mode_kernel)


DRIVE_FULL, DRIVE_HYDRAULIC, DRIVE_MECHANICAL = 0, 1, 2
"""What the replay takes from the record besides the valve's inputs (:func:`replay`'s ``drive``)."""


@njit(cache=True)
def _replay_kernel(x, ps, pr, F_l, restart_at, restart_state, ecs_row, alpha_row, P, fs, n_sub,
                   p_limit, drive, given, out):
    """Integrate one record; ``out`` (4, n) receives X, v_X, p1, p2 from sample
    ``restart_at[0]`` on (NaN before). ``drive`` 1: X follows ``given[0]`` (linear between
    samples, v_X its slope; no friction branch, only the chamber equations evolve); 2: (p1, p2) follow
    ``given[0:2]`` (the caller zeroes the bulk modulus, so they do not evolve inside a step).
    Returns the first sample index where the state diverged, or -1."""
    n = x.shape[0]
    P = params_tuple(P)
    ecs, alpha = _valve_tuples(ecs_row, alpha_row)
    T0 = 1.0 / fs
    h = T0 / n_sub
    d_s = P[_DS]
    for i in range(4):
        for k in range(n):
            out[i, k] = np.nan
    r = 0
    n_r = restart_at.shape[0]
    s = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for k in range(restart_at[0], n):
        if r < n_r and k == restart_at[r]:
            s = (x[k], 0.0, restart_state[r, 0], restart_state[r, 1], restart_state[r, 2],
                 restart_state[r, 3])
            r += 1
        if drive == 1:
            s = (s[0], s[1], given[0, k], s[3], s[4], s[5])
        elif drive == 2:
            s = (s[0], s[1], s[2], s[3], given[0, k], given[1, k])
        out[0, k] = s[2]
        out[1, k] = s[3]
        out[2, k] = s[4]
        out[3, k] = s[5]
        if k == n - 1:
            break
        if not (abs(s[4]) < p_limit and abs(s[5]) < p_limit and abs(s[3]) < 1.0e3):
            return k
        t = k * T0
        slope_x = (x[k + 1] - x[k]) / T0
        slope_ps = (ps[k + 1] - ps[k]) / T0
        sup = (ps[k] - slope_ps * t, slope_ps, 0.0, 0.0, 0.0, pr[k])
        fl = F_l[k]
        p_r = pr[k]
        # the spool follows its recorded path: position at the sample, slope of the interval
        s = (x[k], slope_x, s[2], s[3], s[4], s[5])
        for j in range(n_sub):
            tj = t + j * h
            ps_t = ps[k] + slope_ps * (j * h)
            ps_h = ps_t + slope_ps * 0.5 * h
            ps_1 = ps_t + slope_ps * h
            if drive != 0:
                # X at the substep's start; the (held) pressures at its midpoint
                f = j / n_sub if drive == 1 else (j + 0.5) / n_sub
                g0 = given[0, k] + f * (given[0, k + 1] - given[0, k])
                g1 = given[1, k] + f * (given[1, k + 1] - given[1, k])
                if drive == 1:
                    # the cylinder moves at the slope of its recorded position over the interval,
                    # so the chamber volumes at the samples are exactly the recorded ones
                    s = (s[0], s[1], g0, (given[0, k + 1] - given[0, k]) / T0, s[4], s[5])
                    k1 = rhs_mode_kernel(s[0], s[1], s[2], s[3], s[4], s[5], 0.0, 0.0, fl, ps_t,
                                         p_r, ecs, alpha, P)
                    s = _rk4(s, 0.0, k1, 0.0, fl, ps_t, ps_h, ps_1, p_r, ecs, alpha, P, h)
                    continue
                s = (s[0], s[1], s[2], s[3], g0, g1)
            mode = _mode_of(s, fl, P)
            k1 = rhs_mode_kernel(s[0], s[1], s[2], s[3], s[4], s[5], mode, 0.0, fl, ps_t, p_r,
                                 ecs, alpha, P)
            new = _rk4(s, mode, k1, 0.0, fl, ps_t, ps_h, ps_1, p_r, ecs, alpha, P, h)
            if mode != 0.0:
                ok = new[3] * mode > 0.0
            else:
                ok = abs(_F_R(new, fl, P)) <= d_s
            if ok:
                s = new
            else:
                s = _event_step(s, tj, h, 0.0, fl, sup, ecs, alpha, P)
    return -1


@dataclass(frozen=True)
class ReplayResult:
    """True states of a replay at the sample instants (NaN before the first start).

    Attributes
    ----------
    X_m : Cylinder position. [m]
    vX_m_s : Cylinder velocity. [m/s]
    p1_pa, p2_pa : Chamber pressures (true, not as recorded). [Pa]
    """

    X_m: np.ndarray
    vX_m_s: np.ndarray
    p1_pa: np.ndarray
    p2_pa: np.ndarray


def replay(params: PlantParams, x_m, p_s_pa, p_r_pa, F_l_n, restart_at, restart_states,
           *, condition: ValveCondition | None = None, effects: Effects | None = None,
           substeps: int = DEFAULT_SUBSTEPS,
           reg_band_pa: float = DEFAULT_REG_BAND_PA, drive: int = DRIVE_FULL,
           given=None) -> ReplayResult:
    """Replay the plant on one record of inputs (module docstring).

    Parameters
    ----------
    params : PlantParams
        Plant (its sample rate is the record's).
    x_m : array_like, shape (n,)
        True spool position at the samples. [m]
    p_s_pa, p_r_pa : array_like, shape (n,)
        Supply and return pressure (the supply as measured upstream of a supply line). [Pa]
    F_l_n : array_like, shape (n,)
        External load, held over each sample interval: ``F_l_n[k]`` acts on [t_k, t_k+1) (for a
        load that ramps, pass the interval's mean, not its value at t_k). [N]
    restart_at : sequence of int
        Sample indices, increasing, where the state is set to ``restart_states``; the replay
        starts at the first.
    restart_states : array_like, shape (len(restart_at), 4)
        (X [m], v_X [m/s], p1 [Pa], p2 [Pa]) true states at those samples (v_X = 0 lets the
        cylinder start stuck, Eq. 5b).
    condition : ValveCondition, optional
        Valve condition; default ``params.nominal_condition``.
    effects : Effects, optional
        Library effects; the sensor effects do not enter here (the caller maps recorded to true
        signals and back, :func:`model.effects.true_signals`, :func:`~model.effects.sensor_readings`).
    substeps, reg_band_pa
        As in :func:`model.simulate.simulate_inputs`.
    drive : int
        ``DRIVE_FULL`` (default): the whole state is integrated. ``DRIVE_HYDRAULIC``: the
        cylinder's position follows ``given`` = X [m] per sample (linear between samples, so it
        moves at the slope of the interval and the chamber volumes at the samples are the
        recorded ones) and only the chamber equations (Eq. 6) are integrated: p1, p2 need no
        load, mass or friction (the velocity returned is that slope). ``DRIVE_MECHANICAL``: the chamber pressures follow ``given`` = (p1, p2) [Pa]
        (true) per sample and only the motion (Eq. 5, with sticking) is integrated: X needs no
        flow model.
    given : array_like, shape (n,) or (2, n), optional
        The recorded signals of the driven replays (X, resp. (p1, p2)).

    Returns
    -------
    ReplayResult
    """
    cond = params.nominal_condition if condition is None else condition
    # writable copies, whatever the callers hold (read-only views of polars, broadcasts): the
    # kernel is compiled for one kind of array, not for each mix
    x = np.array(x_m, dtype=float)
    n = x.size
    ps, pr, fl = (np.array(np.broadcast_to(np.asarray(a, float), (n,))) for a in (p_s_pa, p_r_pa, F_l_n))
    at = np.ascontiguousarray(np.asarray(restart_at, dtype=np.int64))
    st = np.ascontiguousarray(np.asarray(restart_states, dtype=float).reshape(-1, 4))
    if at.size == 0 or at.size != st.shape[0]:
        raise ValueError("need one restart state per restart index, at least one")
    if np.any(np.diff(at) <= 0) or at[0] < 0 or at[-1] >= n:
        raise ValueError("restart indices must increase and lie inside the record")
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    for a in (x, ps, pr, fl):
        if not np.all(np.isfinite(a)):
            raise ValueError("replay inputs must be finite")
    P = pack_params(params, reg_band_pa, effects, prescribed_spool=True)
    if drive == DRIVE_FULL:
        g = np.zeros((2, n))
    else:
        g = np.ascontiguousarray(np.asarray(given, float).reshape(-1, n))
        if g.shape[0] != (1 if drive == DRIVE_HYDRAULIC else 2):
            raise ValueError("given: X for the hydraulic replay, (p1, p2) for the mechanical one")
        g = np.ascontiguousarray(np.vstack([g, np.zeros((2 - g.shape[0], n))]))
        if not np.all(np.isfinite(g)):
            raise ValueError("the driving signals must be finite")
    if drive == DRIVE_MECHANICAL:
        P[[_BETA, _KI, _KE, _AIR, _RS]] = 0.0  # the pressures are given: no chamber dynamics
    p_limit = P_LIMIT_FACTOR * float(np.max(np.abs(ps)))
    args = (x, ps, pr, fl, at, st, valve_edge_constants(params.geometry, cond), np.asarray(cond.alpha, float), P,
            params.sensors.sample_rate_hz, int(substeps), p_limit, int(drive), g)
    out = _LAST.continued(args)
    if out is None:
        out = np.empty((4, n))
        bad = _replay_kernel(*args, out)
        _LAST.keep(args, out, bad)
    else:
        bad = -1
    if bad >= 0:
        raise FloatingPointError(f"replay diverged at sample {bad}")
    return ReplayResult(X_m=out[0], vX_m_s=out[1], p1_pa=out[2], p2_pa=out[3])


class _LastReplay:
    """The last replay the kernel integrated, to continue from: a replay that restarts at one
    sample k with the state the last one passed through there exactly, on the same inputs from k
    on (the same plant, valve, spool path, pressures, load from k, drive), is that replay from k
    (the kernel's state at a sample is (X, v_X, p1, p2), nothing before k enters it), so its
    states are copied instead of integrated: the same numbers. Placing a load step across a
    standstill by replay (``transforms.discrepancy.rows``) replays each candidate from its own
    sample on a common prefix; while the replayed cylinder sticks under both loads, the next
    candidates' replays are the last one's. One replay is kept (its inputs and states: memory
    bounded by one record); a replay that diverged is not kept."""

    def __init__(self):
        self.last = None

    def keep(self, args, out, bad: int) -> None:
        """Keep a copy of the kernel's inputs and states (one replay at a time; none if it diverged)."""
        self.last = None if bad >= 0 else (tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args), out.copy())

    def continued(self, args) -> np.ndarray | None:
        """The states (4, n) of a replay with ``args`` (the kernel's, without ``out``) copied from
        the last one, or None where it is not that replay's continuation."""
        if self.last is None:
            return None
        last, states = self.last
        if args[4].size != 1 or args[0].size != last[0].size:
            return None
        k = int(args[4][0])
        if int(last[4][-1]) > k or states[:, k].tobytes() != args[5][0].tobytes():  # bit for bit (0.0 is not -0.0)
            return None
        if any(a != b for a, b in zip(args[9:13], last[9:13])):
            return None
        for i in (0, 1, 2, 6, 7, 8, 13):
            if not np.array_equal(args[i], last[i]):
                return None
        if not np.array_equal(args[3][k:], last[3][k:]):
            return None
        out = np.full_like(states, np.nan)
        out[:, k:] = states[:, k:]
        return out


_LAST = _LastReplay()

"""Operating inputs of one window: reference trajectory of the cylinder, the unknown load
F_l and the supply/return pressures. All deterministic for a given ``numpy.random.Generator``.

Reference trajectory: dwells and smooth moves alternating in direction between random
targets (see :class:`~model.params.TrajectoryParams`). The default move profile is a
cruise at v_peak between raised-cosine velocity ramps of duration T_a,

    v(tau) = v_peak (1 - cos(pi tau / T_a)) / 2        (0 <= tau <= T_a, mirrored at the end)

so position, velocity and acceleration are continuous (peak acceleration pi v_peak / (2 T_a))
and the spool spends most of a move at its cruise opening. A move too short for a cruise
lowers v_peak to |d| / T_a. The alternative ``"minimum_jerk"`` profile is
X = X_a + d (10 s^3 - 15 s^4 + 6 s^5), s = (t - t_a) / T_m, T_m = 1.875 |d| / v_peak.

Supply pressure: p_s(t) = p_s0 + drift t + A sin(2 pi f t + phase) (see
:class:`~model.params.SupplyParams`); return pressure constant per window.

Recordings longer than a window are simulated as consecutive segments
(:func:`segment_inputs`): the reference (:class:`ReferenceStream`), the load and the supply
level carry over from one segment to the next, and each segment draws what is new in it
(moves, load changes, the supply's drift) from its own generator. A window is a recording of
one segment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .params import LoadParams, PlantParams, SupplyParams, TrajectoryParams


@njit(cache=True)
def supply_pressure_kernel(t, p_s0, drift, amplitude, omega, phase):
    """p_s(t) [Pa] = p_s0 + drift t + amplitude sin(omega t + phase)."""
    return p_s0 + drift * t + amplitude * math.sin(omega * t + phase)


@dataclass(frozen=True)
class SupplyProfile:
    """Supply and return pressure of one window.

    Attributes
    ----------
    p_s0_pa : float
        Supply level at t = 0 of the window (without ripple). [Pa]
    drift_pa_s : float
        Slow linear drift. [Pa/s]
    ripple_amplitude_pa : float
        Pump ripple amplitude. [Pa]
    ripple_frequency_hz : float
        Pump ripple frequency. [Hz]
    ripple_phase_rad : float
        Ripple phase at t = 0. [rad]
    p_r_pa : float
        Return pressure. [Pa]
    """

    p_s0_pa: float
    drift_pa_s: float
    ripple_amplitude_pa: float
    ripple_frequency_hz: float
    ripple_phase_rad: float
    p_r_pa: float

    def as_array(self) -> np.ndarray:
        """[p_s0, drift, amplitude, omega, phase, p_r] for the kernels."""
        return np.array([self.p_s0_pa, self.drift_pa_s, self.ripple_amplitude_pa,
                         2.0 * math.pi * self.ripple_frequency_hz, self.ripple_phase_rad,
                         self.p_r_pa])

    def p_s(self, t_s):
        """Supply pressure at window times ``t_s`` [s]. [Pa]"""
        a = self.as_array()
        t = np.asarray(t_s, float)
        return a[0] + a[1] * t + a[2] * np.sin(a[3] * t + a[4])


def draw_supply(rng: np.random.Generator, supply: SupplyParams) -> SupplyProfile:
    """A window's supply profile drawn from ``supply`` (see :class:`SupplyParams`)."""
    return SupplyProfile(
        p_s0_pa=supply.p_s_nominal_pa + rng.uniform(-1, 1) * supply.p_s_window_spread_pa,
        drift_pa_s=rng.uniform(-1, 1) * supply.p_s_drift_max_pa_s,
        ripple_amplitude_pa=supply.ripple_amplitude_pa,
        ripple_frequency_hz=supply.ripple_frequency_hz,
        ripple_phase_rad=rng.uniform(0.0, 2.0 * math.pi),
        p_r_pa=supply.p_r_nominal_pa + rng.uniform(-1, 1) * supply.p_r_window_spread_pa,
    )


def minimum_jerk(t, t0: float, duration: float, x_a: float, x_b: float):
    """Minimum-jerk move from x_a at t0 to x_b at t0 + duration: (position, velocity) at
    times ``t`` [s] (constant outside the move). [m], [m/s]"""
    s = np.clip((np.asarray(t, float) - t0) / duration, 0.0, 1.0)
    d = x_b - x_a
    pos = x_a + d * (10 * s**3 - 15 * s**4 + 6 * s**5)
    vel = d / duration * (30 * s**2 - 60 * s**3 + 30 * s**4)
    return pos, vel


def cosine_move(t, t0: float, x_a: float, x_b: float, v_peak: float, t_ramp: float):
    """Move from x_a to x_b starting at t0: raised-cosine velocity ramps of ``t_ramp`` [s]
    around a cruise at ``v_peak`` [m/s] (lowered to |d| / t_ramp for short moves).

    Returns
    -------
    (position, velocity, duration)
        At times ``t`` (constant outside the move) [m], [m/s], and the move's length [s].
    """
    d = x_b - x_a
    dist = abs(d)
    sgn = 1.0 if d >= 0 else -1.0
    vp = min(v_peak, dist / t_ramp)
    t_c = dist / vp - t_ramp if vp > 0 else 0.0
    total = 2 * t_ramp + t_c
    tau = np.clip(np.asarray(t, float) - t0, 0.0, total)
    ramp_d = 0.5 * vp * t_ramp
    w = np.pi / t_ramp
    up = tau < t_ramp
    down = tau > t_ramp + t_c
    pos = np.where(up, 0.5 * vp * (tau - np.sin(w * tau) / w), ramp_d + vp * (tau - t_ramp))
    vel = np.where(up, 0.5 * vp * (1 - np.cos(w * tau)), vp)
    td = np.clip(total - tau, 0.0, None)
    pos = np.where(down, dist - 0.5 * vp * (td - np.sin(w * td) / w), pos)
    vel = np.where(down, 0.5 * vp * (1 - np.cos(w * td)), vel)
    vel = np.where(tau >= total, 0.0, vel)
    return x_a + sgn * pos, sgn * vel, total


class ReferenceStream:
    """The reference trajectory of a recording, drawn block by block as it is needed.

    Consecutive :meth:`take` calls return consecutive blocks of samples of one continuous
    reference: a move still running at the end of a block goes on in the next, so position
    and velocity are continuous across blocks. Moves are drawn when they start, from the
    generator of the block they start in. Times are kept relative to the next block's first
    sample, so the stream runs for days without losing resolution; only the move in progress
    is held.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the start position, the opening dwell and the first direction.
    sample_rate_hz : float
        [Hz]
    traj : TrajectoryParams
    X0_m : float, optional
        Start position; default uniform in [X_low, X_high]. [m]
    """

    def __init__(self, rng: np.random.Generator, sample_rate_hz: float,
                 traj: TrajectoryParams = TrajectoryParams(), X0_m: float | None = None):
        self.fs = float(sample_rate_hz)
        self.traj = traj
        self.X = float(rng.uniform(traj.X_low_m, traj.X_high_m)) if X0_m is None else float(X0_m)
        """Target of the last move drawn (the start position before the first). [m]"""
        self.t_next = float(rng.uniform(*traj.first_dwell_s))
        """When the next move starts, from the next block's first sample. [s]"""
        self.direction = 1.0 if rng.uniform() < 0.5 else -1.0
        self.running: tuple | None = None
        """The move that runs past the end of the last block: (start [s], from, to, v_peak,
        ramp or duration [s], duration [s])."""

    def _draw_move(self, rng: np.random.Generator) -> tuple:
        traj = self.traj
        room_up = traj.X_high_m - self.X
        room_down = self.X - traj.X_low_m
        if self.direction > 0 and room_up < traj.min_travel_m:
            self.direction = -1.0
        elif self.direction < 0 and room_down < traj.min_travel_m:
            self.direction = 1.0
        room = room_up if self.direction > 0 else room_down
        dist = float(rng.uniform(min(traj.min_travel_m, room), room))
        v_rng = traj.v_extend_m_s if self.direction > 0 else traj.v_retract_m_s
        v_peak = float(rng.uniform(*v_rng))
        target = self.X + self.direction * dist
        if traj.profile == "cosine":
            shape = float(rng.uniform(*traj.ramp_s))
            T_m = cosine_move(0.0, 0.0, self.X, target, v_peak, shape)[2]
        elif traj.profile == "minimum_jerk":
            T_m = shape = 1.875 * dist / v_peak
        else:
            raise ValueError(f"unknown move profile {traj.profile!r}")
        return (self.t_next, self.X, target, v_peak, shape, T_m)

    def _write(self, move: tuple, t: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> bool:
        """Write ``move`` into the block; True if it runs past the block's end."""
        n = t.size
        t0, x_a, x_b, v_peak, shape, T_m = move
        k0 = max(0, int(math.ceil(t0 * self.fs - 1e-9)))
        k1_end = int(math.ceil((t0 + T_m) * self.fs)) + 1
        k1 = min(n, k1_end)
        if self.traj.profile == "cosine":
            p, v, _ = cosine_move(t[k0:k1], t0, x_a, x_b, v_peak, shape)
        else:
            p, v = minimum_jerk(t[k0:k1], t0, shape, x_a, x_b)
        pos[k0:k1] = p
        vel[k0:k1] = v
        pos[k1:] = x_b
        vel[k1:] = 0.0
        return k1_end > n

    def take(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The next ``n`` samples (X_ref [m], v_ref [m/s]); moves starting in them are drawn
        from ``rng``."""
        duration = n / self.fs
        t = np.arange(n) / self.fs
        pos = np.full(n, self.X if self.running is None else self.running[1])
        vel = np.zeros(n)
        running = None
        if self.running is not None and self._write(self.running, t, pos, vel):
            running = self.running
        while self.t_next < duration:
            move = self._draw_move(rng)
            if self._write(move, t, pos, vel):
                running = move
            self.X = move[2]
            self.t_next += move[5] + float(rng.uniform(*self.traj.dwell_s))
            self.direction = -self.direction
        self.t_next -= duration
        self.running = None if running is None else (running[0] - duration, *running[1:])
        return pos, vel


def reference_trajectory(rng: np.random.Generator, duration_s: float, sample_rate_hz: float,
                         traj: TrajectoryParams = TrajectoryParams(),
                         X0_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Reference position and velocity of the cylinder at the sample instants k / f_s.

    Parameters
    ----------
    rng : numpy.random.Generator
    duration_s : float
        Window length. [s]
    sample_rate_hz : float
        Sample rate. [Hz]
    traj : TrajectoryParams
    X0_m : float, optional
        Start position; default uniform in [X_low, X_high]. [m]

    Returns
    -------
    (X_ref, v_ref) : ndarray, shape (n,)
        n = round(duration * f_s). [m], [m/s]. The window starts with a dwell (v_ref = 0).
    """
    n = int(round(duration_s * sample_rate_hz))
    return ReferenceStream(rng, sample_rate_hz, traj, X0_m).take(n, rng)


def load_profile(rng: np.random.Generator, duration_s: float, sample_rate_hz: float,
                 load: LoadParams = LoadParams(), start_level_n: float | None = None) -> np.ndarray:
    """Piecewise-constant unknown external load F_l at the sample instants.

    Changes arrive as a Poisson process of rate ``load.rate_per_s``; each level is 0 with
    probability ``load.p_zero``, else uniform in +-``load.level_max_n``.

    Returns
    -------
    ndarray, shape (n,)
        F_l (> 0 opposes extension). [N]
    """
    n = int(round(duration_s * sample_rate_hz))

    def level():
        return 0.0 if rng.uniform() < load.p_zero else float(rng.uniform(-1, 1) * load.level_max_n)

    out = np.empty(n)
    current = level() if start_level_n is None else float(start_level_n)
    k0 = 0
    t_next = float(rng.exponential(1.0 / load.rate_per_s)) if load.rate_per_s > 0 else math.inf
    while k0 < n:
        k1 = min(n, int(math.ceil(t_next * sample_rate_hz)))
        out[k0:k1] = current
        k0 = k1
        current = level()
        t_next += float(rng.exponential(1.0 / load.rate_per_s))
    return out


@dataclass(frozen=True)
class WindowInputs:
    """Exogenous inputs of one simulated window, at the sample instants.

    Attributes
    ----------
    X_ref_m : ndarray, shape (n,)
        Reference cylinder position. [m]
    v_ref_m_s : ndarray, shape (n,)
        Reference cylinder velocity (feed-forward). [m/s]
    F_l_n : ndarray, shape (n,)
        External load, held between samples. [N]
    supply : SupplyProfile
        Supply and return pressure.
    """

    X_ref_m: np.ndarray
    v_ref_m_s: np.ndarray
    F_l_n: np.ndarray
    supply: SupplyProfile


@dataclass(frozen=True)
class RecordingState:
    """Where a recording's operating inputs stand after a segment, so that the next segment
    continues them without a jump (:func:`segment_inputs`).

    Attributes
    ----------
    reference : ReferenceStream
        The reference trajectory, with the move in progress.
    load_n : float
        The load at the last sample. [N]
    p_s_pa : float
        Supply level (without ripple) at the end of the segment. [Pa]
    ripple_phase_rad : float
        Ripple phase at the end of the segment. [rad]
    p_r_pa : float
        Return pressure. [Pa]
    """

    reference: ReferenceStream
    load_n: float
    p_s_pa: float
    ripple_phase_rad: float
    p_r_pa: float


def next_supply(rng: np.random.Generator, supply: SupplyParams, state: RecordingState,
                duration_s: float) -> SupplyProfile:
    """The supply profile of a segment that continues ``state``: it starts at the level and
    ripple phase where the last one ended and drifts at a rate drawn uniformly in
    +-drift_max, limited so that the level stays within p_s_nominal +- p_s_window_spread
    (a bounded random walk: over hours the level wanders through Table 1's range)."""
    p0 = state.p_s_pa
    lo = supply.p_s_nominal_pa - supply.p_s_window_spread_pa
    hi = supply.p_s_nominal_pa + supply.p_s_window_spread_pa
    d_max = supply.p_s_drift_max_pa_s
    drift = float(rng.uniform(-1, 1)) * d_max
    drift = min(max(drift, (lo - p0) / duration_s), (hi - p0) / duration_s)
    drift = min(max(drift, -d_max), d_max)
    return SupplyProfile(p0, drift, supply.ripple_amplitude_pa, supply.ripple_frequency_hz,
                         state.ripple_phase_rad, state.p_r_pa)


def segment_inputs(params: PlantParams, n_samples: int, rng: np.random.Generator,
                   state: RecordingState | None = None) -> tuple[WindowInputs, RecordingState]:
    """The inputs of one segment of a recording, and where they stand at its end.

    The first segment (``state`` None) draws its supply profile, the reference's start and
    moves and its load from ``rng`` (:func:`window_inputs`); a later one continues ``state``:
    the reference goes on (a move in progress completes), the load holds its level until its
    next change (a Poisson process: the time to the next change is drawn afresh, which does
    not change its law), the supply level and ripple phase go on (:func:`next_supply`). New
    moves, load changes and the supply's drift are drawn from the segment's ``rng``, in that
    order: supply, moves, load.
    """
    fs = params.sensors.sample_rate_hz
    duration = n_samples / fs
    if state is None:
        supply = draw_supply(rng, params.supply)
        reference = ReferenceStream(rng, fs, params.trajectory)
        start_load = None
    else:
        supply = next_supply(rng, params.supply, state, duration)
        reference = state.reference
        start_load = state.load_n
    X_ref, v_ref = reference.take(n_samples, rng)
    F_l = load_profile(rng, duration, fs, params.load, start_level_n=start_load)
    a = supply.as_array()
    end = RecordingState(reference, float(F_l[-1]), float(a[0] + a[1] * duration),
                         float((a[4] + a[3] * duration) % (2.0 * math.pi)), supply.p_r_pa)
    return WindowInputs(X_ref, v_ref, F_l, supply), end


def window_inputs(params: PlantParams, duration_s: float, rng: np.random.Generator) -> WindowInputs:
    """Draw all inputs of a window (trajectory, load, supply) from ``rng``."""
    n = int(round(duration_s * params.sensors.sample_rate_hz))
    return segment_inputs(params, n, rng)[0]

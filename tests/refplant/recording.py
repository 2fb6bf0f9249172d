"""One run of the reference plant: :func:`simulate` and what it returns, :class:`RefRecording`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .params import EDGES, RefPlant
from .plant import Inputs, controller_output, integrate, port_flows, rest_state
from .scenarios import Effects, Load, Trajectory, draw_load, draw_trajectory
from .sensors import first_order_lag, record, skewed

#: The pressure channels in the order of ``Sensors.lag_s``.
PRESSURES = ("ps", "pr", "p1", "p2")


@dataclass(frozen=True)
class RefRecording:
    """A run of the reference plant at the acquisition rate, SI units.

    Recorded (what a historian holds; arrays shaped (n,)): ``ps``, ``pr``, ``p1``, ``p2`` [Pa],
    ``x_spool``, ``x_cyl``, ``x_ref`` [m]. Truth: ``true`` (dict of arrays: ``x``, ``v``, ``X``,
    ``vX``, ``p1``, ``p2``, ``ps``, ``ps_valve``, ``q1``, ``q2``, ``F_l``, ``X_ref``, ``v_ref``,
    ``x_ref``), the ``plant`` (true edges, beta, ...), ``effects``, ``trajectory``, ``load``, and
    the cost: ``cpu_s`` (process time of the integration), ``nfev`` (rhs evaluations).
    """

    t_s: np.ndarray
    ps: np.ndarray
    pr: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    x_spool: np.ndarray
    x_cyl: np.ndarray
    x_ref: np.ndarray
    true: dict
    plant: RefPlant
    effects: Effects
    trajectory: Trajectory
    load: Load
    seed: int
    cpu_s: float
    nfev: int

    @property
    def sample_rate_hz(self) -> float:
        return self.plant.sensors.sample_rate_hz

    @property
    def n_samples(self) -> int:
        return self.t_s.size

    def edge_truth(self) -> list[dict]:
        """The true edges, one dict per edge: edge, law, alpha, underlap_m, gradient_m (linear and laminar laws)."""
        v = self.plant.valve
        return [{"edge": e, "law": ed.law, "alpha": ed.alpha, "underlap_m": ed.underlap_m,
                 "gradient_m": v.gradient(i) if ed.law in ("linear", "laminar") else math.nan}
                for i, (e, ed) in enumerate(zip(EDGES, v.edges))]


def draw_supply(plant: RefPlant, rng: np.random.Generator) -> tuple:
    """(p_s0, drift, ripple, f, phase, p_r) of a window."""
    s = plant.supply
    return (s.p_s_pa + rng.uniform(-1, 1) * s.p_s_spread_pa, rng.uniform(-1, 1) * s.drift_max_pa_s,
            s.ripple_pa, s.ripple_hz, rng.uniform(0, 2 * math.pi), s.p_r_pa)


def draw_window(plant: RefPlant, duration_s: float, seed: int, *, load: Load | None = None,
                trajectory: Trajectory | None = None, supply: tuple | None = None) -> tuple[Trajectory, Load, tuple]:
    """(trajectory, load, supply) of a window: those not given drawn from ``seed``'s streams 1, 2
    and 3 (the noise draws from stream 4)."""
    trajectory = draw_trajectory(plant.operation, duration_s, np.random.default_rng([seed, 1])) if trajectory is None else trajectory
    load = draw_load(plant.operation, duration_s, np.random.default_rng([seed, 2])) if load is None else load
    supply = draw_supply(plant, np.random.default_rng([seed, 3])) if supply is None else supply
    return trajectory, load, supply


def simulate(plant: RefPlant, duration_s: float, seed: int, *, effects: Effects | None = None,
             load: Load | None = None, trajectory: Trajectory | None = None,
             supply: tuple | None = None, spool_command: np.ndarray | None = None,
             initial_state: np.ndarray | None = None, segment_s: float = 10.0) -> RefRecording:
    """Run the plant for ``duration_s`` [s] from rest and record it.

    Parameters
    ----------
    plant : RefPlant
        The true plant (:mod:`.params` presets: ``NAMEPLATE``, ``manufactured``, ``worn``, ``family``).
    duration_s : float
        Length [s]; a whole number of samples. Longer than ``segment_s`` it is one continuous
        recording integrated in consecutive segments (state carried over; memory per segment).
    seed : int
        Draws the trajectory, the load, the supply and the noise, each from its own stream, so
        passing one of them explicitly leaves the others unchanged.
    effects : Effects, optional
        Hidden effects (:mod:`.scenarios`); default none.
    load, trajectory : optional
        Default drawn from ``plant.operation`` (loads stepping every 1-4 s, moves over the stroke).
    supply : tuple, optional
        (p_s0 [Pa], drift [Pa/s], ripple [Pa], ripple frequency [Hz], phase [rad], p_r [Pa]).
    spool_command : ndarray, optional
        A prescribed spool command x_ref per sample (held over the sample) instead of the controller.
    initial_state : ndarray (7,), optional
        (x, v, X, v_X, p1, p2, z); default the rest state at X_ref(0) (:func:`.plant.rest_state`).
    """
    effects = Effects() if effects is None else effects
    fs = plant.sensors.sample_rate_hz
    n = int(round(duration_s * fs))
    if n < 2 or abs(n - duration_s * fs) > 1e-6:
        raise ValueError("duration_s must be a whole number (>= 2) of samples")
    trajectory, load, supply = draw_window(plant, duration_s, seed, load=load, trajectory=trajectory, supply=supply)
    inp = Inputs.build(plant, effects, supply, trajectory, load, spool_command)
    y = rest_state(inp) if initial_state is None else np.asarray(initial_state, float)

    sens = plant.sensors
    fine = max(1, int(sens.fine_per_sample))
    h = 1.0 / (fs * fine)
    taus = [lag + (effects.extra_lag_s if ch == effects.extra_lag_channel else 0.0) for ch, lag in zip(PRESSURES, sens.lag_s)]
    t = np.arange(n) / fs
    states = np.empty((7, n))
    lagged = np.empty((4, n))
    lag_end = None
    nfev = 0
    cpu0 = time.process_time()
    seg = max(1, int(round(segment_s * fs)))
    for k0 in range(0, n - 1, seg):
        k1 = min(n - 1, k0 + seg)
        tf = t[k0] + np.arange((k1 - k0) * fine + 1) * h
        tf[-1] = t[k1]
        yf, nf = integrate(inp, y, tf, plant)
        nfev += nf
        pf = np.vstack([inp.supply_pressure(tf), np.full(tf.size, inp.p_r), yf[4], yf[5]])
        lf = [first_order_lag(pf[c], h, taus[c], None if lag_end is None else lag_end[c]) for c in range(4)]
        lag_end = [f[-1] for f in lf]
        states[:, k0:k1 + 1] = yf[:, ::fine]
        for c in range(4):
            lagged[c, k0:k1 + 1] = lf[c][::fine]
        y = yf[:, -1]
    cpu = time.process_time() - cpu0

    x, v, X, vX, p1, p2, z = states
    ps_true = inp.supply_pressure(t)
    pr_true = np.full(n, inp.p_r)
    q1, q2, psv = port_flows(inp, x, p1, p2, ps_true, pr_true)
    xr, Xr, vr = controller_output(inp, t, X, z)
    true = {"x": x, "v": v, "X": X, "vX": vX, "p1": p1, "p2": p2, "ps": ps_true, "pr": pr_true,
            "ps_valve": psv, "q1": q1, "q2": q2, "F_l": load.at(t), "X_ref": Xr, "v_ref": vr, "x_ref": xr}

    rng = np.random.default_rng([seed, 4])
    sk = sens.skew_samples
    ps_m, pr_m, p1_m, p2_m = (skewed(lagged[c], sk) for c in range(4))
    p1_m = effects.p1_gain * p1_m + effects.p1_offset_pa
    p2_m = effects.p2_gain * p2_m + effects.p2_offset_pa
    return RefRecording(
        t_s=t,
        ps=record(ps_m, sens.ps, rng), pr=record(pr_m, sens.pr, rng),
        p1=record(p1_m, sens.p1, rng), p2=record(p2_m, sens.p2, rng),
        x_spool=record(x + effects.spool_sensor_offset_m, sens.x_spool, rng),
        x_cyl=record(X, sens.x_cyl, rng), x_ref=record(xr, sens.x_ref, rng),
        true=true, plant=plant, effects=effects, trajectory=trajectory, load=load, seed=seed,
        cpu_s=cpu, nfev=nfev)


def without_noise(plant: RefPlant) -> RefPlant:
    """``plant`` whose acquisition adds no noise and does not quantise (ranges kept)."""
    s = plant.sensors
    quiet = {ch: replace(getattr(s, ch), noise=0.0, step=0.0) for ch in ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref")}
    return replace(plant, sensors=replace(s, **quiet))

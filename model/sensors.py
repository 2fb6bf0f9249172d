"""Sensor models: what the plant's acquisition records of a simulated window.

Each signal is sampled at the simulator's sample instants (the simulator already runs at the
acquisition rate), then gets additive white Gaussian noise, uniform quantisation
(round to the nearest step) and clipping to the sensor range, per
:class:`~model.params.SensorChannel` (values and their reasons in
:class:`~model.params.SensorParams`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import Effects, sensor_readings
from .params import SensorChannel, SensorParams
from .simulate import SimulationResult


@dataclass(frozen=True)
class MeasuredSignals:
    """Recorded signals, SI units, arrays shaped (n_windows, n_samples).

    Attributes
    ----------
    t_s : Sample time since the window's start. [s]
    ps : Supply pressure. [Pa]
    pr : Return pressure. [Pa]
    p1 : Head-side chamber pressure. [Pa]
    p2 : Rod-side chamber pressure. [Pa]
    x_spool : Spool position x. [m]
    x_cyl : Cylinder position X. [m]
    x_ref : Spool reference. [m]
    """

    t_s: np.ndarray
    ps: np.ndarray
    pr: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    x_spool: np.ndarray
    x_cyl: np.ndarray
    x_ref: np.ndarray


def measure_channel(values, channel: SensorChannel, rng: np.random.Generator) -> np.ndarray:
    """One signal through its sensor: + N(0, noise_std), quantised to ``step``, clipped to
    [lo, hi]. Units of ``values`` are those of the channel (SI)."""
    v = np.asarray(values, dtype=np.float64)
    if channel.noise_std > 0:
        v = v + rng.normal(0.0, channel.noise_std, v.shape)
    if channel.step > 0:
        v = np.round(v / channel.step) * channel.step
    return np.clip(v, channel.lo, channel.hi)


def measure(result: SimulationResult, sensor_params: SensorParams,
            rng: np.random.Generator, effects: Effects | None = None) -> MeasuredSignals:
    """Turn true simulated signals into recorded ones (noise, quantisation, range).

    Parameters
    ----------
    result : SimulationResult
        True signals at the sample rate.
    sensor_params : SensorParams
        Per-signal noise, quantisation step and range. Its ``sample_rate_hz`` must equal the
        simulation's.
    rng : numpy.random.Generator
        Source of the noise (the result is deterministic for a seeded generator).
    effects : Effects, optional
        Sensor effects (spool sensor offset, pressure sensor offsets and gains,
        :mod:`model.effects`) applied to the true signals before noise; default
        ``result.effects`` (none for a base-model simulation).

    Returns
    -------
    MeasuredSignals
    """
    if abs(sensor_params.sample_rate_hz - result.sample_rate_hz) > 1e-9:
        raise ValueError("sensor sample rate differs from the simulation's sample rate")
    s = sensor_params
    fx = getattr(result, "effects", None) if effects is None else effects
    x, p1, p2 = sensor_readings(result.x_m, result.p1_pa, result.p2_pa, fx)
    return MeasuredSignals(
        t_s=result.t_s.copy(),
        ps=measure_channel(result.ps_pa, s.ps, rng),
        pr=measure_channel(result.pr_pa, s.pr, rng),
        p1=measure_channel(p1, s.p1, rng),
        p2=measure_channel(p2, s.p2, rng),
        x_spool=measure_channel(x, s.x_spool, rng),
        x_cyl=measure_channel(result.X_m, s.x_cyl, rng),
        x_ref=measure_channel(result.x_ref_m, s.x_ref, rng),
    )

"""Transmitters of the reference plant: first-order lag, skew between channels, gain and offset
errors, noise, quantisation and range.

The lag runs on the fine grid of the dense solution (:func:`first_order_lag`: exact for an input
linear between grid points); the recorded pressures are then taken ``skew_samples`` samples late
against the positions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import Channel


@njit(cache=True)
def _lag(u, h, tau, y0):
    n = u.size
    y = np.empty(n)
    y[0] = y0
    a = math.exp(-h / tau)
    c = 1.0 - tau / h * (1.0 - a)
    for i in range(n - 1):
        y[i + 1] = a * y[i] + (1.0 - a) * u[i] + c * (u[i + 1] - u[i])
    return y


def first_order_lag(u: np.ndarray, h_s: float, tau_s: float, y0: float | None = None) -> np.ndarray:
    """Output of tau dy/dt = u - y for ``u`` on a uniform grid of step ``h_s`` [s], linear between
    points, from y(0) = ``y0`` (default u[0], i.e. settled); tau = 0 returns u."""
    u = np.ascontiguousarray(u, float)
    if tau_s <= 0.0:
        return u.copy()
    return _lag(u, float(h_s), float(tau_s), float(u[0] if y0 is None else y0))


def skewed(samples: np.ndarray, skew: int) -> np.ndarray:
    """``samples`` recorded ``skew`` samples late: out[k] = samples[k - skew] (the first ``skew``
    repeat samples[0]: every window starts at rest)."""
    if skew <= 0:
        return samples
    return np.concatenate([np.full(skew, samples[0]), samples[:-skew]])


def record(values: np.ndarray, channel: Channel, rng: np.random.Generator) -> np.ndarray:
    """One channel as the acquisition stores it: + N(0, noise), rounded to the step, clipped."""
    v = np.asarray(values, float)
    if channel.noise > 0:
        v = v + rng.normal(0.0, channel.noise, v.shape)
    if channel.step > 0:
        v = np.round(v / channel.step) * channel.step
    return np.clip(v, channel.lo, channel.hi)

"""The simulation side of ``valvemon simulate``: batches of windows through the model, in this
process or in worker processes.

Kept apart from :mod:`flows.simulate.archive` so a worker process imports only numpy and the model
(no polars, no pandera): workers start in about a second.

Every window draws its operating inputs (trajectory, load, supply) and then its sensor noise
from its own generator, :func:`window_rng` (seed, valve id, window start), so a window's data
do not depend on the batch or the process that simulates it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import multiprocessing
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, TypeVar

import numpy as np

from model.params import PlantParams, SensorParams, ValveCondition
from model.sensors import measure
from model.simulate import SimulationResult, simulate_inputs
from model.trajectory import window_inputs

SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref")
"""The measured signals (:class:`model.sensors.MeasuredSignals` attributes, SI), in the order of
``schemas.fields.SIGNALS``."""


def valve_key(valve_id: str) -> int:
    """A stable 64-bit number for a valve id (seeds must not depend on the valve's position)."""
    return int.from_bytes(hashlib.sha256(valve_id.encode()).digest()[:8], "little")


def window_rng(seed: int, valve_id: str, window_start_us: int) -> np.random.Generator:
    """The generator of one window of one valve: its inputs first, then its sensor noise."""
    return np.random.default_rng([int(seed), valve_key(valve_id), 2, int(window_start_us)])


def simulate_measured(
    params: PlantParams,
    conditions: Sequence[ValveCondition],
    windows: Sequence[tuple[str, int]],
    window_s: float,
    seed: int,
) -> dict[str, np.ndarray]:
    """Measured signals (SI) of a batch of windows of valves that share ``params``.

    Parameters
    ----------
    params : PlantParams
    conditions : sequence of ValveCondition
        The valve condition of each window.
    windows : sequence of (valve id, window start [µs UTC])
        Whose window each is, which seeds it (:func:`window_rng`).
    window_s : float
        Window length. [s]
    seed : int

    Returns
    -------
    dict
        Signal name → array (n_windows, n_samples), SI.
    """
    rngs = [window_rng(seed, vid, start) for vid, start in windows]
    inputs = [window_inputs(params, window_s, g) for g in rngs]
    result = simulate_inputs(params, list(conditions), inputs)
    return measure_windows(result, params.sensors, rngs)


def measure_windows(result: SimulationResult, sensors: SensorParams, rngs: Sequence[np.random.Generator]) -> dict[str, np.ndarray]:
    """Sensor readings of every window of ``result``, each window with its own generator."""
    out = {s: np.empty((result.n_windows, result.n_samples)) for s in SIGNALS}
    for w, g in enumerate(rngs):
        m = measure(window_of(result, w), sensors, g)
        for s in SIGNALS:
            out[s][w] = getattr(m, s)[0]
    return out


def window_of(result: SimulationResult, w: int) -> SimulationResult:
    """Window ``w`` of a batch result, as a batch of one."""
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(result):
        val = getattr(result, f.name)
        if isinstance(val, np.ndarray) and val.ndim == 2:
            kw[f.name] = val[w : w + 1]
        elif f.name == "conditions":
            kw[f.name] = (val[w],)
    return dataclasses.replace(result, **kw)


T = TypeVar("T")


def default_workers() -> int:
    """Worker processes by default: one per CPU beyond the first (which writes), at most 8."""
    return max(0, min(8, (os.cpu_count() or 1) - 1))


def run_ordered(tasks: Iterable[tuple[Callable[..., T], tuple]], workers: int) -> Iterator[T]:
    """Results of ``tasks`` (function, arguments) in task order.

    ``workers`` = 0 runs each task here when its result is asked for; otherwise a pool of
    ``workers`` spawned processes runs up to 2 x workers tasks ahead of the consumer (which
    bounds the memory held by finished results)."""
    if workers <= 0:
        for fn, args in tasks:
            yield fn(*args)
        return
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        pending: deque[Future] = deque()
        it = iter(tasks)
        exhausted = False
        try:
            while True:
                while not exhausted and len(pending) < 2 * workers:
                    try:
                        fn, args = next(it)
                    except StopIteration:
                        exhausted = True
                        break
                    pending.append(pool.submit(fn, *args))
                if not pending:
                    return
                yield pending.popleft().result()
        finally:
            for f in pending:
                f.cancel()

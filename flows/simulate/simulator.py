"""The simulation side of ``valvemon simulate``: batches of windows through the model, in this
process or in worker processes.

Kept apart from :mod:`flows.simulate.archive` so a worker process imports only numpy and the model
(no polars, no pandera): workers start in about a second.

Every segment (a window, or a piece of a longer recording) draws its operating inputs
(trajectory, load, supply) and then its sensor noise from its own generator,
:func:`window_rng` (seed, valve id, segment start), so its data do not depend on the batch or
the process that simulates it; a segment that continues a recording starts from the previous
segment's :class:`Carry`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import multiprocessing
import os
from collections import deque
from collections.abc import Callable, Hashable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np

from flows.common.errors import ValvemonError
from model.params import PlantParams, SensorParams, ValveCondition
from model.sensors import measure
from model.simulate import SimulationDiverged, SimulationResult, simulate_inputs
from model.trajectory import RecordingState, segment_inputs

SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref")
"""The measured signals (:class:`model.sensors.MeasuredSignals` attributes, SI), in the order of
``schemas.fields.SIGNALS``."""


def valve_key(valve_id: str) -> int:
    """A stable 64-bit number for a valve id (seeds must not depend on the valve's position)."""
    return int.from_bytes(hashlib.sha256(valve_id.encode()).digest()[:8], "little")


def window_rng(seed: int, valve_id: str, window_start_us: int) -> np.random.Generator:
    """The generator of one window of one valve: its inputs first, then its sensor noise."""
    return np.random.default_rng([int(seed), valve_key(valve_id), 2, int(window_start_us)])


@dataclass(frozen=True)
class Carry:
    """Where a valve's recording stands after a segment: its inputs and the plant's state and
    controller integrator (``SimulationResult.end_state``), so the next segment continues it."""

    inputs: RecordingState
    end_state: np.ndarray


def simulate_measured(
    params: PlantParams,
    conditions: Sequence[ValveCondition],
    windows: Sequence[tuple[str, int]],
    n_samples: int,
    seed: int,
    carries: Sequence[Carry] | None,
) -> tuple[dict[str, np.ndarray], list[Carry]]:
    """Measured signals (SI) of a batch of segments of valves that share ``params``.

    Parameters
    ----------
    params : PlantParams
    conditions : sequence of ValveCondition
        The valve condition of each segment.
    windows : sequence of (valve id, segment start [µs UTC])
        Whose segment each is, which seeds it (:func:`window_rng`).
    n_samples : int
        Samples per segment.
    seed : int
    carries : sequence of Carry, or None
        Where each valve's recording stood after its previous segment; None: every segment
        starts a recording (at rest, :func:`model.simulate.simulate_inputs`).

    Returns
    -------
    (dict, list of Carry)
        Signal name → array (n_windows, n_samples), SI; and where each recording stands after
        the segment.

    Raises
    ------
    ValvemonError
        If the simulation diverges (one line naming the valve, the segment and the instant) or
        fails otherwise (naming the valves and the segment).
    """
    rngs = [window_rng(seed, vid, start) for vid, start in windows]
    drawn = [segment_inputs(params, n_samples, g, None if carries is None else c.inputs) for g, c in zip(rngs, carries or [None] * len(rngs))]
    inputs = [d[0] for d in drawn]
    start = None if carries is None else np.array([c.end_state for c in carries])
    try:
        result = simulate_inputs(
            params,
            list(conditions),
            inputs,
            initial_states=None if start is None else start[:, :6],
            initial_integrators=None if start is None else start[:, 6],
        )
    except SimulationDiverged as exc:
        vid, t0 = windows[exc.window]
        raise ValvemonError(
            f"simulation of valve {vid} diverged at {iso_us(t0 + round(exc.time_s * 1e6))} "
            f"({exc.time_s:.3f} s into the segment starting {iso_us(t0)}): a pressure or velocity left the physical range"
        ) from None
    except (ArithmeticError, ValueError) as exc:
        valves = ", ".join(dict.fromkeys(vid for vid, _ in windows))
        raise ValvemonError(f"simulation of valve(s) {valves} failed in the segment starting {iso_us(windows[0][1])}: {exc}") from None
    ends = [Carry(d[1], result.end_state[w].copy()) for w, d in enumerate(drawn)]
    return measure_windows(result, params.sensors, rngs), ends


def iso_us(t_us: int) -> str:
    """µs UTC as ISO-8601 with a Z (whole seconds without a fraction)."""
    t = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=int(t_us))
    text = t.isoformat(timespec="microseconds" if t.microsecond else "seconds")
    return text.replace("+00:00", "Z")


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


def default_workers() -> int:
    """Worker processes by default: one per CPU beyond the first (which writes), at most 8."""
    return max(0, min(8, (os.cpu_count() or 1) - 1))


Task = tuple[Callable[..., tuple[Any, Any]], tuple, Hashable | None, Hashable | None]
"""A simulator call: (function, arguments, carry from, carry to). The function is called as
``fn(*args, carry)`` and returns (result, carry out); ``carry`` is the carry out of the task
that named the same key as its *carry to* (None if *carry from* is None), and a task's carry
out is kept for a later task only if it names a *carry to* key."""


def run_ordered(tasks: Iterable[Task], workers: int) -> Iterator[Any]:
    """Results of ``tasks`` (:data:`Task`) in task order.

    ``workers`` = 0 runs each task here when its result is asked for; otherwise a pool of
    ``workers`` spawned processes runs up to 2 x workers tasks ahead of the consumer (which
    bounds the memory held by finished results). A task that continues an earlier one waits,
    before it is submitted, for that task's carry (the segments of one recording run one after
    the other; different recordings and valves in parallel)."""
    carried: dict[Hashable, Any] = {}

    def carry_of(key):
        if key is None:
            return None
        got = carried.pop(key)
        return got.result()[1] if isinstance(got, Future) else got

    if workers <= 0:
        for fn, args, key_in, key_out in tasks:
            result, carry = fn(*args, carry_of(key_in))
            if key_out is not None:
                carried[key_out] = carry
            yield result
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
                        fn, args, key_in, key_out = next(it)
                    except StopIteration:
                        exhausted = True
                        break
                    future = pool.submit(fn, *args, carry_of(key_in))
                    pending.append(future)
                    if key_out is not None:
                        carried[key_out] = future
                if not pending:
                    return
                yield pending.popleft().result()[0]
        finally:
            for f in pending:
                f.cancel()

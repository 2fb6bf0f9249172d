"""Benchmark of the closed-loop simulator (model.simulate_windows) on one core.

Simulates a batch of windows (default 32 x 10 s, healthy/worn/broken valves mixed) after a
warm-up call that loads or compiles the numba kernels, and prints simulated seconds per
wall-clock second and per CPU second of this (single-threaded) process, plus the time per
window. The process is pinned to one CPU where the OS allows it.

Then a continuous recording of ``--continuous-h`` hours (default 1; 0 skips it) of one worn
valve, the way ``valvemon simulate --recording continuous`` makes it: back-to-back segments of
``--segment-s`` seconds, each continuing the last (``flows.simulate.simulator.simulate_measured``:
inputs, closed loop and sensors), with the simulated seconds per CPU second and the peak RSS
before and after (it must not grow with the length).

    .venv/bin/python bench/simulate.py [--windows 32] [--duration 10] [--substeps 2] [--repeats 5] [--continuous-h 1]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from model import BROKEN_1R, TABLE1, WEAR, condition_at, healthy, simulate_windows  # noqa: E402
from model.simulate import DEFAULT_SUBSTEPS  # noqa: E402


def conditions(n: int):
    out = []
    for i in range(n):
        kind = i % 4
        if kind == 0:
            out.append(TABLE1.nominal_condition)
        elif kind == 1:
            out += condition_at(healthy(i), [0.0])
        elif kind == 2:
            out += condition_at(WEAR, [20000.0 * i / n])
        else:
            out += condition_at(BROKEN_1R, [0.0])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=32)
    ap.add_argument("--duration", type=float, default=10.0, help="window length [s]")
    ap.add_argument("--substeps", type=int, default=DEFAULT_SUBSTEPS, help="RK4 steps per sample")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    ap.add_argument("--continuous-h", type=float, default=1.0, help="hours of continuous recording (0: skip)")
    ap.add_argument("--segment-s", type=float, default=60.0, help="segment length of the recording [s]")
    a = ap.parse_args(argv)

    pinned = "no"
    if hasattr(os, "sched_setaffinity") and not a.no_pin:
        cpu = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {cpu})
        pinned = f"cpu {cpu}"

    conds = conditions(a.windows)
    t0 = time.perf_counter()
    simulate_windows(TABLE1, conds[:1], 1.0, a.seed, substeps=a.substeps)
    warm = time.perf_counter() - t0

    sim_s = a.windows * a.duration
    walls, cpus = [], []
    for r in range(a.repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        res = simulate_windows(TABLE1, conds, a.duration, a.seed + r, substeps=a.substeps)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
        assert np.all(np.isfinite(res.p1_pa))
    best_wall, med_wall = min(walls), statistics.median(walls)
    best_cpu, med_cpu = min(cpus), statistics.median(cpus)
    print(f"simulator benchmark: {a.windows} windows x {a.duration:g} s = {sim_s:g} simulated s, "
          f"{a.substeps} RK4 steps per 1 ms sample, pinned to {pinned}, "
          f"warm-up (load/compile) {warm:.2f} s")
    print(f"  wall: best {best_wall:.3f} s, median {med_wall:.3f} s over {a.repeats} runs")
    print(f"  cpu : best {best_cpu:.3f} s, median {med_cpu:.3f} s")
    print(f"  simulated seconds per wall second (best/median): {sim_s / best_wall:,.0f} / "
          f"{sim_s / med_wall:,.0f}")
    print(f"  simulated seconds per CPU second  (best/median): {sim_s / best_cpu:,.0f} / "
          f"{sim_s / med_cpu:,.0f}")
    print(f"  per {a.duration:g} s window: {1e3 * med_wall / a.windows:.2f} ms wall (median)")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"  1-min load average during the run: {load:.2f} on {os.cpu_count()} CPUs"
          + ("  (machine busy: the wall figures include waiting for the CPU; the CPU-second "
             "figures are this process's own single-core throughput)" if load > 1.5 else ""))
    target = 1000.0
    for label, got in (("wall (best)", sim_s / best_wall), ("CPU (median)", sim_s / med_cpu)):
        verdict = "met" if got >= target else f"MISSED by a factor {target / got:.2f}"
        print(f"  target {target:,.0f} simulated s per second on one core, {label}: {verdict}")
    if a.continuous_h > 0:
        continuous(a, sim_s / med_cpu, target)
    return 0


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def continuous(a, batch_rate: float, target: float) -> None:
    """A continuous recording of one worn valve in back-to-back segments (module docstring)."""
    from flows.simulate.simulator import simulate_measured
    from model.condition import condition_at as cond_at

    n_seg = round(a.segment_s * TABLE1.sensors.sample_rate_hz)
    segments = round(a.continuous_h * 3600.0 / a.segment_s)
    simulate_measured(TABLE1, [TABLE1.nominal_condition], [("V001", 0)], 1000, a.seed, None)  # warm-up
    rss0 = _rss_mb()
    carry, half_rss = None, rss0
    w0, c0 = time.perf_counter(), time.process_time()
    for k in range(segments):
        start_us = k * round(a.segment_s * 1e6)
        cond = cond_at(WEAR, [5000.0 + start_us / 3.6e9])
        m, carry = simulate_measured(TABLE1, cond, [("V001", start_us)], n_seg, a.seed, carry)
        assert np.all(np.isfinite(m["p1"]))
        if k == segments // 2:
            half_rss = _rss_mb()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    sim_s = segments * a.segment_s
    print(f"continuous recording: {a.continuous_h:g} h of one worn valve in {segments} segments of {a.segment_s:g} s "
          f"(inputs, closed loop, sensors)")
    print(f"  cpu {cpu:.2f} s, wall {wall:.2f} s: {sim_s / cpu:,.0f} simulated s per CPU second, {sim_s / wall:,.0f} per wall second")
    print(f"  ratio to the window batch above (CPU, same run): {sim_s / cpu / batch_rate:.2f}")
    print(f"  peak RSS: {rss0:.0f} MB before, {half_rss:.0f} MB halfway, {_rss_mb():.0f} MB at the end")
    verdict = "met" if sim_s / cpu >= target else f"MISSED by a factor {target / (sim_s / cpu):.2f}"
    print(f"  target {target:,.0f} simulated s per CPU second on one core: {verdict}")


if __name__ == "__main__":
    raise SystemExit(main())

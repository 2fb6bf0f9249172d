"""Benchmark of the closed-loop simulator (model.simulate_windows) on one core.

Simulates a batch of windows (default 32 x 10 s, healthy/worn/broken valves mixed) after a
warm-up call that loads or compiles the numba kernels, and prints simulated seconds per
wall-clock second and per CPU second of this (single-threaded) process, plus the time per
window. The process is pinned to one CPU where the OS allows it.

    .venv/bin/python bench/simulate.py [--windows 32] [--duration 10] [--substeps 2] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

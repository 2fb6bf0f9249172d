"""Benchmark of the second reference plant (tests/refplant): CPU per 10 s window and solver.

For each edge family (eq3, sharp, linear) and each solve_ivp method asked for, simulates
``--windows`` closed-loop 10 s windows of a manufactured valve (default operation: moves over the
stroke, loads stepping every 1-4 s) after a warm-up call (numba kernels loaded or compiled), and
prints the process CPU seconds of the integration per window (median), the rhs evaluations and
the whole call's CPU (integration, flows, sensors). Then, with ``--continuous-s``, one continuous
recording of that length (10 s segments) with its CPU and peak RSS. Pins itself to one CPU.

    .venv/bin/python bench/refplant.py [--windows 5] [--methods LSODA,BDF,Radau] [--continuous-s 120]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.refplant import NAMEPLATE, family, manufactured, simulate  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=5)
    ap.add_argument("--methods", default="LSODA")
    ap.add_argument("--continuous-s", type=float, default=0.0)
    a = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    simulate(NAMEPLATE, 0.5, 0)  # warm-up
    print("| family | method | integration CPU per 10 s window (median) | rhs evaluations | whole call CPU |")
    print("|---|---|---|---|---|")
    for fam in ("eq3", "sharp", "linear"):
        for method in a.methods.split(","):
            base = family(manufactured(NAMEPLATE, 1), fam)
            plant = replace(base, integration=replace(base.integration, method=method))
            cpu, nfev, whole = [], [], []
            for w in range(a.windows):
                c0 = time.process_time()
                rec = simulate(plant, 10.0, 100 + w)
                whole.append(time.process_time() - c0)
                cpu.append(rec.cpu_s)
                nfev.append(rec.nfev)
            print(f"| {fam} | {method} | {statistics.median(cpu):.2f} s ({min(cpu):.2f}-{max(cpu):.2f}) | "
                  f"{statistics.median(nfev):,.0f} | {statistics.median(whole):.2f} s |", flush=True)
    if a.continuous_s > 0:
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        c0 = time.process_time()
        rec = simulate(manufactured(NAMEPLATE, 1), a.continuous_s, 7)
        cpu = time.process_time() - c0
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"continuous {a.continuous_s:.0f} s: {cpu:.1f} s CPU ({a.continuous_s / cpu:.1f} simulated s per CPU s), "
              f"peak RSS {rss0:.0f} -> {rss1:.0f} MB")


if __name__ == "__main__":
    main()

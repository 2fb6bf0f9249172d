"""Benchmark of ``valvemon simulate``: simulated valve-seconds and export rows per wall second.

Runs the command's own code path (:func:`flows.simulate.archive.run_simulate`) on a 50-valve plant with
hourly 10 s windows for each writer -- long CSV.gz, wide CSV, Parquet (long) -- and prints a
Markdown table for BENCHMARKS.md with the equivalent command lines.

    .venv/bin/python bench/archive.py [--valves 50] [--hours 6] [--workers N] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from flows.simulate.archive import SimulateRequest, run_simulate
from flows.simulate.simulator import default_workers


def cpu_seconds() -> float:
    """User + system CPU time of this process and its finished children (the workers). [s]"""
    t = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        r = resource.getrusage(who)
        t += r.ru_utime + r.ru_stime
    return t


CASES = [
    ("long CSV.gz", "long", True, None),
    ("wide CSV", "wide", False, None),
    ("Parquet (long)", "parquet", False, None),
    ("long CSV.gz, in-process", "long", True, 0),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--valves", type=int, default=50)
    ap.add_argument("--hours", type=float, default=6.0, help="operating hours simulated (hourly windows)")
    ap.add_argument("--workers", type=int, default=None, help="simulator processes (default: the command's own choice)")
    ap.add_argument("--out", type=Path, default=None, help="scratch folder (default: a temporary one, removed)")
    args = ap.parse_args()
    scratch = args.out or Path(tempfile.mkdtemp(prefix="valvemon-bench-"))
    try:
        # warm the numba cache so compilation is not measured
        run_simulate(SimulateRequest(out=scratch / "warm", n_valves=1, hours="0:1", window_s=1.0, overwrite=True, workers=0), show_progress=False)
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")
        print()
        print("| writer | command | valve windows | valve-s / wall s | valve-s / CPU s | rows | rows / wall s | values / wall s | rows / s writing | simulate s | write s | MB | wall s | CPU s |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for label, fmt, gz, workers in CASES:
            workers = args.workers if workers is None else workers
            out = scratch / fmt
            req = SimulateRequest(
                out=out, n_valves=args.valves, hours=f"0:{args.hours:g}", format=fmt, gzip=gz, overwrite=True, workers=workers
            )
            cmd = f"valvemon simulate --out DIR --n-valves {args.valves} --hours 0:{args.hours:g} --format {fmt}" + (" --gzip" if gz else "")
            if workers is not None:
                cmd += f" --workers {workers}"
            t, c = time.perf_counter(), cpu_seconds()
            s = run_simulate(req, show_progress=False)
            wall, cpu = time.perf_counter() - t, cpu_seconds() - c
            print(
                f"| {label} | `{cmd}` | {s.windows:,} | {s.valve_seconds / wall:,.0f} | {s.valve_seconds / cpu:,.0f} | {s.rows:,} | {s.rows / wall / 1e6:,.3g} M "
                f"| {s.values / wall / 1e6:,.2f} M | {s.rows / s.write_s / 1e6:,.3g} M | {s.simulate_s:,.1f} | {s.write_s:,.1f} "
                f"| {s.bytes / 1e6:,.0f} | {wall:,.1f} | {cpu:,.1f} |"
            )
            shutil.rmtree(out)
        w = args.workers if args.workers is not None else default_workers()
        print(f"\nworkers (where not given): {w}; load average {os.getloadavg()[0]:.1f} at the end")
        print("simulate s: time simulating (in-process) or waiting for the workers; write s: converting, formatting, writing")
    finally:
        if args.out is None:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()

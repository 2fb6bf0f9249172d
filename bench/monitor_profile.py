"""Where ``valvemon monitor`` spends its CPU: the command in this process, timed by phase and kernel.

Runs the command (start-up included: imports, numba's first use and the cached kernels loaded,
the publish at the end) with CPU-clock timers wrapped around its phases and around each compiled
kernel of steps 2–4b (module attributes replaced by timing wrappers: one clock reading per
call, so, unlike a profiler's per-call overhead, the figures are those of the plain command),
and prints CPU seconds and nanoseconds per lake row. Pin it to one core:

    taskset -c 1 .venv/bin/python bench/monitor_profile.py -- monitor --config PLANT.toml --warehouse WH
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SPENT: dict[str, float] = defaultdict(float)

# phase -> (module, attribute) whose calls it is (the command's phases are disjoint)
PHASES = {
    "baselines (numba's first use: its start-up)": [("flows.monitor.flow", "ensure_baselines")],
    "lake read (Parquet decode in spans, window-aligned chunks)": [("flows.monitor.flow", "lake_chunks")],
    "steps 2–4b (`monitor_rows`)": [("flows.monitor.flow", "monitor_rows")],
    "fits to rows, DuckDB writes": [("flows.monitor.flow", "_fits_table"), ("flows.monitor.flow", "store_spans")],
    "publish (views, snapshot for queries)": [("flows.report.publish", "publish")],
}
# inside steps 2–4b: the compiled kernels (the first call of each loads it from numba's cache)
KERNELS = {
    "windows": [("transforms.windows", "_steps_kernel"), ("transforms.windows", "_starts_kernel"), ("transforms.windows", "_layout_kernel")],
    "Savitzky–Golay": [("transforms.derivatives", "_savgol_kernel"), ("transforms.derivatives", "_savgol_at_kernel")],
    "step 3 selection": [("transforms.selection", "_selection_kernel")],
    "Eq. 7 points": [("transforms.points", "_points_kernel")],
    "Eq. 8 fits (first estimates on every 8th point, final fit)": [("transforms.fit", "_fit_groups")],
    "leakage correction, the windows' leakage": [("transforms.monitor", "_leak_correct"), ("transforms.monitor", "leak_scale_step")],
}


def cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(label: str, fn):
    def call(*a, **k):
        t0 = cpu()
        try:
            return fn(*a, **k)
        finally:
            SPENT[label] += cpu() - t0

    return call


def _timed_gen(label: str, fn):
    def gen(*a, **k):
        it = fn(*a, **k)
        while True:
            t0 = cpu()
            try:
                item = next(it)
            except StopIteration:
                SPENT[label] += cpu() - t0
                return
            SPENT[label] += cpu() - t0
            yield item

    return gen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    t0 = cpu()
    from flows.common.allocator import retain_polars_memory

    retain_polars_memory()  # as the command does, before polars is imported
    import flows.cli
    import flows.monitor.flow
    import flows.report.publish  # noqa: F401 - the modules the command imports, timed here

    SPENT["imports"] = cpu() - t0
    for table, wrap in ((PHASES, None), (KERNELS, None)):
        for label, targets in table.items():
            for mod, attr in targets:
                m = importlib.import_module(mod)
                fn = getattr(m, attr)
                wrapped = _timed_gen(label, fn) if attr == "lake_chunks" else _timed(label, fn)
                setattr(m, attr, wrapped)
    rows = 0
    inner = flows.monitor.flow.monitor_rows

    def counting(valve, params, baselines, lake):
        nonlocal rows
        rows += lake.height
        return inner(valve, params, baselines, lake)

    flows.monitor.flow.monitor_rows = counting
    sys.argv = ["valvemon", *[a for a in args.command if a != "--"]]
    try:
        flows.cli.main()
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise
    ru = resource.getrusage(resource.RUSAGE_SELF)
    total = ru.ru_utime + ru.ru_stime

    def line(label: str, sec: float) -> None:
        print(f"| {label} | {sec:.2f} | {sec / total:.0%} | {sec / rows * 1e9:.0f} |")

    print(f"\n{rows:,} lake rows; CPU {total:.2f} s (user {ru.ru_utime:.2f} + system {ru.ru_stime:.2f}): "
          f"{rows / total / 1e6:.2f} M lake rows per CPU second\n")
    print("| phase | CPU s | share | ns per lake row |")
    print("|---|---:|---:|---:|")
    line("imports", SPENT["imports"])
    for label in PHASES:
        line(label, SPENT[label])
    line("the rest (CLI, configuration, Python between the phases)", total - SPENT["imports"] - sum(SPENT[k] for k in PHASES))
    print("| *of steps 2–4b:* | | | |")
    for label in KERNELS:
        line(label, SPENT[label])
    step = SPENT["steps 2–4b (`monitor_rows`)"] - sum(SPENT[k] for k in KERNELS)
    line("frames, columns to numpy, Python glue", step)


if __name__ == "__main__":
    main()

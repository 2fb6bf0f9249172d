"""Where ``valvemon report`` and ``valvemon retention`` spend their CPU: the command in this
process, timed by phase.

Runs the command (start-up included) with CPU-clock timers wrapped around its phases (module
attributes replaced by timing wrappers, :mod:`bench.monitor_profile`'s: one clock reading per
call, so the figures are those of the plain command) and prints CPU seconds per phase; the
pictures the report draws in a pool of processes count as the children's CPU. Phases may nest
(an inner one is part of the outer one: indented). Pin it to one core:

    taskset -c 1 .venv/bin/python bench/night_profile.py -- report --config PLANT.toml --warehouse WH
    taskset -c 1 .venv/bin/python bench/night_profile.py -- retention --config PLANT.toml --warehouse WH --as-of DATE
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import inspect  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.monitor_profile import SPENT, _timed, _timed_gen, cpu  # noqa: E402

# command -> [(depth, label, [(module, attribute), ...])]: the phases in the order they run
PHASES = {
    "report": [
        (0, "standstill check (Eq. 9 from the lake)", [("flows.report.flow", "update_standstill")]),
        (1, "lake read", [("flows.monitor.flow", "lake_chunks")]),
        (1, "Eq. 9 per window", [("flows.report.flow", "standstill_rows")]),
        (0, "publish (bounds, views, summaries, snapshot)", [("flows.report.flow", "publish")]),
        (1, "daily summaries", [("flows.report.publish", "update_summaries")]),
        (1, "snapshot copy", [("flows.report.publish", "publish_snapshot")]),
        (0, "the report's views computed", [("flows.report.flow", "materialise_views")]),
        (0, "BI export", [("flows.report.flow", "export_bi")]),
        (0, "pictures (pool; this process's share)", [("flows.report.flow", "render_figures")]),
        (0, "HTML", [("flows.report.flow", "render_report")]),
    ],
    "retention": [
        (0, "interrupted actions, state read", [("flows.retention.flow", "complete_interrupted"), ("flows.retention.flow", "read_state"),
                                                 ("flows.retention.flow", "check_as_of")]),
        (0, "first pass: every time stamp (fitted, hours)", [("flows.retention.flow", "scan_partition")]),
        (0, "second pass: kept rows counted", [("flows.retention.flow", "count_kept")]),
        (0, "thinning: kept row groups read, filtered, written", [("flows.retention.flow", "thin_partition")]),
        (1, "write (kept rows, fsync, rename)", [("flows.retention.flow", "write_partition_pieces")]),
        (0, "intent and completion records", [("flows.retention.flow", "record"), ("flows.retention.flow", "complete")]),
    ],
}
IMPORTS = {
    "report": ("flows.cli", "flows.report.flow"),
    "retention": ("flows.cli", "flows.retention.flow"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    argv = [a for a in args.command if a != "--"]
    name = argv[0]
    t0 = cpu()
    from flows.common.allocator import retain_polars_memory

    retain_polars_memory()  # as the commands do, before polars is imported
    for mod in IMPORTS[name]:
        importlib.import_module(mod)
    SPENT["imports"] = cpu() - t0
    for _, label, targets in PHASES[name]:
        for mod, attr in targets:
            m = importlib.import_module(mod)
            fn = getattr(m, attr)
            setattr(m, attr, (_timed_gen if inspect.isgeneratorfunction(fn) else _timed)(label, fn))
    sys.argv = ["valvemon", *argv]
    try:
        importlib.import_module("flows.cli").main()
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise
    ru = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    own = ru.ru_utime + ru.ru_stime
    children = kids.ru_utime + kids.ru_stime
    print(f"\n`valvemon {name}`: CPU {own + children:.2f} s (this process {own:.2f}: user {ru.ru_utime:.2f} + system {ru.ru_stime:.2f}; "
          f"child processes {children:.2f})\n")
    print("| phase | CPU s |")
    print("|---|---:|")
    print(f"| imports | {SPENT['imports']:.2f} |")
    top = SPENT["imports"]
    for depth, label, _ in PHASES[name]:
        print(f"| {'&nbsp;&nbsp;' * 2 * depth}{label} | {SPENT[label]:.2f} |")
        top += SPENT[label] if depth == 0 else 0
    print(f"| the rest (CLI, configuration, Python between the phases) | {own - top:.2f} |")
    if children:
        print(f"| child processes (the pictures' pool) | {children:.2f} |")


if __name__ == "__main__":
    main()

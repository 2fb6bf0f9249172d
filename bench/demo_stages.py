"""Where ``valvemon demo``'s time goes: :func:`flows.demo.run_demo` with each stage wrapped.

    .venv/bin/python bench/demo_stages.py /tmp/demo-X     (a fresh warehouse folder)

Prints, per stage (run_simulate of the span, run_ingest, run_monitor, run_report), its start
and end since the start, its wall time, this process's CPU and that of the child processes
reaped meanwhile (the simulator's worker, the report's picture processes; the demo's side
process is reaped when the simulations end, so its CPU counts only in the total).
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import flows.demo as demo


def _cpu() -> tuple[float, float]:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def main(warehouse: Path) -> None:
    t_start = time.perf_counter()
    log: list[tuple[str, float, float, float]] = []

    def timed(name: str):
        fn = getattr(demo, name)

        def run(*args, **kwargs):
            t0, (own0, ch0) = time.perf_counter(), _cpu()
            try:
                return fn(*args, **kwargs)
            finally:
                own1, ch1 = _cpu()
                t1 = time.perf_counter()
                log.append((name, t1 - t0, own1 - own0, ch1 - ch0))
                print(f"{name} from {t0 - t_start:.1f} s to {t1 - t_start:.1f} s", flush=True)

        return run

    for name in ("run_simulate", "run_ingest", "run_monitor", "run_report"):
        setattr(demo, name, timed(name))
    demo.run_demo(warehouse, show_progress=False)
    for name, wall, own, children in log:
        print(f"{name:14s} wall {wall:7.1f} s  cpu here {own:7.1f} s  children {children:7.1f} s")
    own, children = _cpu()
    print(f"total wall {time.perf_counter() - t_start:.1f} s  cpu here {own:.1f} s  children {children:.1f} s")


if __name__ == "__main__":  # the demo spawns processes: they import this file as __mp_main__
    main(Path(sys.argv[1]))

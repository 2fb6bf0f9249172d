"""Start-up latency of the command line, before and after issue 15, side by side in one run.

"before" is a checkout of the commit before issue 15's items 1–3 (default 4c3ade9) with its own
environment (``make setup`` there); "after" is this checkout. Each command runs ``--repeats``
times on each side, once with ``PYTHONDONTWRITEBYTECODE=1`` (as on CI) and once without, and the
median wall time and the median CPU time (user + system, the command and its child processes:
the temporary Prefect server included) are printed as a Markdown table.

A fresh environment has no bytecode of its own: "before" (``uv sync`` without
``--compile-bytecode``) is measured with ``PYTHONDONTWRITEBYTECODE=1`` after its ``.pyc``
files are removed (every run compiles every module, as on CI), then without (the first run of
each command writes the ``.pyc`` files, and is not counted). Commands alternate between the two
sides, so both see the same load. "after" is measured as ``make setup`` left it
(bytecode compiled at install).

Commands: ``valvemon --help``; ``valvemon query "select 1"`` (on a warehouse that has a snapshot);
``valvemon monitor`` of one 10 s window of one valve (ingested once per side before); with
``--demo`` also ``valvemon demo`` (minutes before: once per side and mode).

    make setup && (cd /work/wt/latency-before && make setup)
    taskset -c 0 .venv/bin/python bench/latency.py --before /work/wt/latency-before --demo
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


class Side:
    """One checkout with its environment, its Prefect home and its warehouse."""

    def __init__(self, name: str, root: Path, work: Path):
        self.name, self.root = name, root
        self.exe = root / ".venv" / "bin" / "valvemon"
        if not self.exe.exists():
            raise SystemExit(f"{self.exe}: missing (run `make setup` in {root})")
        self.home = work / f"prefect-{name}"
        self.warehouse = work / f"wh-{name}"

    def env(self, no_bytecode: bool, warehouse: Path | None = None) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_") and k != "PYTHONDONTWRITEBYTECODE"}
        env |= {"PREFECT_HOME": str(self.home), "PREFECT_SERVER_ANALYTICS_ENABLED": "false", "VALVEMON_WAREHOUSE": str(warehouse or self.warehouse)}
        if no_bytecode:
            env["PYTHONDONTWRITEBYTECODE"] = "1"
        return env

    def run(self, args: list[str], no_bytecode: bool, *, warehouse: Path | None = None, check: bool = True) -> tuple[float, float]:
        """Wall and CPU seconds of one command."""
        c0, w0 = _children_cpu(), time.perf_counter()
        proc = subprocess.run([str(self.exe), *args], env=self.env(no_bytecode, warehouse), cwd=self.root, capture_output=True, text=True)
        wall, cpu = time.perf_counter() - w0, _children_cpu() - c0
        if check and proc.returncode != 0:
            raise SystemExit(f"{self.name}: valvemon {' '.join(args)} failed: {proc.stderr.strip()[-2000:]}")
        return wall, cpu

    def remove_bytecode(self) -> None:
        """Delete the ``.pyc`` files (numba's kernel cache beside them stays)."""
        for folder in [self.root / ".venv", *(self.root / p for p in ("flows", "transforms", "model", "schemas"))]:
            for pyc in folder.rglob("*.pyc"):
                pyc.unlink(missing_ok=True)


def prepare(side: Side, archive: Path) -> None:
    """The side's warehouse: the archive ingested, monitored, reported (so a snapshot exists)."""
    config = str(archive / "plant.toml")
    side.run(["ingest", "--config", config, str(archive / "exports")], no_bytecode=False)
    side.run(["monitor", "--config", config], no_bytecode=False)
    side.run(["report", "--config", config, "--detail", "0"], no_bytecode=False)


def commands(archive: Path) -> dict[str, list[str]]:
    return {
        "valvemon --help": ["--help"],
        'valvemon query "select 1"': ["query", "select 1"],
        "valvemon monitor (one 10 s window)": ["monitor", "--config", str(archive / "plant.toml")],
    }


def measure(side: Side, args: list[str], no_bytecode: bool, repeats: int) -> tuple[float, float]:
    runs = [side.run(args, no_bytecode) for _ in range(repeats)]
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, default=Path("/work/wt/latency-before"), help="checkout of the commit before (with its .venv)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--demo", action="store_true", help="also time `valvemon demo` (once per side and mode)")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder [default: a temporary one]")
    args = ap.parse_args()

    work = Path(args.work or tempfile.mkdtemp(prefix="valvemon-latency-"))
    work.mkdir(parents=True, exist_ok=True)
    sides = [Side("before", args.before.resolve(), work), Side("after", ROOT, work)]
    print(f"load before: {os.getloadavg()[0]:.1f} (1-min average, {os.cpu_count()} cores); affinity {sorted(os.sched_getaffinity(0))}", flush=True)

    archive = work / "archive"  # one valve, one 10 s window at 1 kHz (the simulator is the same on both sides)
    if not archive.exists():
        sides[1].run(["simulate", "--out", str(archive), "--n-valves", "1", "--days", "1", "--windows-per-day", "1",
                      "--format", "parquet", "--quiet"], no_bytecode=False)  # fmt: skip
    for side in sides:
        if not (side.warehouse / "snapshot" / "valvemon.duckdb").exists():
            prepare(side, archive)

    results: dict[tuple[str, str, bool], tuple[float, float]] = {}
    cmds = commands(archive)
    if args.demo:
        cmds["valvemon demo"] = ["demo"]

    def record(label: str, side: Side, no_bytecode: bool) -> None:
        args_ = cmds[label]
        if args_ == ["demo"]:
            wh = work / f"demo-{side.name}-{int(no_bytecode)}"
            shutil.rmtree(wh, ignore_errors=True)
            results[(label, side.name, no_bytecode)] = side.run(["demo"], no_bytecode, warehouse=wh)
        else:
            results[(label, side.name, no_bytecode)] = measure(side, args_, no_bytecode, args.repeats)
        w, c = results[(label, side.name, no_bytecode)]
        print(f"  {side.name:6} PYTHONDONTWRITEBYTECODE={'1' if no_bytecode else '-'}  {label:38} wall {w:7.2f} s  cpu {c:7.2f} s", flush=True)

    # 1. PYTHONDONTWRITEBYTECODE=1 in a fresh environment: "before" has no .pyc files at all
    sides[0].remove_bytecode()
    for label in cmds:
        for side in sides:
            record(label, side, True)
    # 2. without it: the first run of each command writes the .pyc files (not counted)
    for label, args_ in cmds.items():
        for side in sides:
            if args_ != ["demo"]:
                side.run(args_, no_bytecode=False)
            record(label, side, False)

    print(f"\nload after: {os.getloadavg()[0]:.1f}; median of {args.repeats} runs (demo: one run)\n")
    print("| command | PYTHONDONTWRITEBYTECODE | before: wall | after: wall | before: CPU | after: CPU | wall before / after |")
    print("|---|---|---|---|---|---|---|")
    for label in cmds:
        for no_bytecode in (True, False):
            bw, bc = results[(label, "before", no_bytecode)]
            aw, ac = results[(label, "after", no_bytecode)]
            print(f"| `{label}` | {'1' if no_bytecode else 'unset'} | {bw:.2f} s | {aw:.2f} s | {bc:.2f} s | {ac:.2f} s | {bw / aw:.1f}× |")


if __name__ == "__main__":
    sys.exit(main())

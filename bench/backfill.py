"""Benchmark of ``valvemon backfill``: a simulated archive → lake → fits, single process vs Dask.

Runs the command itself (``valvemon backfill --config ARCHIVE/plant.toml --exports
ARCHIVE/exports --from … --to … --quiet``) once per mode into a fresh warehouse under
``--work``, and measures from outside:

* wall time;
* CPU seconds of the whole process tree, split into the flow process (the command: planning,
  Prefect bookkeeping, every DuckDB write), the Dask workers and the Prefect API server — the
  tree is sampled every ``--sample-s`` with psutil and each process's last CPU times are kept,
  and the total is checked against ``getrusage(RUSAGE_CHILDREN)``;
* peak memory: the largest resident set of one process (``ru_maxrss``) and the peak of the
  tree's summed RSS (sampled);
* the 1-minute load average before and after (the machine is shared);
* rows: archive rows ingested (``ingest_manifest.rows_in``), lake rows monitored and windows
  and fits written (``backfill_progress``), hence rows per second.

Make the archive first (not in the repository), e.g. 2 valve-years of hourly 10 s windows:

    valvemon simulate --out /tmp/vm_bench/archive2vy --n-valves 2 --from 2025-01-01 --days 365 \\
        --format parquet --workers 1 --quiet
    .venv/bin/python bench/backfill.py --archive /tmp/vm_bench/archive2vy --from 2025-01-01 --to 2026-01-01 \\
        --work /tmp/vm_bench/work --modes single,dask2

``--db-scaling WAREHOUSE`` instead times the flow's database write of one weekly monitor unit
against ``edge_fits`` tables of growing size (the serial part of a large backfill):

    .venv/bin/python bench/backfill.py --db-scaling /tmp/vm_bench/work/wh-single --db-sizes 0,1000000,10000000

``--task-overhead N`` times N no-op tasks through the same bounded window instead (the fixed
price of a unit in the flow process and in the workers):

    .venv/bin/python bench/backfill.py --task-overhead 300 --modes threads2,dask2

Modes: ``single`` (tasks on one thread of the command's process, ``--concurrency 1``),
``threadsN`` (N threads), ``daskN`` (a temporary local Dask cluster of N one-thread worker
processes, ``--dask-workers N``). Results are printed as a Markdown table and appended to
``--json`` if given.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import duckdb
import psutil

ROOT = Path(__file__).resolve().parents[1]
VALVEMON = str(Path(sys.executable).with_name("valvemon"))


def mode_args(mode: str) -> list[str]:
    if mode == "single":
        return ["--concurrency", "1"]
    if mode.startswith("threads"):
        return ["--concurrency", mode.removeprefix("threads")]
    if mode.startswith("dask"):
        n = int(mode.removeprefix("dask"))
        return ["--dask-workers", str(n), "--concurrency", str(2 * n)]
    raise SystemExit(f"unknown mode {mode!r}")


class TreeSampler(threading.Thread):
    """Samples the CPU times and RSS of a process and its descendants."""

    def __init__(self, pid: int, every_s: float):
        super().__init__(daemon=True)
        self.root = psutil.Process(pid)
        self.every_s = every_s
        self.cpu: dict[int, tuple[str, float]] = {}
        self.peak_rss = 0
        self.stop = threading.Event()

    @staticmethod
    def kind(p: psutil.Process, root_pid: int) -> str:
        if p.pid == root_pid:
            return "flow"
        try:
            cmd = " ".join(p.cmdline())
        except psutil.Error:
            return "other"
        if "uvicorn" in cmd or "prefect.server" in cmd or "server start" in cmd:
            return "api"
        if "multiprocessing" in cmd or "distributed" in cmd or "dask" in cmd:
            return "workers"
        return "other"

    def sample(self) -> None:
        try:
            procs = [self.root, *self.root.children(recursive=True)]
        except psutil.Error:
            return
        rss = 0
        for p in procs:
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    rss += p.memory_info().rss
                    kind = self.cpu.get(p.pid, (None, 0))[0] or self.kind(p, self.root.pid)
                    self.cpu[p.pid] = (kind, t.user + t.system)
            except psutil.Error:
                continue
        self.peak_rss = max(self.peak_rss, rss)

    def run(self) -> None:
        while not self.stop.is_set():
            self.sample()
            self.stop.wait(self.every_s)

    def by_kind(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for kind, cpu in self.cpu.values():
            out[kind] = out.get(kind, 0.0) + cpu
        return out


def counts(warehouse: Path) -> dict:
    con = duckdb.connect(str(warehouse / "valvemon.duckdb"), read_only=True)
    try:
        q = lambda sql: con.execute(sql).fetchone()  # noqa: E731
        rows_in, files = q("SELECT coalesce(sum(rows_in), 0), count(*) FROM ingest_manifest")
        lake_rows, windows, units = q("SELECT coalesce(sum(rows_read), 0), coalesce(sum(windows), 0), count(*) FROM backfill_progress WHERE unit_kind = 'monitor'")
        fits, ok = q("SELECT count(*), count(*) FILTER (status = 'ok') FROM edge_fits")
    finally:
        con.close()
    lake_bytes = sum(p.stat().st_size for p in (warehouse / "lake").rglob("*.parquet"))
    return {"archive_rows": int(rows_in), "files": int(files), "lake_rows": int(lake_rows), "windows": int(windows),
            "monitor_units": int(units), "fits": int(fits), "fits_ok": int(ok), "lake_mb": lake_bytes / 1e6}  # fmt: skip


def run_mode(mode: str, args) -> dict:
    warehouse = Path(args.work) / f"wh-{mode}"
    archive = Path(args.archive)
    if args.phase == "monitor":  # redo the monitoring of a kept warehouse (--force, no exports)
        if not warehouse.exists():
            raise SystemExit(f"{warehouse}: no warehouse of an earlier --keep run")
        inputs = ["--force"]
    else:
        if warehouse.exists():
            shutil.rmtree(warehouse)
        inputs = ["--exports", str(archive / "exports")]
    cmd = [
        VALVEMON, "backfill", "--config", str(archive / "plant.toml"), *inputs,
        "--from", args.start, "--to", args.end, "--warehouse", str(warehouse), "--unit-days", str(args.unit_days),
        "--quiet", *mode_args(mode),
    ]  # fmt: skip
    env = dict(os.environ, PREFECT_HOME=str(Path(args.work) / f"prefect-{mode}"), PREFECT_SERVER_ANALYTICS_ENABLED="false")
    env.pop("PREFECT_API_URL", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()[0]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sampler = TreeSampler(proc.pid, args.sample_s)
    sampler.start()
    out, err = proc.communicate()
    wall = time.monotonic() - t0
    sampler.stop.set()
    sampler.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    load1 = os.getloadavg()[0]
    if proc.returncode != 0:
        raise SystemExit(f"{mode}: exit {proc.returncode}\n{err[-3000:]}")
    cpu_rusage = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    c = counts(warehouse)
    kinds = sampler.by_kind()
    summary = out.strip().splitlines()[-1] if out.strip() else ""
    m = re.search(r" in ([\d,.]+) s$", summary)
    return {
        "mode": mode, "phase": args.phase, "command": " ".join(cmd[1:]), "wall_s": wall, "cpu_s": cpu_rusage, "cpu_sampled": kinds,
        "max_rss_mb": after.ru_maxrss / 1024, "peak_tree_rss_mb": sampler.peak_rss / 1e6, "load_before": load0,
        "load_after": load1, "summary": summary, "flow_s": float(m.group(1).replace(",", "")) if m else None, **c,
    }  # fmt: skip


def db_scaling(src: Path, work: Path, sizes: list[int], valves: int = 500, repeats: int = 20) -> list[dict]:
    """Cost of the flow's write of monitor units (``flows.orchestration.backfill.store_units``: delete each
    unit's span, insert its fits and selection rows and its progress row, a fresh connection and
    one transaction for 1 or 32 units) against ``edge_fits`` already holding N rows (time-major, ``valves`` valves, one
    week of hourly windows per valve and unit, copied from a real unit of ``src``)."""
    from datetime import timedelta

    import polars as pl

    from flows.common.warehouse_db import connect, insert_frame, query_frame
    from flows.monitor.flow import ensure_monitor_tables
    from flows.orchestration.backfill import MonitorUnit, _progress_frame, ensure_backfill_tables, store_units

    with connect(src, read_only=True) as con:
        t0 = query_frame(con, "SELECT min(window_start) AS t FROM edge_fits")["t"][0]
        fits = query_frame(con, "SELECT * FROM edge_fits WHERE valve_id = 'V001' AND window_start < ? ORDER BY ALL", [t0 + timedelta(days=7)])
        sel = query_frame(con, "SELECT * FROM selection_stats WHERE valve_id = 'V001' AND window_start < ? ORDER BY ALL", [t0 + timedelta(days=7)])
    week = timedelta(days=7)

    def unit_rows(v: int, w: int) -> tuple[pl.DataFrame, pl.DataFrame]:
        shift = [pl.col("window_start") + w * week, pl.lit(f"V{v:04d}").alias("valve_id")]
        f = fits.with_columns(*shift, pl.col("window_end") + w * week)
        return f, sel.with_columns(*shift)

    out = []
    for size in sizes:
        wh = work / f"dbscale-{size}"
        shutil.rmtree(wh, ignore_errors=True)
        with connect(wh) as con:
            ensure_monitor_tables(con)
            ensure_backfill_tables(con)
        n_units = size // fits.height
        batch_f, batch_s, done = [], [], 0
        for k in range(n_units):
            f, s_ = unit_rows(k % valves, k // valves)
            batch_f.append(f)
            batch_s.append(s_)
            if len(batch_f) * fits.height >= 500_000 or k == n_units - 1:
                with connect(wh) as con:
                    insert_frame(con, "edge_fits", pl.concat(batch_f))
                    insert_frame(con, "selection_stats", pl.concat(batch_s))
                done += len(batch_f)
                batch_f, batch_s = [], []
        w_next = n_units // valves + 1
        row = {}
        for batch in (1, 32):
            times = []
            for r in range(repeats):
                items, prog = [], []
                for b in range(batch):
                    f, s_ = unit_rows((r * batch + b) % valves, w_next + (r * batch + b) // valves)
                    unit = MonitorUnit(f["valve_id"][0], f["window_start"].min(), f["window_start"].min() + week)
                    items.append((unit, f, s_))
                    prog.append({"unit_kind": "monitor", "unit_key": unit.key, "valve_id": unit.valve_id, "run_id": "bench", "finished_at": unit.start})
                t = time.perf_counter()
                store_units(wh, items, _progress_frame(prog))
                times.append((time.perf_counter() - t) / batch)
            w_next += repeats * batch // valves + 1
            times.sort()
            row[f"batch{batch}_median_ms"], row[f"batch{batch}_best_ms"] = 1e3 * times[len(times) // 2], 1e3 * times[0]
        with connect(wh, read_only=True) as con:
            n = query_frame(con, "SELECT count(*) AS n FROM edge_fits")["n"][0]
            m = query_frame(con, "SELECT count(*) AS n FROM selection_stats")["n"][0]
        row |= {"edge_fits_rows": n, "selection_rows": m, "unit_fits": fits.height, "unit_selection": sel.height,
                "db_mb": (wh / "valvemon.duckdb").stat().st_size / 1e6}  # fmt: skip
        print(json.dumps(row), flush=True)
        out.append(row)
        shutil.rmtree(wh, ignore_errors=True)
    print()
    print("| edge_fits rows | selection_stats rows | DB MB | per unit, one unit per transaction (median / best) | per unit, 32 units per transaction (median / best) |")
    print("|---:|---:|---:|---|---|")
    for r in out:
        print(f"| {r['edge_fits_rows']:,} | {r['selection_rows']:,} | {r['db_mb']:,.0f} | {r['batch1_median_ms']:.0f} / {r['batch1_best_ms']:.0f} ms "
              f"| {r['batch32_median_ms']:.1f} / {r['batch32_best_ms']:.1f} ms |")
    return out


def task_overhead(n: int, modes: list[str]) -> list[dict]:
    """CPU cost of one Prefect task (a no-op, submitted through the backfill's bounded window)
    in the flow process and in the Dask workers: the fixed price of a unit."""
    from prefect import flow, task

    from flows.orchestration.backfill import Window
    from flows.orchestration.dask_runner import cluster_threads, local_cluster, shared_api, task_runner

    @task(name="noop", persist_result=False)
    def noop(i: int) -> int:
        return i

    @flow(name="bench-task-overhead", persist_result=False)
    def run(n: int, limit: int) -> None:
        w = Window(limit, lambda tag, r: None, lambda tag, exc: None)
        for i in range(n):
            w.submit(i, noop, i)
        w.drain()

    def worker_cpu(address) -> float:
        import distributed

        with distributed.Client(address, set_as_default=False) as c:
            usage = c.run(lambda: (lambda r: r.ru_utime + r.ru_stime)(resource.getrusage(resource.RUSAGE_SELF)))
        return sum(usage.values())

    out = []
    for mode in modes:
        with shared_api():
            if mode.startswith("dask"):
                with local_cluster(int(mode.removeprefix("dask"))) as address:
                    limit = 2 * cluster_threads(address)
                    f = run.with_options(task_runner=task_runner(limit, address))
                    f(n=20, limit=limit)  # warm up: imports in the workers
                    w0, p0, t0 = worker_cpu(address), time.process_time(), time.monotonic()
                    f(n=n, limit=limit)
                    w1, p1, t1 = worker_cpu(address), time.process_time(), time.monotonic()
            else:
                limit = int(mode.removeprefix("threads") or 2)
                f = run.with_options(task_runner=task_runner(limit))
                f(n=20, limit=limit)
                w0 = w1 = 0.0
                p0, t0 = time.process_time(), time.monotonic()
                f(n=n, limit=limit)
                p1, t1 = time.process_time(), time.monotonic()
        row = {"mode": mode, "tasks": n, "wall_ms_per_task": 1e3 * (t1 - t0) / n, "flow_cpu_ms_per_task": 1e3 * (p1 - p0) / n,
               "worker_cpu_ms_per_task": 1e3 * (w1 - w0) / n, "load": os.getloadavg()[0]}  # fmt: skip
        print(json.dumps(row), flush=True)
        out.append(row)
    print()
    print("| runner | tasks | wall per task | flow-process CPU per task | worker CPU per task | 1-min load |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in out:
        print(f"| {r['mode']} | {r['tasks']} | {r['wall_ms_per_task']:.0f} ms | {r['flow_cpu_ms_per_task']:.0f} ms | {r['worker_cpu_ms_per_task']:.0f} ms | {r['load']:.1f} |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--archive", help="A `valvemon simulate` archive (plant.toml, exports/).")
    ap.add_argument("--from", dest="start")
    ap.add_argument("--to", dest="end")
    ap.add_argument("--work", default="/tmp/vm_bench/work", help="Warehouses are made here (one per mode).")
    ap.add_argument("--modes", default="single,dask2")
    ap.add_argument("--unit-days", type=float, default=7.0)
    ap.add_argument("--sample-s", type=float, default=1.0)
    ap.add_argument("--json", help="Append the results (one JSON object per line) to this file.")
    ap.add_argument("--keep", action="store_true", help="Keep the warehouses.")
    ap.add_argument("--phase", choices=("all", "monitor"), default="all",
                    help="all: archive → lake → fits into a fresh warehouse; monitor: redo the fits of a kept warehouse (--force).")
    ap.add_argument("--db-scaling", metavar="WAREHOUSE", help="Instead: time the flow's write of one monitor unit against growing tables (rows copied from this warehouse's fits).")
    ap.add_argument("--db-sizes", default="0,1000000,10000000", help="edge_fits rows already there, for --db-scaling.")
    ap.add_argument("--task-overhead", type=int, metavar="N", help="Instead: the CPU price of N no-op Prefect tasks per --modes (threadsN, daskN).")
    args = ap.parse_args()
    Path(args.work).mkdir(parents=True, exist_ok=True)
    if args.task_overhead:
        task_overhead(args.task_overhead, args.modes.split(","))
        return
    if args.db_scaling:
        db_scaling(Path(args.db_scaling), Path(args.work), [int(x) for x in args.db_sizes.split(",")])
        return
    if not (args.archive and args.start and args.end):
        ap.error("--archive, --from and --to are required (or --db-scaling)")
    results = []
    for mode in args.modes.split(","):
        r = run_mode(mode, args)
        results.append(r)
        print(json.dumps(r), flush=True)
        if args.json:
            with open(args.json, "a") as fh:
                fh.write(json.dumps(r) + "\n")
        if not args.keep and args.phase == "all":
            shutil.rmtree(Path(args.work) / f"wh-{mode}", ignore_errors=True)
    print()
    print(f"phase: {args.phase}")
    print("| mode | wall s | of which in the flow s | CPU s (tree) | flow / workers / API CPU s | archive rows / wall s | lake rows / wall s | lake rows / CPU s | windows | fits | peak RSS one process MB | peak tree RSS MB | load 1-min before → after |")
    print("|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in results:
        k = r["cpu_sampled"]
        print(
            f"| {r['mode']} | {r['wall_s']:,.0f} | {r['flow_s'] or 0:,.0f} | {r['cpu_s']:,.0f} | {k.get('flow', 0):,.0f} / {k.get('workers', 0):,.0f} / {k.get('api', 0):,.0f} "
            f"| {(str(round(r['archive_rows'] / r['wall_s'] / 1e6, 2)) + ' M') if r['phase'] == 'all' else '—'} | {r['lake_rows'] / r['wall_s'] / 1e6:,.2f} M | {r['lake_rows'] / r['cpu_s'] / 1e6:,.2f} M "
            f"| {r['windows']:,} | {r['fits']:,} | {r['max_rss_mb']:,.0f} | {r['peak_tree_rss_mb']:,.0f} | {r['load_before']:.1f} → {r['load_after']:.1f} |"
        )


if __name__ == "__main__":
    main()

"""Benchmark of lake → opening-area points → fits on a fleet archive, side by side with a
pandas + scipy baseline of the same steps (``bench/monitor_baseline.py``).

Prepare the data once (a fleet of hourly 10 s windows; 10 valves × 10 days = 24 M lake rows):

    valvemon simulate --out /tmp/valvemon_bench/fleet --n-valves 10 --days 10 --format parquet --seed 7 --quiet
    valvemon ingest --config /tmp/valvemon_bench/fleet/plant.toml --warehouse /tmp/valvemon_bench/wh /tmp/valvemon_bench/fleet/exports

then

    .venv/bin/python bench/monitor_pipeline.py --config /tmp/valvemon_bench/fleet/plant.toml \\
        --warehouse /tmp/valvemon_bench/wh [--baseline-valves N] [--json out.json]

Three measurements, each in a fresh process pinned to one CPU (polars and numba limited to one
thread), so that CPU seconds are per-core figures and the peak resident memory is the step's own:

* ``full``: ``flows.monitor.flow.run_monitor`` for every valve (the production path: lake reading in
  gap-aligned chunks, baselines from the warehouse, steps 2–4b with the leakage refinement,
  edge_fits and selection_stats replaced in DuckDB), with the time split into its stages;
* ``transforms``: the same chunks already in memory, through ``flows.monitor.flow.monitor_rows``
  (steps 2–4b only);
* ``baseline``: the same chunks (as pandas frames) through ``monitor_pandas``.

``--from``/``--to`` limit the ``full`` step to a span, as ``valvemon monitor --from --to`` does
(one day: what a nightly run reads; ``--steps full``).

Each process first warms up on the first ten minutes of one valve's first day (numba cache loads, imports; a
snapshot or ten minutes of a continuous recording, so the peak memory is the run's own), not timed.
Rows/s are lake rows per CPU second of the process (all its threads) and per wall second.
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def _pin() -> str:
    if hasattr(os, "sched_setaffinity"):
        cpu = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {cpu})
        return f"cpu {cpu}"
    return "no"


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Clock:
    """CPU and wall seconds per stage."""

    def __init__(self):
        self.cpu: dict[str, float] = {}
        self.wall: dict[str, float] = {}

    def wrap(self, name, f):
        def timed(*a, **k):
            c, w = time.process_time(), time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                self.cpu[name] = self.cpu.get(name, 0.0) + time.process_time() - c
                self.wall[name] = self.wall.get(name, 0.0) + time.perf_counter() - w

        return timed

    def wrap_gen(self, name, f):
        def timed(*a, **k):
            it = f(*a, **k)
            while True:
                c, w = time.process_time(), time.perf_counter()
                try:
                    item = next(it)
                except StopIteration:
                    return
                finally:
                    self.cpu[name] = self.cpu.get(name, 0.0) + time.process_time() - c
                    self.wall[name] = self.wall.get(name, 0.0) + time.perf_counter() - w
                yield item

        return timed


def _chunks(config, warehouse: Path, valve_ids):
    """The production chunks (flows.monitor.flow.lake_chunks) of every valve: [(valve, rows)]."""
    import flows.monitor.flow as fm

    out = []
    for vid in valve_ids:
        valve = config.valve(vid)
        params = fm.plant_monitor_params(config, valve)
        gap_s = params.gap_limit_periods * params.sample_period_s
        out += [(vid, rows) for rows in fm.lake_chunks(warehouse, vid, gap_s, None, None, window_s=params.window_s)]
    return out


def _warm_rows(config, warehouse: Path):
    from datetime import timedelta

    import flows.monitor.flow as fm
    from flows.common.lake import list_partitions, read_lake

    vid = config.valves[0].id
    _, day, _ = list_partitions(warehouse, [vid])[0]
    from datetime import datetime, timezone

    lo = datetime(day.year, day.month, day.day, tzinfo=timezone.utc)
    rows = read_lake(warehouse, [vid], lo, lo + timedelta(minutes=10)).collect()
    valve = config.valve(vid)
    return valve, fm.plant_monitor_params(config, valve), rows


def step_full(config_path: Path, warehouse: Path, valve_ids, start: str | None = None, end: str | None = None) -> dict:
    import flows.monitor.flow as fm
    from flows.common.config import load_plant_config

    pinned = _pin()
    config = load_plant_config(config_path)
    valve, params, rows = _warm_rows(config, warehouse)
    fm.monitor_rows(valve, params, fm.ensure_baselines(valve, params, warehouse), rows)
    fm.run_monitor(config_path, warehouse, [valve.id], end=rows["timestamp_utc"][0].isoformat())  # opens DuckDB, no windows
    clock = _Clock()
    fm.lake_chunks = clock.wrap_gen("read lake (parquet → polars, gap-aligned chunks)", fm.lake_chunks)
    fm.ensure_baselines = clock.wrap("baselines (from DuckDB)", fm.ensure_baselines)
    fm.monitor_rows = clock.wrap("steps 2–4b (transforms.monitor)", fm.monitor_rows)
    fm._fits_table = clock.wrap("fits → table rows", fm._fits_table)
    fm.store_spans = clock.wrap("store (DuckDB delete + insert)", fm.store_spans)
    c, w = time.process_time(), time.perf_counter()
    reports = fm.run_monitor(config_path, warehouse, valve_ids, start, end)
    cpu, wall = time.process_time() - c, time.perf_counter() - w
    rows_read = sum(r.rows_read for r in reports)
    return {
        "step": "full", "pinned": pinned, "rows": rows_read, "cpu_s": cpu, "wall_s": wall, "peak_mb": _peak_mb(),
        "windows": sum(r.windows for r in reports), "fits_ok": sum(r.fits_ok for r in reports),
        "stages_cpu_s": clock.cpu, "stages_wall_s": clock.wall,
    }  # fmt: skip


def step_transforms(config_path: Path, warehouse: Path, valve_ids) -> dict:
    import flows.monitor.flow as fm
    from flows.common.config import load_plant_config

    pinned = _pin()
    config = load_plant_config(config_path)
    valve, params, rows = _warm_rows(config, warehouse)
    fm.monitor_rows(valve, params, fm.ensure_baselines(valve, params, warehouse), rows)
    chunks = _chunks(config, warehouse, valve_ids)
    base = {}
    for vid in valve_ids:
        v = config.valve(vid)
        p = fm.plant_monitor_params(config, v)
        base[vid] = (v, p, fm.ensure_baselines(v, p, warehouse))
    n = sum(r.height for _, r in chunks)
    c, w = time.process_time(), time.perf_counter()
    ok = 0
    for vid, r in chunks:
        v, p, b = base[vid]
        res = fm.monitor_rows(v, p, b, r)
        ok += int((res.fits["status"] == "ok").sum())
    cpu, wall = time.process_time() - c, time.perf_counter() - w
    return {"step": "transforms", "pinned": pinned, "rows": n, "cpu_s": cpu, "wall_s": wall, "peak_mb": _peak_mb(), "fits_ok": ok}


def step_baseline(config_path: Path, warehouse: Path, valve_ids) -> dict:
    from monitor_baseline import monitor_pandas

    import flows.monitor.flow as fm
    from flows.common.config import load_plant_config

    pinned = _pin()
    config = load_plant_config(config_path)
    valve, params, rows = _warm_rows(config, warehouse)
    cols = ["timestamp_utc", "ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m"]
    chunks = [(vid, r.select(cols).to_pandas()) for vid, r in _chunks(config, warehouse, valve_ids)]
    setup = {}
    for vid in valve_ids:
        v = config.valve(vid)
        p = fm.plant_monitor_params(config, v)
        b = fm.ensure_baselines(v, p, warehouse)
        setup[vid] = (
            p,
            {e: (x.characteristic.knots_u_m, x.characteristic.values_m2) for e, x in b.items()},
            {e: (x.leakage.knots_u_m, x.leakage.values_m2) for e, x in b.items()},
        )
    p0, b0, l0 = setup[valve.id]
    monitor_pandas(rows.head(20_000).select(cols).to_pandas(), p0, b0, l0)  # warm-up
    n = sum(len(r) for _, r in chunks)
    c, w = time.process_time(), time.perf_counter()
    fits = []
    for vid, r in chunks:
        p, b, lk = setup[vid]
        f = monitor_pandas(r, p, b, lk)
        f["valve_id"] = vid
        fits.append(f)
    cpu, wall = time.process_time() - c, time.perf_counter() - w
    import pandas as pd

    allf = pd.concat(fits)
    out = Path(tempfile.gettempdir()) / f"valvemon_bench_baseline_fits_{os.getpid()}.parquet"
    allf.to_parquet(out)
    return {"step": "baseline", "pinned": pinned, "rows": n, "cpu_s": cpu, "wall_s": wall, "peak_mb": _peak_mb(),
            "fits_ok": int((allf["status"] == "ok").sum()), "fits_path": str(out)}  # fmt: skip


def _agreement(warehouse: Path, fits_path: str, valve_ids) -> dict:
    """Baseline vs production fits, per (valve, window, edge) where both are ok."""
    import polars as pl

    from flows.common.warehouse_db import connect, query_frame

    with connect(warehouse, read_only=True) as con:
        ours = query_frame(con, "SELECT valve_id, edge, window_start, status, alpha_hat, x_hat_mm FROM edge_fits")
    base = pl.read_parquet(fits_path).with_columns(pl.col("window_start").dt.cast_time_unit("us").dt.replace_time_zone("UTC"))
    j = ours.filter(pl.col("valve_id").is_in(valve_ids)).join(base, on=["valve_id", "edge", "window_start"], suffix="_b")
    both = j.filter((pl.col("status") == "ok") & (pl.col("status_b") == "ok"))
    da = (both["alpha_hat"] - both["alpha_hat_b"]).abs()
    dx = (both["x_hat_mm"] - both["x_hat_m"] * 1e3).abs() * 1e3
    return {
        "populations": j.height, "same_status": int((j["status"] == j["status_b"]).sum()), "both_ok": both.height,
        "within_1e-3_and_1um": int(((da < 1e-3) & (dx < 1.0)).sum()), "median_dalpha": float(da.median()),
        "median_dx_um": float(dx.median()), "max_dx_um": float(dx.max()),
    }  # fmt: skip


STEPS = {"full": step_full, "transforms": step_transforms, "baseline": step_baseline}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, required=True)
    ap.add_argument("--warehouse", type=Path, required=True)
    ap.add_argument("--baseline-valves", type=int, default=None, help="run the baseline on the first N valves only")
    ap.add_argument("--steps", default="full,transforms,baseline")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--from", dest="start", default=None, help="full step only: monitor the windows from this instant (as `valvemon monitor --from`)")
    ap.add_argument("--to", dest="end", default=None, help="full step only: … up to this instant (a nightly run: one day)")
    ap.add_argument("--step", choices=tuple(STEPS), help=argparse.SUPPRESS)
    ap.add_argument("--valves", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)

    from flows.common.config import load_plant_config

    config = load_plant_config(a.config)
    if a.step:  # a child process: one measurement, JSON on stdout
        valve_ids = a.valves.split(",") if a.valves else [v.id for v in config.valves]
        span = {"start": a.start, "end": a.end} if a.step == "full" else {}
        print(json.dumps(STEPS[a.step](a.config, a.warehouse, valve_ids, **span)))
        return 0

    all_ids = [v.id for v in config.valves]
    results = {"load_average_start": os.getloadavg()}
    for step in a.steps.split(","):
        ids = all_ids[: a.baseline_valves] if (step == "baseline" and a.baseline_valves) else all_ids
        cmd = [sys.executable, __file__, "--config", str(a.config), "--warehouse", str(a.warehouse), "--step", step, "--valves", ",".join(ids)]
        cmd += [f"--from={a.start}"] * bool(a.start) + [f"--to={a.end}"] * bool(a.end)
        out = subprocess.run(cmd, check=True, capture_output=True, text=True)
        results[step] = json.loads(out.stdout.strip().splitlines()[-1])
        r = results[step]
        print(f"{step:10s} {r['rows']:>12,} rows  CPU {r['cpu_s']:7.2f} s ({r['rows'] / r['cpu_s'] / 1e6:5.2f} M rows/s)  "
              f"wall {r['wall_s']:7.2f} s ({r['rows'] / r['wall_s'] / 1e6:5.2f} M rows/s)  peak RSS {r['peak_mb']:,.0f} MB", flush=True)  # fmt: skip
        if step == "full":
            for k, v in sorted(r["stages_cpu_s"].items(), key=lambda kv: -kv[1]):
                print(f"    {k:52s} CPU {v:7.2f} s ({100 * v / r['cpu_s']:4.1f} %)  wall {r['stages_wall_s'][k]:7.2f} s")
            rest = r["cpu_s"] - sum(r["stages_cpu_s"].values())
            print(f"    {'other (config, bookkeeping)':52s} CPU {rest:7.2f} s ({100 * rest / r['cpu_s']:4.1f} %)")
    results["load_average_end"] = os.getloadavg()
    if "baseline" in results:
        b = results["baseline"]
        rb = b["rows"] / b["cpu_s"]
        for step in ("transforms", "full"):
            if step in results:
                r = results[step]
                print(f"speed-up over the baseline ({step}): {r['rows'] / r['cpu_s'] / rb:5.1f}x per CPU second")
        if "full" in results:
            results["agreement"] = _agreement(a.warehouse, b["fits_path"], all_ids[: a.baseline_valves] if a.baseline_valves else all_ids)
            print("agreement with the production fits:", results["agreement"])
    print(f"load average (1 min) at start {results['load_average_start'][0]:.1f}, at end {results['load_average_end'][0]:.1f}; CPUs {os.cpu_count()}")
    if a.json:
        a.json.write_text(json.dumps(results, indent=2, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The nightly ``valvemon report`` and every ``sql/`` view on a warehouse holding a long history of
continuously recorded valves (a window a minute, 4 edges: 5,760 ``edge_fits`` rows a valve-day).

A bench warehouse of VALVES valves × DAYS days is written straight into ``edge_fits`` by DuckDB's
own generators (``range``, ``random``; no Python loop): every window ok, α̂, x̂ and e scattered as
one-minute windows scatter (docs/monitoring.md, "The detector's clock") around a slow wear
drift, every edge of every valve on a nominal baseline. Then the night is replayed: one more day
of fits is inserted (what the nightly monitor adds) and ``valvemon report`` runs, pinned to one
core (``taskset -c CORE``), under ``/usr/bin/time`` (CPU = user + sys, peak resident memory);
then every view is read whole from the published snapshot, each in its own process, the same way.
The first report on the history builds the daily summaries of all of it (``flows/report/summaries.py``);
the night's closes one day.
The bench warehouse is deleted at the end (``--keep`` keeps it).

    .venv/bin/python bench/report_scale.py --valves 500 --days 7 [--core 1] [--views] [--detail 20] [--tmp DIR] [--src DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.publish import plant  # noqa: E402
from flows.common.warehouse_db import connect, db_path  # noqa: E402
from flows.monitor.flow import ensure_monitor_tables  # noqa: E402
from flows.report.views import discover_views, snapshot_path  # noqa: E402

WINDOWS_PER_DAY = 1440
START = "2025-01-01 00:00:00+00"


def add_days(warehouse: Path, valves: int, first_day: int, days: int) -> int:
    """Insert ``days`` days of one-minute fits of every valve from day ``first_day`` on, in SQL."""
    with connect(warehouse) as con:
        ensure_monitor_tables(con)
        before = con.execute("SELECT count(*) FROM edge_fits").fetchone()[0]
        con.execute(f"""
            INSERT INTO edge_fits BY NAME
            WITH windows AS (
                SELECT printf('V%03d', v) AS valve_id, k,
                       TIMESTAMPTZ '{START}' + to_microseconds(k * 60000000) AS window_start,
                       k / 60.0 AS operating_hours
                FROM range(1, {valves} + 1) AS a(v),
                     range({first_day} * {WINDOWS_PER_DAY}, {first_day + days} * {WINDOWS_PER_DAY}) AS b(k)
            ),
            fits AS (
                SELECT windows.*, edge,
                       1.0 + 8e-6 * operating_hours + 2e-4 * (random() - 0.5) AS alpha_hat,
                       0.2 + 2.2e-4 * operating_hours + 8e-3 * (random() - 0.5) AS x_hat_pct,
                       0.1 + 4e-3 * (random() - 0.5) AS e_mm2
                FROM windows, (VALUES ('s1'), ('1r'), ('s2'), ('2r')) AS e(edge)
            )
            SELECT valve_id, edge, window_start, window_start + INTERVAL 59 SECOND AS window_end, operating_hours,
                   19000 AS n_points, alpha_hat, x_hat_pct * 0.035 AS x_hat_mm, x_hat_pct, e_mm2, 'ok' AS status,
                   alpha_hat - 4e-4 AS alpha_ci_low, alpha_hat + 4e-4 AS alpha_ci_high,
                   x_hat_pct * 0.035 - 6e-4 AS x_hat_ci_low_mm, x_hat_pct * 0.035 + 6e-4 AS x_hat_ci_high_mm,
                   0.3 AS u_min_mm, 2.9 AS u_max_mm, 1 AS baseline_version, now() AS monitored_at,
                   1.0 + 0.2 * (random() - 0.5) AS leak_scale, 0.6 AS leak_scale_ci_low, 1.4 AS leak_scale_ci_high
            FROM fits
        """)
        con.execute("CHECKPOINT")
        return con.execute("SELECT count(*) FROM edge_fits").fetchone()[0] - before


def timed(cmd: list[str], core: int, src: str | None = None) -> dict:
    """Run ``cmd`` pinned to ``core`` under /usr/bin/time: wall, CPU (user + sys, its picture
    processes included), peak RSS. ``src``: a checkout whose code runs instead (``PYTHONPATH``)."""
    full = ["taskset", "-c", str(core), "/usr/bin/time", "-f", "TIME %e %U %S %M", *cmd]
    env = os.environ | ({"PYTHONPATH": src} if src else {})
    p = subprocess.run(full, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{p.stderr[-3000:]}")
    wall, user, sys_, rss_kb = p.stderr.strip().splitlines()[-1].split()[1:]
    return {"wall_s": float(wall), "cpu_s": float(user) + float(sys_), "peak_mb": int(rss_kb) / 1024}


def read_view(snapshot: Path, name: str) -> None:
    """Read view ``name`` whole (every column of every row hashed, so nothing is pruned)."""
    import duckdb

    con = duckdb.connect(str(snapshot), read_only=True)
    n = con.execute(f"SELECT count(*), sum(hash(COLUMNS(*))) FROM {name}").fetchone()[0]
    print(f"{name}: {n} rows")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--valves", type=int, default=500)
    ap.add_argument("--days", type=int, default=7, help="days of history before the night")
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--views", action="store_true", help="also read every view from the snapshot")
    ap.add_argument("--detail", type=int, default=20, help="valves pictured by the report (its --detail)")
    ap.add_argument("--src", help="run the report of this checkout (e.g. `git archive main | tar -x -C DIR`) instead: the before")
    ap.add_argument("--tmp", default=os.environ.get("BENCH_TMP"), help="folder for the bench warehouse")
    ap.add_argument("--keep", action="store_true", help="keep the bench warehouse")
    ap.add_argument("--read-view", nargs=2, metavar=("SNAPSHOT", "VIEW"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.read_view:
        read_view(Path(a.read_view[0]), a.read_view[1])
        return
    tmp = Path(tempfile.mkdtemp(prefix="valvemon-report-scale-", dir=a.tmp))
    try:
        config, wh = plant(tmp, a.valves), tmp / "wh"
        t0 = time.perf_counter()
        history = add_days(wh, a.valves, 0, a.days)
        write_s = time.perf_counter() - t0
        report = [str(ROOT / ".venv" / "bin" / "valvemon"), "report", "--config", str(config), "--warehouse", str(wh), "--detail", str(a.detail)]
        first = timed(report, a.core, a.src)  # the report that finds the history (a first run, or after an upgrade)
        tonight = add_days(wh, a.valves, a.days, 1)
        night = timed(report, a.core, a.src)  # the nightly report after one more day
        size_gb = db_path(wh).stat().st_size / 1e9
        print(f"load {os.getloadavg()[0]:.1f} (1-min average, 2 cores); {a.valves} valves; history {a.days} d = "
              f"{history:,} edge_fits rows written in {write_s:.0f} s; database {size_gb:.2f} GB; tonight {tonight:,} rows")
        print("| step | rows in edge_fits | wall | CPU | peak memory |")
        print("|---|---|---|---|---|")
        print(f"| report, first run on the history | {history:,} | {first['wall_s']:.1f} s | {first['cpu_s']:.1f} s | {first['peak_mb']:,.0f} MB |")
        print(f"| report, the night after (+1 day) | {history + tonight:,} | {night['wall_s']:.1f} s | {night['cpu_s']:.1f} s | {night['peak_mb']:,.0f} MB |")
        if a.views:
            for name in discover_views():
                r = timed([sys.executable, __file__, "--read-view", str(snapshot_path(wh)), name], a.core)
                print(f"| view `{name}` | {history + tonight:,} | {r['wall_s']:.1f} s | {r['cpu_s']:.1f} s | {r['peak_mb']:,.0f} MB |")
    finally:
        if a.keep:
            print(f"kept: {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

"""Cost of publishing the read-only snapshot (``flows.report.publish``), which every writing command
now ends with, on warehouses of realistic size.

A warehouse of VALVES valves × DAYS days × WINDOWS windows a day is filled with synthetic rows
(``edge_fits``: 4 edges a window; ``selection_stats``: 5 rules × 4 edges a window; a nominal
baseline per edge), then :func:`flows.report.publish.publish` is timed (wall and this process's
CPU), and, for comparison, the copy alone two ways: the byte copy of the checkpointed database
file that ``publish_snapshot`` makes, and DuckDB's ``COPY FROM DATABASE`` it made before
(which re-encodes every row).

    .venv/bin/python bench/publish.py                       # 12 valves × 60 d (the demo) and 50 valves × 365 d
    .venv/bin/python bench/publish.py --size 50x365x24
"""

from __future__ import annotations

import argparse
import copy
import os
import resource
import shutil
import sys
import tempfile
import time
import tomllib
from datetime import datetime, timezone
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flows.common.warehouse_db import connect, db_path  # noqa: E402
from flows.monitor.flow import ensure_monitor_tables  # noqa: E402
from flows.report.publish import publish  # noqa: E402
from flows.report.views import snapshot_path  # noqa: E402

EXAMPLE = ROOT / "tests" / "fixtures" / "plant_example.toml"
RULES = ("no_derivative", "standstill", "pressure_peak", "spool_range", "small_dp")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def plant(tmp: Path, valves: int) -> Path:
    raw = tomllib.loads(EXAMPLE.read_text())
    template = raw["valves"][0]
    raw["valves"] = []
    for i in range(valves):
        v = copy.deepcopy(template)
        v["id"] = f"V{i + 1:03d}"
        for t in v["tags"].values():
            t["tag"] = t["tag"].replace("V017", v["id"])
        raw["valves"].append(v)
    path = tmp / "plant.toml"
    path.write_bytes(tomli_w.dumps(raw).encode())
    return path


def fill(warehouse: Path, valves: int, days: int, windows: int) -> dict[str, int]:
    """Synthetic monitor tables: every window ok, parameters scattered around 'unchanged'."""
    start = datetime(2025, 1, 1, tzinfo=timezone.utc)
    with connect(warehouse) as con:
        ensure_monitor_tables(con)
        con.execute(f"""
            CREATE TEMP TABLE w AS
            SELECT printf('V%03d', v) AS valve_id,
                   TIMESTAMPTZ '{start.isoformat()}' + to_microseconds(CAST(k * (86400e6 // {windows}) AS BIGINT)) AS window_start,
                   k * 24.0 / {windows} AS operating_hours
            FROM range(1, {valves} + 1) AS a(v), range(0, {days} * {windows}) AS b(k)
        """)
        con.execute("""
            INSERT INTO edge_fits
            SELECT valve_id, edge, window_start, window_start + INTERVAL 10 SECOND, operating_hours, 3000,
                   1 + 0.01 * (random() - 0.5), 0.001 * (random() - 0.5), 0.03 * (random() - 0.5), 0.1 + 0.01 * random(), 'ok',
                   0.99, 1.01, -0.001, 0.001, -1.5, 1.5, 1, now()
            FROM w, (VALUES ('s1'), ('1r'), ('s2'), ('2r')) AS e(edge)
        """)
        con.execute(f"""
            INSERT INTO selection_stats
            SELECT valve_id, edge, window_start, window_start + INTERVAL 10 SECOND, rule, 10000, 500, 400, 6000
            FROM w, (VALUES ('s1'), ('1r'), ('s2'), ('2r')) AS e(edge), (VALUES {", ".join(f"('{r}')" for r in RULES)}) AS r(rule)
        """)
        con.execute("CHECKPOINT")
        return {t: con.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("edge_fits", "selection_stats")}


def measure(size: str, repeats: int) -> dict:
    valves, days, windows = (int(x) for x in size.split("x"))
    with tempfile.TemporaryDirectory(prefix="valvemon-publish-", dir=os.environ.get("BENCH_TMP")) as tmp:
        tmp = Path(tmp)
        config, wh = plant(tmp, valves), tmp / "wh"
        rows = fill(wh, valves, days, windows)
        publish(config, wh)  # views exist, caches warm
        walls, cpus = [], []
        for _ in range(repeats):
            w0, c0 = time.perf_counter(), _cpu()
            publish(config, wh)
            walls.append(time.perf_counter() - w0)
            cpus.append(_cpu() - c0)
        # the copy alone: COPY FROM DATABASE vs copying the checkpointed file's bytes
        copy_s, file_s = [], []
        for _ in range(repeats):
            target = tmp / "copy.duckdb"
            target.unlink(missing_ok=True)
            with connect(wh) as con:
                main = con.execute("SELECT current_database()").fetchone()[0]
                w0 = time.perf_counter()
                con.execute(f"ATTACH '{target}' AS c")
                con.execute(f"COPY FROM DATABASE {main} TO c")
                con.execute("DETACH c")
                copy_s.append(time.perf_counter() - w0)
                con.execute("CHECKPOINT")
                w0 = time.perf_counter()
                shutil.copyfile(db_path(wh), tmp / "bytes.duckdb")
                file_s.append(time.perf_counter() - w0)
        return {
            "size": f"{valves} valves × {days} d × {windows}/d", **rows,
            "db_mb": db_path(wh).stat().st_size / 1e6, "snapshot_mb": snapshot_path(wh).stat().st_size / 1e6,
            "publish_wall_s": min(walls), "publish_cpu_s": min(cpus), "copy_from_database_s": min(copy_s), "file_copy_s": min(file_s),
        }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", action="append", help="VALVESxDAYSxWINDOWS_PER_DAY (repeat) [default: 12x60x4 and 50x365x24]")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average, 2 cores)")
    print("| warehouse | edge_fits rows | selection_stats rows | database | snapshot | publish (wall, min) | publish (CPU) | the copy: file bytes (now) | the copy: COPY FROM DATABASE (before) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for size in args.size or ["12x60x4", "50x365x24"]:
        r = measure(size, args.repeats)
        print(f"| {r['size']} | {r['edge_fits']:,} | {r['selection_stats']:,} | {r['db_mb']:,.0f} MB | {r['snapshot_mb']:,.0f} MB | "
              f"{r['publish_wall_s']:.2f} s | {r['publish_cpu_s']:.2f} s | {r['file_copy_s']:.2f} s | {r['copy_from_database_s']:.2f} s |")


if __name__ == "__main__":
    main()

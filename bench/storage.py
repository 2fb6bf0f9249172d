"""Storage of continuous recordings: lake bytes per row, what retention leaves, and the plant-scale arithmetic.

Usage (figures and the exact command in BENCHMARKS.md, "Retention and storage"):

    taskset -c 0 .venv/bin/python bench/storage.py                # 20 min of one valve
    taskset -c 0 .venv/bin/python bench/storage.py --minutes 60 --valves 500 --keep-days 90 --thin-s 10
    taskset -c 0 .venv/bin/python bench/storage.py --encodings WAREHOUSE/lake/sensors/valve_id=V001/date=2025-01-01/part-h01.parquet

1. ``valvemon simulate`` writes ``--minutes`` of one valve recorded continuously at 1 kHz (back-to-back
   10-minute windows from 00:00 UTC: one run without a gap, the shape of a continuous recording);
2. it is ingested (``run_ingest``) into the lake: bytes per lake row of continuous data, measured;
3. monitored and read by the report's standstill pass, so retention may act;
4. ``valvemon retention`` in thin mode (``--thin-s`` per hour) as of a year later: bytes and rows
   left, bytes per row of what thinning keeps, and the CPU time retention takes per lake row;
5. the fits: ``edge_fits`` and ``selection_stats`` rows per window, and bytes per row in DuckDB,
   measured on a fresh database file holding 200 000 copies of the measured rows (the values
   jittered, so that they do not compress better than real ones).

``--encodings LAKEFILE`` instead re-encodes one lake file (an hour file of a continuous recording)
with the lake's own writer (``write_partition``, fsync included) in each candidate layout — codec,
float encoding (PLAIN or BYTE_STREAM_SPLIT), row groups (≤ 1 M rows, or one per hour file) — and
measures per layout what a night does with the file: bytes per row, the write, the monitor's read
of it (``lake_chunks`` with the monitor's columns, polars' decoder; the report's standstill pass
reads the same columns the same way), the same columns decoded by pyarrow and handed to polars
(the alternative reader), DuckDB's sum of the float columns (one thread), and thinning it to 10 s
(retention's functions, on a copy). CPU seconds, the least of ``--repeat`` rounds that alternate
over the layouts.

Then the extrapolation: ``--valves`` valves × 86 400 s × 1 kHz per day, without retention and with
``keep_days`` full days plus (thin) the thinned remainder or (drop) nothing; and the fits per
valve-year for windows of ``--window-min`` minutes. CPU times are ``time.process_time`` of this
process (single-threaded polars/Arrow), so the load of the machine changes them little.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("RAYON_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from flows.common.allocator import retain_freed_memory, retain_polars_memory  # noqa: E402

retain_polars_memory()  # as the commands do, before polars is imported: decoded columns reuse freed pages
retain_freed_memory()

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from datetime import date, datetime, timezone  # noqa: E402

import duckdb  # noqa: E402
import numpy as np  # noqa: E402
import polars as pl  # noqa: E402
import pyarrow as pa  # noqa: E402
import tomli_w  # noqa: E402

pa.set_cpu_count(1)
pa.set_io_thread_count(1)

from flows.common.config import load_plant_config  # noqa: E402
from flows.common.lake import partition_bytes, partition_folders, partition_rows  # noqa: E402
from flows.common.warehouse_db import connect, create_table_sql, query_frame  # noqa: E402
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor  # noqa: E402
from flows.report.flow import update_standstill  # noqa: E402
from flows.retention.flow import run_retention  # noqa: E402
from flows.simulate.archive import SimulateRequest, run_simulate  # noqa: E402
from schemas.fields import EDGE_FIT_FIELDS, SELECTION_FIELDS  # noqa: E402
from schemas.plant_config import RetentionSpec, plant_config_to_dict  # noqa: E402

DAY_S = 86_400
RATE_HZ = 1_000


def lake_totals(wh: Path) -> tuple[int, int]:
    """(rows, bytes) of the whole lake."""
    parts = partition_folders(wh)
    return sum(partition_rows(f) for _, _, f in parts), sum(partition_bytes(f) for _, _, f in parts)


def db_bytes_per_row(frame: pl.DataFrame, name: str, fields, n: int = 200_000, seed: int = 0) -> float:
    """Bytes per row of a table in a fresh DuckDB file holding ``n`` jittered copies of ``frame``."""
    rng = np.random.default_rng(seed)
    reps = frame.sample(n, with_replacement=True, seed=seed)
    floats = [c for c, t in reps.schema.items() if t == pl.Float64]
    reps = reps.with_columns([(pl.col(c) * pl.Series(1 + 1e-3 * rng.standard_normal(n))).alias(c) for c in floats])
    reps = reps.with_columns(
        (pl.col("window_start") + pl.duration(seconds=pl.Series(np.arange(n) * 600))).alias("window_start"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.duckdb"
        con = duckdb.connect(str(path))
        con.execute(create_table_sql(name, fields))
        con.register("f", reps.to_arrow())
        con.execute(f"INSERT INTO {name} BY NAME SELECT * FROM f")
        con.execute("CHECKPOINT")
        used = con.execute("SELECT used_blocks * block_size FROM pragma_database_size()").fetchone()[0]
        con.close()
    return used / n


ENCODINGS = [
    # (name, codec, byte-stream-split floats, row groups of at most this many rows)
    ("uncompressed, ≤ 1 M-row groups (the lake)", "none", False, 1_048_576),
    ("LZ4, ≤ 1 M-row groups (the lake until 2026-11-27)", "lz4", False, 1_048_576),
    ("LZ4, one group per hour file", "lz4", False, None),
    ("LZ4 + BYTE_STREAM_SPLIT, ≤ 1 M-row groups", "lz4", True, 1_048_576),
    ("LZ4 + BYTE_STREAM_SPLIT, one group", "lz4", True, None),
    ("zstd-1, one group", "zstd", False, None),
    ("zstd-1 + BYTE_STREAM_SPLIT, one group", "zstd", True, None),
    ("snappy, one group", "snappy", False, None),
    ("uncompressed, one group", "none", False, None),
]
"""The layouts ``--encodings`` compares (``None``: the lake's :data:`ROW_GROUP_MAX_ROWS`)."""


def least(f, repeat: int) -> float:
    """Least CPU time of ``repeat`` calls of ``f``. [s]"""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        f()
        best = min(best, time.process_time() - t0)
    return best


def encodings(source: Path, repeat: int) -> None:
    """Re-encode one lake file in each layout of :data:`ENCODINGS` with the lake's writer and
    measure what a night does with it, rounds alternating over the layouts (module doc)."""
    import pyarrow.parquet as pq

    import flows.common.lake as lake
    from flows.monitor.flow import lake_chunks
    from flows.retention.flow import count_kept, scan_partition, thin_partition
    from transforms.monitor import LAKE_COLUMNS

    frame = pl.read_parquet(source, hive_partitioning=False).cast(dict(lake.SENSOR_POLARS_SCHEMA))
    n = frame.height
    floats = [c for c in frame.columns if c.endswith(("_pa", "_m"))]
    t_us = frame["timestamp_utc"].to_physical().to_numpy()
    q = f"SELECT {', '.join(f'sum({c})' for c in floats)} FROM read_parquet(?)"
    con = duckdb.connect()
    con.execute("SET threads = 1")
    defaults = (lake.COLUMN_ENCODING, lake.ROW_GROUP_MAX_ROWS)
    best: dict[str, dict[str, float]] = {name: {} for name, *_ in ENCODINGS}
    facts: dict[str, tuple[int, int]] = {}

    def note(name: str, what: str, f) -> None:
        t0 = time.process_time()
        f()
        best[name][what] = min(best[name].get(what, float("inf")), time.process_time() - t0)

    with tempfile.TemporaryDirectory(prefix="valvemon-encodings-") as tmp:
        for _ in range(repeat):
            for name, codec, bss, max_rows in ENCODINGS:
                wh = Path(tmp) / f"{codec}_{bss}_{max_rows}"
                path = lake.partition_path(wh, "V001", frame["date"][0]).parent / "part-h01.parquet"
                lake.COLUMN_ENCODING = {"timestamp_utc": "DELTA_BINARY_PACKED", **({c: "BYTE_STREAM_SPLIT" for c in floats} if bss else {})}
                lake.ROW_GROUP_MAX_ROWS = max_rows or defaults[1]
                try:
                    note(name, "write", lambda: lake.write_partition(path, frame, codec=codec))
                finally:
                    lake.COLUMN_ENCODING, lake.ROW_GROUP_MAX_ROWS = defaults
                facts[name] = (pq.ParquetFile(path).metadata.num_row_groups, path.stat().st_size)
                note(name, "monitor", lambda: [c.height for c in lake_chunks(wh, "V001", 0.005, None, None, columns=LAKE_COLUMNS, window_s=600.0)])
                note(name, "pyarrow", lambda: pl.from_arrow(pq.read_table(path, columns=list(LAKE_COLUMNS[1:]))))
                note(name, "duckdb", lambda: con.execute(q, [str(path)]).fetchall())
                thin = wh / "thin" / "date=x"
                thin.mkdir(parents=True, exist_ok=True)
                shutil.copy(path, thin / "part-h01.parquet")
                note(name, "thin", lambda: thin_partition(count_kept(thin, scan_partition(thin, (t_us[:1], t_us[-1:]), True), 10.0), codec))
    con.close()
    print(f"{source}: {n:,} rows; CPU s per file, least of {repeat} alternating rounds, one core")
    print("night = write + 2 × the monitor's read (the monitor's and the report's standstill pass read the same columns) + thinning")
    print("| layout | row groups | B/row | write | monitor's read (lake_chunks) | pyarrow → polars | DuckDB sum | thin to 10 s | night |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, t in best.items():
        groups, size = facts[name]
        night = t["write"] + 2 * t["monitor"] + t["thin"]
        print(f"| {name} | {groups} | {size / n:.2f} | {t['write']:.3f} | {t['monitor']:.3f} | {t['pyarrow']:.3f} | {t['duckdb']:.3f} | {t['thin']:.3f} | {night:.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--encodings", type=Path, default=None, metavar="LAKEFILE", help="Compare the lake's candidate layouts on this lake file instead.")
    ap.add_argument("--repeat", type=int, default=5, help="With --encodings: repetitions per measurement (the least counts).")
    ap.add_argument("--minutes", type=int, default=20, help="Minutes of continuous 1 kHz data measured (a multiple of 10).")
    ap.add_argument("--valves", type=int, default=500)
    ap.add_argument("--keep-days", type=int, default=90)
    ap.add_argument("--thin-s", type=float, default=10.0, help="thin_keep_s_per_hour")
    ap.add_argument("--window-min", type=float, default=10.0, help="Monitoring window of a continuous recording, for the fits per valve-year. [min]")
    ap.add_argument("--out", type=Path, default=None, help="Work folder (default: a temporary one).")
    args = ap.parse_args()
    if args.encodings:
        encodings(args.encodings, args.repeat)
        return
    root = args.out or Path(tempfile.mkdtemp(prefix="valvemon-storage-"))
    sim, wh = root / "sim", root / "wh"

    t0 = time.process_time()
    end = f"2025-01-01T{args.minutes // 60:02d}:{args.minutes % 60:02d}:00Z"
    run_simulate(SimulateRequest(out=sim, n_valves=1, start="2025-01-01T00:00:00Z", end=end, windows_per_day=144, window_s=600.0,
                                 format="parquet", seed=7, workers=0), show_progress=False)  # fmt: skip
    t_sim = time.process_time() - t0
    config = load_plant_config(sim / "plant.toml")
    cfg = root / "plant.toml"
    cfg.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, retention=RetentionSpec(1, "thin", args.thin_s)))).encode())

    t0 = time.process_time()
    run_ingest(cfg, [sim / "exports"], wh)
    t_ingest = time.process_time() - t0
    rows, nbytes = lake_totals(wh)
    bpr = nbytes / rows
    run_monitor(cfg, wh)
    update_standstill(load_plant_config(cfg), wh, datetime.now(timezone.utc))
    with connect(wh, read_only=True) as con:
        fits = query_frame(con, "SELECT * FROM edge_fits")
        sel = query_frame(con, "SELECT * FROM selection_stats")
        windows = con.execute("SELECT count(DISTINCT window_start) FROM edge_fits").fetchone()[0]

    plant = load_plant_config(cfg)
    shutil.copytree(wh, root / "wh_drop")
    t0 = time.process_time()
    run_retention(dataclasses.replace(plant, retention=RetentionSpec(1, "drop")), root / "wh_drop", as_of=date(2026, 1, 1))
    t_drop = time.process_time() - t0
    t0 = time.process_time()
    summary = run_retention(plant, wh, as_of=date(2026, 1, 1))
    t_ret = time.process_time() - t0
    rows_t, bytes_t = lake_totals(wh)
    acted = [o for o in summary.outcomes if o.action == "thin"]
    bpr_thin = bytes_t / rows_t

    fit_bpr = db_bytes_per_row(fits, "edge_fits", EDGE_FIT_FIELDS)
    sel_bpr = db_bytes_per_row(sel, "selection_stats", SELECTION_FIELDS)

    print(f"measured: {args.minutes} min of one valve at 1 kHz, continuous (work folder {root})")
    print(f"  simulate {t_sim:.1f} s CPU, ingest {t_ingest:.1f} s CPU ({rows / t_ingest / 1e6:.2f} M rows/CPU s)")
    print(f"  lake: {rows:,} rows, {nbytes:,} B -> {bpr:.2f} B/row")
    print(f"  thin ({args.thin_s:g} s/h, {len(acted)} partition): {rows_t:,} rows, {bytes_t:,} B -> {bpr_thin:.2f} B/row")
    print(f"  retention CPU: thin {t_ret:.2f} s = {t_ret / rows * 1e9:.0f} ns/lake row (scan, count, read, write, log); "
          f"drop {t_drop:.2f} s = {t_drop / rows * 1e9:.0f} ns/lake row (scan, rename, log, delete)")  # fmt: skip
    print(f"  fits: {windows} windows -> {fits.height} edge_fits rows ({fits.height / windows:.0f}/window), "
          f"{sel.height} selection_stats rows ({sel.height / windows:.0f}/window); DuckDB {fit_bpr:.0f} and {sel_bpr:.0f} B/row")  # fmt: skip

    day_rows = DAY_S * RATE_HZ
    valve_day = day_rows * bpr
    plant_day = args.valves * valve_day
    thin_rows_day = 24 * args.thin_s * RATE_HZ
    thin_day = thin_rows_day * bpr_thin
    k = args.keep_days
    win_year = 365 * 24 * 60 / args.window_min
    fits_year = win_year * (fits.height / windows * fit_bpr + sel.height / windows * sel_bpr)
    print()
    print(f"extrapolated: {args.valves} valves x 86,400 s x 1 kHz = {args.valves * day_rows / 1e9:.1f} G lake rows/day")
    print("| quantity | per valve | plant |")
    print("|---|---:|---:|")
    print(f"| lake per day, no retention | {valve_day / 1e9:.2f} GB | {plant_day / 1e12:.2f} TB |")
    print(f"| lake after a year, no retention | {365 * valve_day / 1e9:.0f} GB | {365 * plant_day / 1e12:.0f} TB |")
    print(f"| drop after {k} d: steady state ({k} full days) | {k * valve_day / 1e9:.0f} GB | {args.valves * k * valve_day / 1e12:.0f} TB |")
    print(f"| thin after {k} d: one thinned day ({args.thin_s:g} s of every hour) | {thin_day / 1e6:.1f} MB | {args.valves * thin_day / 1e9:.2f} GB |")
    print(f"| thin after {k} d: after a year ({k} full + {365 - k} thinned days) | {(k * valve_day + (365 - k) * thin_day) / 1e9:.0f} GB | "
          f"{args.valves * (k * valve_day + (365 - k) * thin_day) / 1e12:.0f} TB |")  # fmt: skip
    print(f"| thin after {k} d: growth per further year | {365 * thin_day / 1e9:.1f} GB | {args.valves * 365 * thin_day / 1e12:.2f} TB |")
    print(f"| fits per year ({args.window_min:g}-min windows: {win_year:,.0f}) | {fits_year / 1e6:.0f} MB | {args.valves * fits_year / 1e9:.1f} GB |")
    for name, t in (("thin", t_ret), ("drop", t_drop)):
        print(f"| retention CPU per night, {name} (one valve-day each) | {day_rows * t / rows:.0f} s | {args.valves * day_rows * t / rows / 3600:.1f} h |")

if __name__ == "__main__":
    main()

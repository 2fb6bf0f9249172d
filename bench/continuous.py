"""Continuous-recording ingest benchmark: a valve-day of back-to-back 1 kHz samples → lake.

Usage (figures and the exact commands in BENCHMARKS.md, "Ingest", ING-8):

    .venv/bin/python bench/continuous.py --hours 24 --layout wide --format parquet           # one file
    .venv/bin/python bench/continuous.py --hours 24 --layout wide --format parquet --hourly   # 24 hourly files
    .venv/bin/python bench/continuous.py --hours 2 --layout long --format csv

The generator writes synthetic plant signals (``bench/ingest.py: signals``: motion + noise + 16-bit
quantisation, exactly on the 1 kHz grid) an hour at a time with ``pyarrow.parquet.ParquetWriter``
or appended CSV blocks, so it stays in bounded memory itself. Then, each in a child process
pinned to one core (``taskset -c 0``, ``POLARS_MAX_THREADS=1``), it measures on the same files:

- ``bare``: ``pl.read_parquet`` / ``pl.read_csv`` of each file + ``write_parquet`` (LZ4) of the frame;
- ``ingest``: ``flows.ingest.flow.run_ingest`` of the files into an empty warehouse;
- ``monitor``: ``flows.monitor.flow.run_monitor`` of that lake (clock windows of the default
  ``[monitor] window_s``, nominal baselines): lake → fits, with the fits' status counts (the
  synthetic signals are not the valve model's, so many windows end ``not ok``: the figure is the
  monitor's cost per lake row, not its accuracy, which ``docs/monitoring.md`` measures);

wall time, CPU time (user + system of the child, after its imports) and peak RSS (the child's
``VmHWM``; its ``ru_maxrss`` would include the generator's peak, inherited over fork). The
inputs and warehouses are deleted afterwards.
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

EXAMPLE = ROOT / "tests" / "fixtures" / "plant_example.toml"
SIGNALS = {"ps": "PS", "pr": "PR", "p1": "P1", "p2": "P2", "x_spool": "XS", "x_cyl": "XC"}
START_US = 1_740_787_200_000_000  # 2025-03-01T00:00:00Z
HOUR = 3_600_000


def write_plant(folder: Path, valves: list[str], layout: str) -> Path:
    """The example plant on a 1 kHz grid, with ``valves`` (copies of its valve) and ``layout``."""
    import tomli_w

    raw = tomllib.loads(EXAMPLE.read_text())
    raw["export"].update({"sample_rate_hz": 1000.0, "max_gap_s": 0.005, "layout": layout})
    if layout == "wide":
        for k in ("tag_column", "value_column", "quality_column", "good_quality"):
            raw["export"].pop(k, None)
    base = raw["valves"][0]
    raw["valves"] = []
    for vid in valves:
        v = json.loads(json.dumps(base))
        v["id"] = vid
        v["tags"] = {s: {"tag": f"MILL1.{vid}.{t}", "unit": base["tags"][s]["unit"]} for s, t in SIGNALS.items()}
        raw["valves"].append(v)
    path = folder / "plant.toml"
    path.write_bytes(tomli_w.dumps(raw).encode())
    return path


def generate(folder: Path, valves: list[str], hours: float, layout: str, fmt: str, hourly: bool) -> list[Path]:
    """Write the recording an hour at a time (bounded memory); returns the files."""
    import polars as pl
    import pyarrow.parquet as pq

    from bench.ingest import signals

    n_total = int(hours * HOUR)
    files: list[Path] = []
    writer = None
    out = None
    for h, a in enumerate(range(0, n_total, HOUR)):
        n = min(HOUR, n_total - a)
        ts = pl.Series("timestamp", START_US + (a + np.arange(n, dtype=np.int64)) * 1000).cast(pl.Datetime("us", "UTC"))
        cols = {f"MILL1.{vid}.{SIGNALS[s]}": x for k, vid in enumerate(valves) for s, x in signals(n, seed=1000 * k + h).items()}
        if layout == "wide":
            frame = pl.DataFrame({"timestamp": ts, **cols})
        else:  # time-major long rows: every tag of an instant together
            names = list(cols)
            frame = pl.DataFrame(
                {
                    "timestamp": ts.to_numpy().repeat(len(names)),
                    "tag": np.tile(np.array(names, dtype=object), n),
                    "value": np.stack([cols[c] for c in names], axis=1).reshape(-1),
                    "quality": "Good",
                }
            ).with_columns(pl.col("timestamp").cast(pl.Datetime("us", "UTC")))
        if fmt == "csv":
            frame = frame.with_columns(pl.col("timestamp").dt.strftime("%Y-%m-%dT%H:%M:%S%.3fZ"))
        if out is None or hourly:
            if writer is not None:
                writer.close()
                writer = None
            out = folder / (f"rec_{h:02d}.{fmt}" if hourly else f"rec.{fmt}")
            files.append(out)
            if out.exists():
                out.unlink()
        if fmt == "parquet":
            table = frame.to_arrow()
            if writer is None:
                writer = pq.ParquetWriter(out, table.schema, compression="zstd")
            writer.write_table(table, row_group_size=1 << 20)
        else:
            with open(out, "ab") as fh:
                frame.write_csv(fh, include_header=fh.tell() == 0)
        del frame, cols
    if writer is not None:
        writer.close()
    return files


def child_bare(files: list[str], out: str) -> dict:
    import polars as pl

    n = 0
    for i, f in enumerate(files):
        df = pl.read_parquet(f) if f.endswith(".parquet") else pl.read_csv(f)
        n += df.height
        df.write_parquet(Path(out) / f"bare_{i}.parquet", compression="lz4")
        del df
    return {"rows": n}


def child_ingest(config: str, files: list[str], warehouse: str) -> dict:
    from flows.ingest.flow import run_ingest

    s = run_ingest(config, files, warehouse)
    return {"rows": s.rows_written, "rows_read": s.rows_read, "partitions_written": s.partitions_written}


def child_monitor(config: str, warehouse: str) -> dict:
    from flows.monitor.flow import run_monitor

    reports = run_monitor(config, warehouse)
    status: dict[str, int] = {}
    for r in reports:
        for k, n in r.status_counts.items():
            status[k] = status.get(k, 0) + n
    return {"rows": sum(r.rows_read for r in reports), "windows": sum(r.windows for r in reports), "status": status}


def peak_rss_mb() -> float:
    """This process's peak resident memory: ``VmHWM`` (``ru_maxrss`` would carry the parent's peak
    over ``fork`` + ``exec``: the generator's, here)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _child(argv: list[str]) -> None:
    kind, payload = argv[0], json.loads(argv[1])
    import polars  # noqa: F401  (imports are not what is measured)

    if kind == "ingest":
        import flows.ingest.flow  # noqa: F401
    if kind == "monitor":
        import flows.monitor.flow  # noqa: F401
    t0, c0 = time.perf_counter(), time.process_time()
    r = {"bare": child_bare, "ingest": child_ingest, "monitor": child_monitor}[kind](**payload)
    r.update(wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0, peak_rss_mb=peak_rss_mb())
    print(json.dumps(r))


def run_child(kind: str, payload: dict) -> dict:
    cmd = ["taskset", "-c", "0", sys.executable, __file__, "--child", kind, json.dumps(payload)]
    env = dict(os.environ, PREFECT_SERVER_ANALYTICS_ENABLED="false")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def du(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--valves", type=int, default=1)
    ap.add_argument("--layout", choices=["wide", "long"], default="wide")
    ap.add_argument("--format", choices=["parquet", "csv"], default="parquet")
    ap.add_argument("--hourly", action="store_true", help="one file per hour instead of one file")
    ap.add_argument("--dir", default=None, help="where to put the inputs (default: a temporary folder)")
    args = ap.parse_args()
    valves = [f"V{k + 1:03d}" for k in range(args.valves)]
    with tempfile.TemporaryDirectory(prefix="valvemon-cont-", dir=args.dir) as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        config = write_plant(tmp, valves, args.layout)
        files = generate(tmp, valves, args.hours, args.layout, args.format, args.hourly)
        size = sum(f.stat().st_size for f in files)
        print(f"input: {len(valves)} valve(s) × {args.hours:g} h at 1 kHz, {args.layout} {args.format}, {len(files)} file(s), {size / 1e9:.2f} GB (generated in {time.perf_counter() - t0:.0f} s)")
        print(f"load: {os.getloadavg()}")
        (tmp / "bare").mkdir()
        bare = run_child("bare", {"files": [str(f) for f in files], "out": str(tmp / "bare")})
        shutil.rmtree(tmp / "bare")
        wh = tmp / "wh"
        ing = run_child("ingest", {"config": str(config), "files": [str(f) for f in files], "warehouse": str(wh)})
        lake_bytes = du(wh / "lake")
        mon = run_child("monitor", {"config": str(config), "warehouse": str(wh)})
        rows = ing["rows"]
        print(f"{'':<8}{'wall s':>9}{'CPU s':>9}{'peak RSS MB':>13}{'lake Mrows/s (CPU)':>20}")
        for name, r in (("bare", bare), ("ingest", ing), ("monitor", mon)):
            print(f"{name:<8}{r['wall_s']:>9.1f}{r['cpu_s']:>9.1f}{r['peak_rss_mb']:>13.0f}{rows / r['cpu_s'] / 1e6:>20.2f}")
        print(f"ingest / bare: wall {ing['wall_s'] / bare['wall_s']:.2f}×, CPU {ing['cpu_s'] / bare['cpu_s']:.2f}×")
        print(f"monitor: {mon['rows']:,} lake rows read, {mon['windows']:,} windows, fits {mon['status']}")
        print(f"lake: {rows:,} rows, {lake_bytes / 1e9:.2f} GB ({lake_bytes / max(rows, 1):.1f} bytes/row), {ing['partitions_written']} day-folder writes (summed over the files)")
        print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()

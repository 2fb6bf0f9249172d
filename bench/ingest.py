"""Ingest benchmark: export → lake against a bare read of the same file, and the lake's storage.

Usage (figures and the exact command in BENCHMARKS.md, "Ingest"):

    .venv/bin/python bench/ingest.py                 # throughput, one core
    .venv/bin/python bench/ingest.py --storage       # lake storage study (codec, float width, row groups)
    .venv/bin/python bench/ingest.py --seconds 200   # a smaller input
    .venv/bin/python bench/ingest.py --recorder      # wide recorder formats: CSV, ASCII with header rows, TDMS, Parquet
    .venv/bin/python bench/ingest.py --stages-of DAY --hours 3   # where a recorded day's ingest goes, per hour file

Throughput: a synthetic plant export (one valve, six required tags, sampled exactly on the 1 kHz
grid, realistic signals: smooth motion + sensor noise + 16-bit quantisation) is written as a
long CSV (``timestamp,tag,value,quality``, ISO-8601 with ``Z``) and as a long Parquet file. For
each, the benchmark times a plain ``polars.read_csv`` / ``polars.read_parquet`` of the file and
the whole ingest of the file into an empty warehouse (``flows.ingest.flow.ingest_file``: hash, read,
parse, quarantine check, de-duplicate, grid, validate, merge, atomic Parquet write,
DuckDB manifest). Everything runs on one core (``POLARS_MAX_THREADS=1``, one Arrow thread), so
rows/s is per core. The ratio ingest / bare read is the figure (target ≤ 2).

Recorder formats (``--recorder``): the same signals as one wide file per format — CSV with one
header line, iba-style ASCII (tab, header lines tag/name/unit), TDMS (a channel per tag, waveform
time, a segment per 100,000 samples) and Parquet — each against its bare read (``polars.read_csv``,
``nptdms.TdmsFile.read`` of every channel, ``polars.read_parquet``) and ingested with a wide plant.

Storage: the same signals as a lake partition, written with several codecs and float widths,
then decoded (``polars.read_parquet`` of all columns, and a DuckDB scan), sized, and read for
one 10 s window by a time filter, to choose the lake's codec, float width and row groups.
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import polars as pl  # noqa: E402
import pyarrow as pa  # noqa: E402

pa.set_cpu_count(1)
pa.set_io_thread_count(1)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from flows.common.config import load_plant_config  # noqa: E402
from flows.ingest.flow import ingest_file
from transforms.ingest import TagTable  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "plant_example.toml"
TAGS = {
    "ps": ("MILL1.V017.PS", 1e5),
    "pr": ("MILL1.V017.PR", 1e5),
    "p1": ("MILL1.V017.P1", 1e5),
    "p2": ("MILL1.V017.P2", 1e5),
    "x_spool": ("MILL1.V017.XS", 1e-3),
    "x_cyl": ("MILL1.V017.XC", 1e-3),
}
START_US = 1_740_787_200_000_000  # 2025-03-01T00:00:00Z


def signals(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Plant-like signals in export units (bar, mm), 1 kHz: motion + noise + 16-bit quantisation."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    x_ref = 1.2 * np.sin(2 * np.pi * 0.37 * t) * np.sin(2 * np.pi * 0.05 * t)
    x_spool = x_ref + 0.01 * rng.standard_normal(n)
    x_cyl = 300 + 150 * np.cumsum(x_spool) / n * 50
    p1 = 90 + 40 * np.tanh(x_spool) + 0.3 * rng.standard_normal(n)
    p2 = 110 - 40 * np.tanh(x_spool) + 0.3 * rng.standard_normal(n)
    ps = 210 + 0.5 * np.sin(2 * np.pi * 3.1 * t) + 0.2 * rng.standard_normal(n)
    pr = 2.0 + 0.05 * rng.standard_normal(n)

    def q(x: np.ndarray, full_scale: float) -> np.ndarray:  # 16-bit ADC over the sensor's range
        step = full_scale / 65536
        return np.round(x / step) * step

    out = {"ps": q(ps, 400), "pr": q(pr, 400), "p1": q(p1, 400), "p2": q(p2, 400), "x_spool": q(x_spool, 7), "x_cyl": q(x_cyl, 1000)}
    return {k: np.round(v, 4) for k, v in out.items()}  # 4 decimals, as the export writes them


def long_frame(n: int) -> pl.DataFrame:
    """A long export, time-major (all tags of one instant together), as historians write it."""
    sig = signals(n)
    ts = pl.Series("timestamp", START_US + np.arange(n, dtype=np.int64) * 1000).cast(pl.Datetime("us", "UTC"))
    parts = [pl.DataFrame({"timestamp": ts, "tag": TAGS[s][0], "value": sig[s], "quality": "Good", "k": np.arange(n), "j": j}) for j, s in enumerate(TAGS)]
    return pl.concat(parts).sort(["k", "j"]).drop("k", "j")


def write_inputs(folder: Path, n: int) -> dict[str, Path]:
    df = long_frame(n)
    csv = folder / "export_long.csv"
    df.with_columns(pl.col("timestamp").dt.strftime("%Y-%m-%dT%H:%M:%S%.3fZ")).write_csv(csv)
    pq_path = folder / "export_long.parquet"
    df.write_parquet(pq_path, compression="zstd")
    return {"csv": csv, "parquet": pq_path}


def timed(f, repeat: int) -> float:
    """CPU seconds of this process for ``f()``, the least of ``repeat`` runs.

    CPU time rather than wall time: the figures are per core, and other processes on a shared
    machine then disturb them much less; the least of several runs drops the remaining noise.
    """
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        f()
        times.append(time.process_time() - t0)
    return min(times)


def ingester(path: Path, config, tags: TagTable, wh: Path, n: int):
    """The whole ingest of ``path`` into an empty warehouse ``wh`` (``n`` lake rows expected)."""

    def ingest() -> None:
        shutil.rmtree(wh, ignore_errors=True)
        r = ingest_file(path, config, wh, "bench", tags=tags)
        assert r.rows_out == n, r

    return ingest


def throughput(seconds: int, repeat: int) -> None:
    n = seconds * 1000
    config = load_plant_config(CONFIG)
    tags = TagTable.from_config(config)
    with tempfile.TemporaryDirectory(prefix="valvemon-bench-") as tmp:
        tmp = Path(tmp)
        inputs = write_inputs(tmp, n)
        rows = 6 * n
        print(f"input: {n:,} instants × 6 tags = {rows:,} long rows; one core (POLARS_MAX_THREADS={os.environ['POLARS_MAX_THREADS']})")
        stages: dict[str, dict[str, float]] = {}
        print(f"{'file':<10}{'size MB':>9}{'bare read s':>13}{'ingest s':>10}{'ratio':>7}{'bare Mrows/s':>14}{'ingest Mrows/s':>16}{'lake rows':>11}")
        for kind, path in inputs.items():
            bare = (lambda: pl.read_csv(path)) if kind == "csv" else (lambda: pl.read_parquet(path))
            t_bare = timed(bare, repeat)
            ingest = ingester(path, config, tags, tmp / f"wh_{kind}", n)
            t_ing = timed(ingest, repeat)
            print(f"{kind:<10}{path.stat().st_size / 1e6:>9.1f}{t_bare:>13.3f}{t_ing:>10.3f}{t_ing / t_bare:>7.2f}{rows / t_bare / 1e6:>14.2f}{rows / t_ing / 1e6:>16.2f}{n:>11,}")
            stages[kind] = _stages(lambda: ingest(), repeat)
        print("\nwhere the ingest's CPU time goes (s, least of the repeats per stage):")
        names = list(next(iter(stages.values())))
        print(f"{'stage':<44}" + "".join(f"{k:>10}" for k in stages))
        for name in names:
            print(f"{name:<44}" + "".join(f"{stages[k][name]:>10.3f}" for k in stages))


STAGES = [
    ("flows.ingest.formats", "open_export", "format, BLAKE3 of the mapped file in blocks, header"),
    ("flows.ingest.formats.text", "read_csv_export", "CSV decode (per block of lines)"),
    ("transforms.ingest.stream", "samples_of", "samples: tags, timestamps, values, quarantine"),
    ("transforms.ingest.samples", "parse_timestamps", "  of which: timestamps to UTC"),
    ("transforms.ingest.stream", "validate_raw_rows", "pandera: raw rows"),
    ("transforms.ingest.stream", "prepare_tag", "sort + duplicates per tag"),
    ("transforms.ingest.stream", "to_grid", "grid + gaps per tag"),
    ("transforms.ingest.stream", "assemble_valve", "assemble valve frame"),
    ("transforms.ingest.stream", "validate_sensor_frame", "pandera: sensor frame"),
    ("flows.ingest.staging", "read_partition", "read existing lake file"),
    ("flows.ingest.staging", "stage_file", "write lake files (fsync)"),
    ("flows.ingest.staging", "commit_files", "put files in place (rename)"),
    ("flows.ingest.flow", "record_file", "DuckDB manifest, quarantine, gaps"),
]


CONTINUOUS_STAGES = [
    ("flows.ingest.formats", "open_export", "open: format, BLAKE3 of the file in blocks"),
    ("flows.ingest.formats", "iload", "Parquet decode of the batches (polars)"),
    ("transforms.ingest.stream", "samples_of", "samples: checks, SI, quarantine masks"),
    ("transforms.ingest.samples", "_value_checks", "  of which: null / NaN / inf masks"),
    ("transforms.ingest.samples._Faults", "checked", "  of which: SI + range + time checks"),
    ("transforms.ingest.samples", "_accepted", "  of which: accepted samples (frames)"),
    ("transforms.ingest.samples", "ClockSteps.after_step", "  of which: clock steps"),
    ("transforms.ingest.stream", "validate_raw_rows", "registry check: raw rows"),
    ("transforms.ingest.stream", "tag_blocks", "per-tag arrays"),
    ("transforms.ingest.stream", "prepare_tag", "order check, duplicates per tag"),
    ("transforms.ingest.stream", "to_grid", "grid + gaps per tag"),
    ("transforms.ingest.stream", "assemble_valve", "assemble valve rows (float32)"),
    ("transforms.ingest.stream", "validate_sensor_frame", "registry check: lake rows"),
    ("flows.ingest.staging", "split_days", "split by day / hour"),
    ("flows.ingest.staging", "read_partition", "read existing lake file"),
    ("flows.ingest.staging", "merge_partition", "merge with the lake file"),
    ("flows.ingest.staging", "stage_file", "write lake files (fsync)"),
    ("flows.ingest.staging", "commit_files", "put files in place (rename)"),
    ("flows.ingest.flow", "record_file", "DuckDB manifest, quarantine, gaps"),
]
"""Stages of a wide Parquet recording's ingest (``--stages-of``); an indented stage is part of the
one above it."""


def _stages(run, repeat: int, stages: list[tuple[str, str, str]] = STAGES) -> dict[str, float]:
    """CPU time per stage of ``run()``, by wrapping the stage functions where they are looked up
    (``module.Class`` for a method; a generator's time is that of its ``next`` calls)."""
    import importlib
    import inspect

    best: dict[str, float] = {}
    for _ in range(repeat):
        acc: dict[str, float] = {label: 0.0 for _, _, label in stages}
        saved = []
        for mod_name, fn, label in stages:
            try:
                mod = importlib.import_module(mod_name)
            except ModuleNotFoundError:  # module.Class
                mod_name, cls = mod_name.rsplit(".", 1)
                mod = getattr(importlib.import_module(mod_name), cls)
            if "." in fn:  # Class.method, found in the module
                cls, fn = fn.split(".")
                mod = getattr(mod, cls)
            f = getattr(mod, fn)
            saved.append((mod, fn, f))

            def timed_gen(gen, _label):
                while True:
                    t0 = time.process_time()
                    try:
                        item = next(gen)
                    except StopIteration:
                        acc[_label] += time.process_time() - t0
                        return
                    acc[_label] += time.process_time() - t0
                    yield item

            def wrapped(*a, _f=f, _label=label, **k):
                t0 = time.process_time()
                try:
                    out = _f(*a, **k)
                finally:
                    acc[_label] += time.process_time() - t0
                return timed_gen(out, _label) if inspect.isgenerator(out) else out

            setattr(mod, fn, wrapped)
        try:
            t0 = time.process_time()
            run()
            acc["total"] = time.process_time() - t0
        finally:
            for mod, fn, f in saved:
                setattr(mod, fn, f)
        for k, v in acc.items():
            best[k] = min(best.get(k, v), v)
    return best


def wide_config():
    """The example plant, wide (time column ``timestamp``, ISO-8601)."""
    import tomllib

    from schemas.plant_config import parse_plant_config

    raw = tomllib.loads(CONFIG.read_text())
    for k in ("tag_column", "value_column", "quality_column", "good_quality"):
        raw["export"].pop(k)
    raw["export"]["layout"] = "wide"
    return parse_plant_config(raw)


def write_recorder_inputs(folder: Path, n: int) -> dict[str, tuple[Path, object, object]]:
    """``format → (file, bare read, plant)`` of the same signals, wide."""
    import dataclasses

    from nptdms import ChannelObject, TdmsWriter

    sig = signals(n)
    t_us = START_US + np.arange(n, dtype=np.int64) * 1000
    ts = pl.Series("timestamp", t_us).cast(pl.Datetime("us", "UTC"))
    df = pl.DataFrame([ts] + [pl.Series(TAGS[s][0], sig[s]) for s in TAGS])
    text = df.with_columns(pl.col("timestamp").dt.strftime("%Y-%m-%dT%H:%M:%S%.3fZ"))
    config = wide_config()
    ascii_config = dataclasses.replace(config, export=dataclasses.replace(config.export, header_rows=("tag", "name", "unit"), separator="\t"))
    out = {}
    csv = folder / "export_wide.csv"
    text.write_csv(csv)
    out["wide csv"] = (csv, lambda: pl.read_csv(csv), config)
    asc = folder / "export_iba.txt"
    units = ["bar"] * 4 + ["mm"] * 2
    with asc.open("wb") as fh:
        fh.write(("\t".join(df.columns) + "\n" + "\t".join(["", *TAGS]) + "\n" + "\t".join(["", *units]) + "\n").encode())
        text.write_csv(fh, separator="\t", include_header=False)
    out["iba ascii"] = (asc, lambda: pl.read_csv(asc, separator="\t", skip_rows_after_header=2), ascii_config)
    tdms = folder / "export.tdms"
    with TdmsWriter(str(tdms)) as w:
        for a in range(0, n, 100_000):
            props = lambda k: {"wf_start_time": np.datetime64(START_US, "us"), "wf_increment": 0.001, "unit_string": units[k]} if a == 0 else None  # noqa: E731
            w.write_segment([ChannelObject("rec", TAGS[s][0], sig[s][a : a + 100_000], properties=props(k)) for k, s in enumerate(TAGS)])

    def read_tdms() -> None:
        from nptdms import TdmsFile

        f = TdmsFile.read(tdms)
        for ch in f["rec"].channels():
            ch[:]

    out["tdms"] = (tdms, read_tdms, config)
    pq_path = folder / "export_wide.parquet"
    df.write_parquet(pq_path, compression="zstd")
    out["wide parquet"] = (pq_path, lambda: pl.read_parquet(pq_path), config)
    return out


def recorder(seconds: int, repeat: int) -> None:
    n = seconds * 1000
    with tempfile.TemporaryDirectory(prefix="valvemon-bench-") as tmp:
        tmp = Path(tmp)
        inputs = write_recorder_inputs(tmp, n)
        print(f"input: {n:,} instants × 6 tags, wide; one core (POLARS_MAX_THREADS={os.environ['POLARS_MAX_THREADS']})")
        print(f"{'file':<14}{'size MB':>9}{'bare read s':>13}{'ingest s':>10}{'ratio':>7}{'ingest lake rows/s':>20}")
        for kind, (path, bare, config) in inputs.items():
            t_bare = timed(bare, repeat)
            t_ing = timed(ingester(path, config, TagTable.from_config(config), tmp / f"wh_{kind.replace(' ', '_')}", n), repeat)
            print(f"{kind:<14}{path.stat().st_size / 1e6:>9.1f}{t_bare:>13.3f}{t_ing:>10.3f}{t_ing / t_bare:>7.2f}{n / t_ing / 1e6:>18.2f} M")


def lake_day(days: int, seed: int = 1) -> pl.DataFrame:
    """Lake content shaped like the archive: per day 24 hourly windows of 10 s at 1 kHz.

    Values go through the export's text (7 significant digits in bar / mm) and are then
    converted to SI, as the ingest does: their float64 mantissas are full of noise.
    """
    n_win = 24 * days
    n = n_win * 10_000
    sig = signals(n, seed)
    starts = START_US + np.arange(n_win, dtype=np.int64) * 3_600_000_000
    t_us = (starts[:, None] + np.arange(10_000, dtype=np.int64)[None, :] * 1000).ravel()

    def text_round(x: np.ndarray) -> np.ndarray:  # what 4 decimals in the export's text leave
        return np.round(x, 4)

    frame = pl.DataFrame(
        {
            "valve_id": "V017",
            "timestamp_utc": pl.Series(t_us).cast(pl.Datetime("us", "UTC")),
            **{f"{s}_pa": text_round(sig[s]) * 1e5 for s in ("ps", "pr", "p1", "p2")},
            "x_spool_m": text_round(sig["x_spool"]) * 1e-3,
            "x_cyl_m": text_round(sig["x_cyl"]) * 1e-3,
            "x_ref_m": pl.repeat(None, n, dtype=pl.Float64, eager=True),
        }
    ).with_columns(date=pl.col("timestamp_utc").dt.date())
    from schemas.fields import SENSOR_FIELDS, polars_schema

    return frame.select(polars_schema(SENSOR_FIELDS).names())


def storage(seconds: int, repeat: int) -> None:
    """Lake storage variants: size, write time, decode rate, one-window read."""
    import duckdb
    import pyarrow.parquet as pq

    from flows.common.lake import STATISTICS_COLUMNS, row_group_bounds

    days = max(seconds // 240, 1)
    frame = lake_day(days)
    n = frame.height
    t_us = frame["timestamp_utc"].to_physical().to_numpy()
    channels = ["timestamp_utc", "ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m"]
    value_cols = [c for c in frame.columns if c.endswith(("_pa", "_m"))]
    print(f"lake: {days} day(s) of 24 hourly 10 s windows at 1 kHz = {n:,} rows, one file; values via 4-decimal export text → SI")
    print("rows per CPU second (one core): polars.read_parquet of timestamp + six channels, of all 10 columns;")
    print("duckdb SELECT sum() of the six channels (1 thread); window = polars scan with a time filter for one 10 s window")
    print(f"{'variant':<36}{'B/row':>7}{'write s':>9}{'6ch M/s':>9}{'all M/s':>9}{'duckdb M/s':>12}{'window ms':>11}")
    # (name, value dtype, codec, level, byte_stream_split, row groups, delta-encoded time); row
    # groups: "lake" = flows.common.lake.row_group_bounds (>= ROW_GROUP_MIN_ROWS, ending at a window
    # start), "window" = one per 10 s window, "one" = one per file
    variants = [
        ("float64 zstd-1, window groups", pl.Float64, "zstd", 1, False, "window", False),
        ("float32 zstd-1, window groups", pl.Float32, "zstd", 1, False, "window", False),
        ("float32 zstd-1 delta, window groups", pl.Float32, "zstd", 1, False, "window", True),
        ("float32 zstd-1 delta, >=64k groups", pl.Float32, "zstd", 1, False, "lake", True),
        ("float32 zstd-1 delta bss, >=64k", pl.Float32, "zstd", 1, True, "lake", True),
        ("float32 lz4 delta, window groups", pl.Float32, "lz4", None, False, "window", True),
        ("float32 lz4 delta, >=64k (lake)", pl.Float32, "lz4", None, False, "lake", True),
        ("float32 snappy delta, >=64k", pl.Float32, "snappy", None, False, "lake", True),
        ("float32 none delta, >=64k", pl.Float32, "none", None, False, "lake", True),
        ("float32 lz4 delta, 1 row group", pl.Float32, "lz4", None, False, "one", True),
    ]
    w0 = frame["timestamp_utc"][n // 2 - (n // 2) % 10_000]
    w1 = frame["timestamp_utc"][n // 2 - (n // 2) % 10_000 + 9_999]
    with tempfile.TemporaryDirectory(prefix="valvemon-bench-") as tmp:
        for name, dtype, codec, level, bss, groups, delta in variants:
            f = frame.with_columns(pl.col(value_cols).cast(dtype))
            table = f.to_arrow()
            path = Path(tmp) / f"{name.replace(' ', '_').replace('/', '_')}.parquet"
            if groups == "lake":
                bounds = row_group_bounds(t_us, 5000)
            elif groups == "one":
                bounds = [(0, n)]
            else:
                bounds = row_group_bounds(t_us, 5000, min_rows=1)

            def write() -> None:
                with pq.ParquetWriter(
                    path, table.schema, compression=codec, compression_level=level, use_dictionary=["valve_id", "date"],
                    write_statistics=STATISTICS_COLUMNS, use_byte_stream_split=value_cols if bss else False,
                    column_encoding={"timestamp_utc": "DELTA_BINARY_PACKED"} if delta else None,
                ) as w:
                    for a, b in bounds:
                        w.write_table(table.slice(a, b - a), row_group_size=b - a)

            t_w = timed(write, repeat)
            size = path.stat().st_size
            t_6 = timed(lambda: pl.read_parquet(path, columns=channels), repeat)
            t_all = timed(lambda: pl.read_parquet(path), repeat)
            con = duckdb.connect()
            con.execute("SET threads = 1")
            q = f"SELECT {', '.join(f'sum({c})' for c in channels[1:])} FROM read_parquet('{path}')"
            t_db = timed(lambda: con.execute(q).fetchall(), repeat)
            con.close()
            t_win = timed(lambda: pl.scan_parquet(path).filter(pl.col("timestamp_utc").is_between(w0, w1)).collect(), repeat)
            print(f"{name:<36}{size / n:>7.1f}{t_w:>9.3f}{n / t_6 / 1e6:>9.1f}{n / t_all / 1e6:>9.1f}{n / t_db / 1e6:>12.1f}{t_win * 1e3:>11.2f}")
        print("\nfloat32 round-off against the signal's quantisation step (16-bit over the sensor range):")
        for c, step in (("ps_pa", 400e5 / 65536), ("p1_pa", 400e5 / 65536), ("x_spool_m", 7e-3 / 65536), ("x_cyl_m", 1.0 / 65536)):
            v = frame[c].to_numpy()
            err = np.abs(v.astype(np.float32).astype(np.float64) - v).max()
            print(f"  {c:<10} max |float32 - float64| = {err:.3g}   quantisation step = {step:.3g}   ratio = {err / step:.2g}")


def stages_of(day: Path, hours: int) -> None:
    """Where the ingest of a recorded valve-day's hourly wide Parquet files goes, stage by stage:
    the first file ingested once (warm-up: numba's cache, imports), then ``hours`` files into an
    empty warehouse; CPU seconds per stage and per hour file."""
    from flows.ingest.flow import run_ingest

    files = sorted((day / "exports").glob("*.parquet"))
    config = day / "plant.toml"
    with tempfile.TemporaryDirectory(prefix="valvemon-stages-") as tmp:
        run_ingest(config, files[:1], Path(tmp) / "warm")
        wh = Path(tmp) / "wh"
        result = _stages(lambda: run_ingest(config, files[1 : 1 + hours], wh), 1, CONTINUOUS_STAGES)
    print(f"{hours} hour file(s) of {day} after a warm-up on the first; CPU s per hour file (one core):")
    for name, t in result.items():
        print(f"  {name:<46}{t / hours:>8.3f}")
    listed = sum(t for (_, _, name) in CONTINUOUS_STAGES if not name.startswith(" ") for t in [result[name]])
    print(f"  {'(other: batching, carries, Python)':<46}{(result['total'] - listed) / hours:>8.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=int, default=1000, help="length of the synthetic export at 1 kHz [s] (default 1000: 6 M long rows)")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions per measurement (median)")
    ap.add_argument("--storage", action="store_true", help="run the lake storage study instead")
    ap.add_argument("--recorder", action="store_true", help="wide recorder formats (CSV, iba ASCII, TDMS, Parquet) instead")
    ap.add_argument("--stages-of", type=Path, default=None, metavar="DAY",
                    help="stage breakdown of the ingest of a simulated valve-day (DAY/plant.toml, DAY/exports/*.parquet) instead")
    ap.add_argument("--hours", type=int, default=3, help="with --stages-of: how many hour files (after the first, the warm-up)")
    args = ap.parse_args()
    if args.stages_of:
        stages_of(args.stages_of, args.hours)
        return
    (storage if args.storage else recorder if args.recorder else throughput)(args.seconds, args.repeat)


if __name__ == "__main__":
    main()

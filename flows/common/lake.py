"""The sensor lake on disk: partition paths, atomic partition writes, reads.

Layout: ``WAREHOUSE/lake/sensors/valve_id=<id>/date=<YYYY-MM-DD>/part-0.parquet``, one file per
valve and UTC date, the canonical sensor frame of ``schemas.fields.SENSOR_FIELDS`` (keys
``valve_id`` and ``date`` inside the files too), sorted by ``timestamp_utc``.

A partition is replaced whole and atomically (:func:`write_partition`): the new content goes to
a hidden temporary file beside the partition (``.part-0.parquet.<random>.tmp``, a name no
``*.parquet`` glob matches), is flushed and fsynced, then ``os.replace`` puts it in place and
the folder is fsynced. A process killed at any moment leaves the old partition or the new one,
never a mix; a left-over temporary file is removed by the next write to that folder.

Storage choices (codec, float width, row groups) are measured and justified in
``docs/ingest.md``; they are the constants below.
"""

from __future__ import annotations

import os
import uuid
from datetime import date, datetime, timezone
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow.parquet as pq

from flows.common.instants import utc_instant
from schemas.fields import SENSOR_FIELDS, arrow_schema, polars_schema
from transforms.windows import window_starts

LAKE_DIR = Path("lake") / "sensors"
PART_NAME = "part-0.parquet"

COMPRESSION = "lz4"
"""Parquet codec of the lake (``docs/ingest.md``, "Storage"): LZ4 decodes 2× as fast as zstd
level 1 for ~20 % more disk; the monitor reads every row, so its decode speed counts most."""
COMPRESSION_LEVEL = None
"""The codec's default level."""
COLUMN_ENCODING = {"timestamp_utc": "DELTA_BINARY_PACKED"}
"""Timestamps on a uniform grid delta-encode to almost nothing: the lake is ~10 % smaller, written
~1.4× and the time column decoded ~3× faster than PLAIN + zstd (``docs/ingest.md``, "Storage")."""
STATISTICS_COLUMNS = ["timestamp_utc", "date"]
"""Columns with min/max statistics, which readers use to skip row groups by time. The valve (a
constant, named by the folder) and the signals have none: no reader prunes on them, and their
statistics made the write ~20 % slower (85 → 68 ms per 1 M rows, ``docs/ingest.md``, "Storage")."""
ROW_GROUP_MIN_ROWS = 65_536
"""A row group closes at the first window start (a gap) after this many rows (~7 hourly 10 s
windows at 1 kHz; fewer, larger pages decode ~1.7× as fast as a row group per window)…"""
ROW_GROUP_MAX_ROWS = 1_048_576
"""…or at this many rows, whichever comes first."""
ROW_GROUP_GAP_US = 5_000
"""Times further apart than this start a new window (default ``export.max_gap_s``)."""

SENSOR_ARROW_SCHEMA = arrow_schema(SENSOR_FIELDS)
SENSOR_POLARS_SCHEMA = polars_schema(SENSOR_FIELDS)


def lake_root(warehouse: str | Path) -> Path:
    """``WAREHOUSE/lake/sensors``."""
    return Path(warehouse) / LAKE_DIR


def partition_path(warehouse: str | Path, valve_id: str, day: date) -> Path:
    """The partition file of one valve and UTC date."""
    return lake_root(warehouse) / f"valve_id={valve_id}" / f"date={day.isoformat()}" / PART_NAME


def row_group_bounds(t_us: np.ndarray, gap_us: int = ROW_GROUP_GAP_US, min_rows: int = ROW_GROUP_MIN_ROWS, max_rows: int = ROW_GROUP_MAX_ROWS) -> list[tuple[int, int]]:
    """Row-group slices ``(start, stop)`` aligned to monitoring windows.

    A window is a run of samples without a gap longer than ``gap_us``. A row group ends just
    before a window start once it holds ``min_rows`` rows, and never exceeds ``max_rows``; so a
    reader that wants one window touches one row group (two if a window is longer than
    ``max_rows``), and row-group statistics on ``timestamp_utc`` let it skip the rest.
    """
    n = len(t_us)
    if n == 0:
        return []
    starts = window_starts(t_us, gap_us)
    bounds = []
    a = 0
    for s in starts[1:]:
        s = int(s)
        while s - a > max_rows:
            bounds.append((a, a + max_rows))
            a += max_rows
        if s - a >= min_rows:
            bounds.append((a, s))
            a = s
    while n - a > max_rows:
        bounds.append((a, a + max_rows))
        a += max_rows
    bounds.append((a, n))
    return bounds


def _remove_stale_temps(folder: Path) -> None:
    for p in folder.glob(f".{PART_NAME}.*.tmp"):
        try:
            p.unlink()
        except FileNotFoundError:
            pass


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_temp(tmp: Path, frame: pl.DataFrame, gap_us: int) -> None:
    """Write the frame as Parquet to ``tmp``, flushed and fsynced."""
    table = frame.to_arrow().cast(SENSOR_ARROW_SCHEMA)
    t_us = frame["timestamp_utc"].to_physical().to_numpy()
    with open(tmp, "wb") as fh:
        with pq.ParquetWriter(
            fh,
            SENSOR_ARROW_SCHEMA,
            compression=COMPRESSION,
            compression_level=COMPRESSION_LEVEL,
            use_dictionary=["valve_id", "date"],
            column_encoding=COLUMN_ENCODING,
            write_statistics=STATISTICS_COLUMNS,
            sorting_columns=[pq.SortingColumn(SENSOR_ARROW_SCHEMA.get_field_index("timestamp_utc"))],
        ) as writer:
            for a, b in row_group_bounds(t_us, gap_us):
                writer.write_table(table.slice(a, b - a), row_group_size=b - a)
        fh.flush()
        os.fsync(fh.fileno())


def _commit(tmp: Path, path: Path) -> None:
    """Put the temporary file in place (atomic on POSIX) and make the rename durable."""
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def write_partition(path: Path, frame: pl.DataFrame, *, gap_us: int = ROW_GROUP_GAP_US) -> None:
    """Replace one partition file whole and atomically (module doc).

    Parameters
    ----------
    path : Path
        The partition file (:func:`partition_path`).
    frame : DataFrame
        Its complete new content: the sensor frame, sorted by time.
    gap_us : int
        Window separation for the row groups (``export.max_gap_s`` in µs).
    """
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    _remove_stale_temps(folder)
    tmp = folder / f".{PART_NAME}.{uuid.uuid4().hex}.tmp"
    try:
        _write_temp(tmp, frame, gap_us)
        _commit(tmp, path)
    except BaseException:
        # an ordinary exception: tidy up; a killed process leaves the file to the next write
        if tmp.exists():
            tmp.unlink()
        raise


def read_partition(path: Path) -> pl.DataFrame | None:
    """One partition file as a sensor frame, None if there is none."""
    if not path.exists():
        return None
    return pl.read_parquet(path, hive_partitioning=False).cast(dict(SENSOR_POLARS_SCHEMA))


def list_partitions(warehouse: str | Path, valve_ids: list[str] | None = None, start: str | date | datetime | None = None, end: str | date | datetime | None = None) -> list[tuple[str, date, Path]]:
    """Partitions ``(valve_id, date, path)`` of the lake, optionally only some valves and dates.

    ``start`` (inclusive) and ``end`` (exclusive) select the UTC dates that can hold such times.
    """
    root = lake_root(warehouse)
    if not root.exists():
        return []
    t0, t1 = utc_instant(start), utc_instant(end)
    wanted = set(valve_ids) if valve_ids is not None else None
    out = []
    for vdir in sorted(root.glob("valve_id=*")):
        vid = vdir.name.split("=", 1)[1]
        if wanted is not None and vid not in wanted:
            continue
        for ddir in sorted(vdir.glob("date=*")):
            day = date.fromisoformat(ddir.name.split("=", 1)[1])
            if t0 is not None and day < t0.date():
                continue
            if t1 is not None and datetime(day.year, day.month, day.day, tzinfo=timezone.utc) >= t1:
                continue
            path = ddir / PART_NAME
            if path.exists():
                out.append((vid, day, path))
    return out


def read_lake(
    warehouse: str | Path,
    valve_ids: list[str] | None = None,
    start: str | date | datetime | None = None,
    end: str | date | datetime | None = None,
) -> pl.LazyFrame:
    """The sensor lake as a LazyFrame in the canonical schema, sorted by valve and time.

    Parameters
    ----------
    warehouse : path
        The warehouse folder.
    valve_ids : list of str, optional
        Only these valves.
    start, end : ISO-8601 str, date or datetime, optional
        Only samples with ``start <= timestamp_utc < end``; naive values are UTC. Partition
        folders outside the span are not opened; row-group statistics prune the rest.
    """
    parts = list_partitions(warehouse, valve_ids, start, end)
    if not parts:
        return pl.LazyFrame(schema=SENSOR_POLARS_SCHEMA)
    lf = pl.scan_parquet([str(p) for _, _, p in parts], hive_partitioning=False, schema=SENSOR_POLARS_SCHEMA)
    t0, t1 = utc_instant(start), utc_instant(end)
    # a bound at midnight UTC is a partition boundary: the partitions chosen hold no row beyond it
    if t0 is not None and not _midnight(t0):
        lf = lf.filter(pl.col("timestamp_utc") >= t0)
    if t1 is not None and not _midnight(t1):
        lf = lf.filter(pl.col("timestamp_utc") < t1)
    return lf


def _midnight(t: datetime) -> bool:
    return t.hour == t.minute == t.second == t.microsecond == 0

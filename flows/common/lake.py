"""The sensor lake on disk: partition paths, atomic partition writes, reads.

Layout: ``WAREHOUSE/lake/sensors/valve_id=<id>/date=<YYYY-MM-DD>/`` holds one valve's UTC date,
the canonical sensor frame of ``schemas.fields.SENSOR_FIELDS`` (keys ``valve_id`` and ``date``
inside the files too), each file sorted by ``timestamp_utc``, in one of two forms:

- a *day file* ``part-0.parquet`` while the day holds at most :data:`DAY_FILE_MAX_ROWS` rows
  (hourly snapshots, a few hours of continuous recording), or
- *hour files* ``part-h00.parquet`` … ``part-h23.parquet`` (the rows of that UTC hour) once it
  holds more (continuous recordings: 3.6 M rows per hour at 1 kHz), so that a file is read,
  merged and rewritten an hour at a time and memory never grows with the day.

A folder that holds ``part-0.parquet`` *is* its day file: hour files beside it are the unfinished
switch of a killed ingest (the day file is removed last, as the switch's commit) and are ignored
by :func:`day_files` and removed by :func:`repair_day`. Why these sizes: ``docs/ingest.md``.

A file is replaced whole and atomically (:func:`write_partition`, or :func:`stage_file` then
:func:`commit_files`): the new content goes to a hidden temporary file beside it
(``.part-0.parquet.<random>.tmp``, a name no ``*.parquet`` glob matches), is flushed and fsynced,
then ``os.replace`` puts it in place and the folder is fsynced. A process killed at any moment
leaves the old file or the new one, never a mix; a left-over temporary file is removed by the next
write to that folder.

Storage choices (codec, float width and encoding, row groups, the time grid record) are measured
and justified in ``docs/ingest.md``; they are the constants below.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
from datetime import date, datetime, timezone
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np
import polars as pl
import pyarrow.parquet as pq

from flows.common.instants import utc_instant
from schemas.fields import SENSOR_FIELDS, arrow_schema, polars_schema
from transforms.windows import window_starts

LAKE_DIR = Path("lake") / "sensors"
PART_NAME = "part-0.parquet"
"""The day file of a day folder."""
HOUR_NAME = "part-h{hour:02d}.parquet"
"""An hour file of a day folder (UTC hour 00–23)."""
DAY_FILE_MAX_ROWS = 4_194_304
"""A day with more rows is stored as hour files (``docs/ingest.md``, "Continuous recordings")."""
US_PER_HOUR = 3_600_000_000

COMPRESSION = "none"
"""Parquet codec of the lake by default, none (a plant's ``[lake] codec`` chooses another;
``docs/ingest.md``, "Storage"). LZ4 kept noisy float32 signals only 29 % smaller (a continuous
valve-day 19.9 against 28.0 B per lake row) and cost its decode on every read (the monitor's lake
read of a valve-day ~0.5 CPU s) and its encode on every write (the lake's writer ~0.25 s an hour
file); lake files of any codec are read as they are: Parquet names the codec per column chunk."""
COMPRESSION_LEVEL = None
"""The codec's default level (none has none)."""
COLUMN_ENCODING = {"timestamp_utc": "DELTA_BINARY_PACKED"}
"""Timestamps on a uniform grid delta-encode to almost nothing: the lake is ~10 % smaller, written
~1.4× and the time column decoded ~3× faster than PLAIN + zstd (``docs/ingest.md``, "Storage").
The floats stay PLAIN: ``BYTE_STREAM_SPLIT`` is 21 % smaller and written faster, but polars (the
monitor's and the standstill pass's reader) decodes it ~4× slower, a dearer night (same page)."""
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

TIME_GRID_KEY = "valvemon.time_grid"
"""Key of a lake file's *time grid record* (Parquet key-value metadata in the footer): for each
row group, the uniform runs ``[first_us, step_us, rows]`` its ``timestamp_utc`` values are,
exactly (value i of a run is ``first_us + i * step_us``), written by the lake's writer. A reader
that trusts it (:func:`time_grid`, checked against the row groups' row counts and time
statistics) builds the time column without decoding it (``docs/ingest.md``, "Storage")."""
TIME_DIGEST_KEY = "valvemon.time_digest"
"""Key of what binds the time grid record to the file's rows: for each row group, the BLAKE2b-128
(hex) of its ``timestamp_utc`` column chunk's bytes as written. Another program that rewrites the
file and carries the footer's key-value metadata over (pyarrow does) but reorders or moves rows
writes other bytes there, so the record is not trusted (:func:`time_grid`) even where row counts,
minima and maxima still agree. Equal bytes decode to equal time stamps."""
_PENDING_DIGEST = "?" * 32
"""What the writer puts in the footer before the digests are known (the same length)."""
TIME_GRID_MAX_RUNS = 64
"""A row group whose time stamps are more runs than this (an irregular clock) gets no record;
a file with such a row group is read by decoding its time column, as one without a record."""

SENSOR_ARROW_SCHEMA = arrow_schema(SENSOR_FIELDS)
SENSOR_POLARS_SCHEMA = polars_schema(SENSOR_FIELDS)


def lake_root(warehouse: str | Path) -> Path:
    """``WAREHOUSE/lake/sensors``."""
    return Path(warehouse) / LAKE_DIR


def partition_path(warehouse: str | Path, valve_id: str, day: date) -> Path:
    """The day file of one valve and UTC date (its folder: ``partition_path(...).parent``)."""
    return lake_root(warehouse) / f"valve_id={valve_id}" / f"date={day.isoformat()}" / PART_NAME


def hour_path(folder: Path, hour: int) -> Path:
    """The hour file of a day folder for UTC hour ``hour``."""
    return folder / HOUR_NAME.format(hour=hour)


def _hour_files(folder: Path) -> list[Path]:
    return sorted(folder.glob("part-h[0-2][0-9].parquet"))


def day_files(folder: Path) -> list[Path]:
    """The files that hold a day folder's rows, in time order (module doc): the day file if there
    is one, else the hour files."""
    day = folder / PART_NAME
    if day.exists():
        return [day]
    return _hour_files(folder)


def repair_day(folder: Path) -> None:
    """Undo the unfinished switch of a killed ingest: hour files beside a day file go (module doc)."""
    if (folder / PART_NAME).exists():
        stray = _hour_files(folder)
        for p in stray:
            p.unlink(missing_ok=True)
        if stray:
            _fsync_dir(folder)


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
    for p in folder.glob(".part-*.parquet.*.tmp"):
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


def _coalesced(frames: Iterable[pl.DataFrame], min_rows: int) -> Iterator[pl.DataFrame]:
    """The frames joined into pieces of at least ``min_rows`` rows (the last may be shorter)."""
    buffer: list[pl.DataFrame] = []
    n = 0
    for frame in frames:
        buffer.append(frame)
        n += frame.height
        if n >= min_rows:
            yield pl.concat(buffer) if len(buffer) > 1 else buffer[0]
            buffer, n = [], 0
    if buffer:
        yield pl.concat(buffer) if len(buffer) > 1 else buffer[0]


def grid_runs(t_us: np.ndarray, max_runs: int = TIME_GRID_MAX_RUNS) -> list[list[int]] | None:
    """The time stamps ``t_us`` (µs, int64, sorted) as uniform runs ``[first_us, step_us, rows]``
    (each run as long as it goes: a run ends where the step changes, the next starts at the row
    after), exactly: :func:`grid_series` of the result is ``t_us``. None if they are more than
    ``max_runs`` runs, or not strictly increasing."""
    t_us = np.asarray(t_us, dtype=np.int64)
    n = t_us.shape[0]
    if n == 0:
        return []
    d = np.diff(t_us)
    if d.size and int(d.min()) <= 0:
        return None
    change = np.flatnonzero(d[1:] != d[:-1]) + 1  # steps d[k] that differ from d[k - 1]
    if change.size > 2 * max_runs:
        return None
    runs: list[list[int]] = []
    a = 0
    while a < n:
        if len(runs) == max_runs:
            return None
        if a == n - 1:
            runs.append([int(t_us[a]), 1, 1])
            break
        k = np.searchsorted(change, a, side="right")  # the first step change after step a
        last = int(change[k]) if k < change.size else n - 1  # step d[last] differs: row `last` ends the run
        runs.append([int(t_us[a]), int(d[a]), last - a + 1])
        a = last + 1
    return runs


def _time_digests(fh, md: pq.FileMetaData) -> list[str]:
    """Per row group, the BLAKE2b-128 (hex) of its ``timestamp_utc`` column chunk's bytes in the
    open file ``fh`` (:data:`TIME_DIGEST_KEY`)."""
    col = md.schema.names.index("timestamp_utc")
    out = []
    for g in range(md.num_row_groups):
        chunk = md.row_group(g).column(col)
        fh.seek(chunk.dictionary_page_offset if chunk.has_dictionary_page else chunk.data_page_offset)
        out.append(hashlib.blake2b(fh.read(chunk.total_compressed_size), digest_size=16).hexdigest())
    return out


def _seal_digests(fh, groups: int) -> None:
    """Put the time column chunks' digests in place of the placeholder the writer left in the
    closed Parquet file ``fh`` (opened for reading and writing): the footer's length is
    unchanged (a Parquet footer carries no checksum)."""
    pending = json.dumps([_PENDING_DIGEST] * groups).encode()
    size = fh.seek(0, os.SEEK_END)
    fh.seek(size - 8)
    length = int.from_bytes(fh.read(4), "little")
    fh.seek(size - 8 - length)
    footer = fh.read(length)
    at = footer.rfind(pending)
    md = pq.ParquetFile(fh).metadata
    sealed = json.dumps(_time_digests(fh, md)).encode()
    if at < 0 or len(sealed) != len(pending):
        raise RuntimeError("the lake writer's time digest placeholder is not in the footer")
    fh.seek(size - 8 - length + at)
    fh.write(sealed)


def time_grid(md: pq.FileMetaData, source) -> list[tuple[int, int, int]] | None:
    """A lake file's time stamps as uniform runs ``(first_us, step_us, rows)`` in time order
    (runs that continue each other joined: a continuous hour file is one run), from its time grid
    record (:data:`TIME_GRID_KEY`) if it has one that agrees with the footer: one entry per row
    group, each row group's runs holding its row count, starting at its ``timestamp_utc`` minimum
    and ending at its maximum, every run and the row groups in increasing time, and every row
    group's time column chunk in ``source`` (the file's path, or the open file) holding the bytes
    :data:`TIME_DIGEST_KEY` names. None otherwise (no record, an irregular row group, a record
    that disagrees, rows rewritten under a carried-over record): the time column must be
    decoded."""
    meta = md.metadata or {}
    raw, digests = meta.get(TIME_GRID_KEY.encode()), meta.get(TIME_DIGEST_KEY.encode())
    if raw is None or digests is None:
        return None
    try:
        groups = json.loads(raw)
        col = md.schema.names.index("timestamp_utc")
    except ValueError:
        return None
    if not isinstance(groups, list) or len(groups) != md.num_row_groups:
        return None
    out: list[tuple[int, int, int]] = []
    last = None
    for g, runs in enumerate(groups):
        st = md.row_group(g).column(col).statistics
        if not isinstance(runs, list) or not runs or st is None or not st.has_min_max:
            return None
        rows = 0
        for run in runs:
            if not (isinstance(run, list) and len(run) == 3 and all(type(v) is int for v in run)):
                return None
            first, step, n = run
            if n < 1 or step < 1 or (last is not None and first <= last):
                return None
            d = first - last if out else 0
            if out and (out[-1][2] == 1 or out[-1][1] == d) and (n == 1 or step == d):
                out[-1] = (out[-1][0], d, out[-1][2] + n)  # it continues the run before
            else:
                out.append((first, step, n))
            last = first + step * (n - 1)
            rows += n
        if rows != md.row_group(g).num_rows or runs[0][0] != int(st.min_raw) or last != int(st.max_raw):
            return None
    try:
        if isinstance(source, (str, Path)):
            with open(source, "rb") as fh:
                found = _time_digests(fh, md)
        else:
            found = _time_digests(source, md)
        if json.loads(digests) != found:
            return None
    except (OSError, ValueError):
        return None
    return out


def grid_rows_before(runs: list[tuple[int, int, int]], t_us: int) -> int:
    """How many of the time stamps of uniform runs (:func:`time_grid`) lie before ``t_us``."""
    k = 0
    for first, step, n in runs:
        if t_us <= first:
            break
        k += min(n, -((first - t_us) // step))  # ceil((t_us - first) / step) of the run's rows
    return k


def grid_series(runs: list[tuple[int, int, int]], a: int, b: int, lengths: list[int] | None = None) -> pl.Series:
    """``timestamp_utc`` of rows [a, b) of uniform runs (:func:`time_grid`), built (not decoded),
    in chunks of ``lengths`` rows (default one chunk): those of the columns it joins, so that a
    frame of them keeps its chunks rather than copying them into one."""
    dtype = SENSOR_POLARS_SCHEMA["timestamp_utc"]
    pieces = []
    row = 0
    for first, step, n in runs:
        lo, hi = max(a, row), min(b, row + n)
        if lo < hi:
            pieces.append(pl.int_range(first + step * (lo - row), first + step * (hi - row), step, dtype=pl.Int64))
        row += n
    if not pieces:
        return pl.Series("timestamp_utc", [], dtype=dtype)
    t = pl.select(pl.concat(pieces) if len(pieces) > 1 else pieces[0]).to_series().rechunk().cast(dtype).alias("timestamp_utc")
    if lengths is None or len(lengths) < 2:
        return t
    out, off = t.slice(0, lengths[0]), lengths[0]
    for m in lengths[1:]:
        out.append(t.slice(off, m))
        off += m
    return out


def _write_temp(tmp: Path, frames: Iterable[pl.DataFrame], gap_us: int, codec: str) -> None:
    """Write the frames, in order, as one Parquet file to ``tmp``, flushed and fsynced; pieces
    are joined up to :data:`ROW_GROUP_MAX_ROWS` rows before being cut into row groups, and the
    file gets its time grid record (:data:`TIME_GRID_KEY`) if every row group is one, sealed with
    its time column's digests (:data:`TIME_DIGEST_KEY`)."""
    with open(tmp, "w+b") as fh:
        with pq.ParquetWriter(
            fh,
            SENSOR_ARROW_SCHEMA,
            compression=codec,
            compression_level=COMPRESSION_LEVEL,
            use_dictionary=["valve_id", "date"],
            column_encoding=COLUMN_ENCODING,
            write_statistics=STATISTICS_COLUMNS,
            sorting_columns=[pq.SortingColumn(SENSOR_ARROW_SCHEMA.get_field_index("timestamp_utc"))],
        ) as writer:
            grid: list | None = []
            for frame in _coalesced(frames, ROW_GROUP_MAX_ROWS):
                table = frame.to_arrow().cast(SENSOR_ARROW_SCHEMA)
                t_us = frame["timestamp_utc"].to_physical().to_numpy()
                for a, b in row_group_bounds(t_us, gap_us, ROW_GROUP_MIN_ROWS, ROW_GROUP_MAX_ROWS):
                    writer.write_table(table.slice(a, b - a), row_group_size=b - a)
                    runs = grid_runs(t_us[a:b]) if grid is not None else None
                    grid = None if runs is None else grid + [runs]
            if grid:
                pending = json.dumps([_PENDING_DIGEST] * len(grid))
                writer.add_key_value_metadata({TIME_GRID_KEY: json.dumps(grid, separators=(",", ":")), TIME_DIGEST_KEY: pending})
        if grid:
            _seal_digests(fh, len(grid))
        fh.flush()
        os.fsync(fh.fileno())


def _commit(tmp: Path, path: Path) -> None:
    """Put the temporary file in place (atomic on POSIX) and make the rename durable."""
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def write_partition(path: Path, frame: pl.DataFrame, *, gap_us: int = ROW_GROUP_GAP_US, codec: str = COMPRESSION) -> None:
    """Replace one partition file whole and atomically (module doc).

    Parameters
    ----------
    path : Path
        The partition file (:func:`partition_path`).
    frame : DataFrame
        Its complete new content: the sensor frame, sorted by time.
    gap_us : int
        Window separation for the row groups (``export.max_gap_s`` in µs).
    codec : str
        Parquet codec (``[lake] codec``: ``"none"``, ``"lz4"``, ``"zstd"``).
    """
    write_partition_pieces(path, [frame], gap_us=gap_us, codec=codec)


def write_partition_pieces(path: Path, frames: Iterable[pl.DataFrame], *, gap_us: int = ROW_GROUP_GAP_US, codec: str = COMPRESSION) -> None:
    """:func:`write_partition` for content that arrives in consecutive time-sorted pieces (e.g.
    streamed from a file being thinned): memory holds one row group's worth, not the file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temps(path.parent)
    tmp = _stage(path, frames, gap_us, codec)
    try:
        _commit(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def stage_file(path: Path, frame: pl.DataFrame, *, gap_us: int = ROW_GROUP_GAP_US, codec: str = COMPRESSION) -> Path:
    """Write a lake file's complete new content to a hidden temporary file beside ``path``
    (flushed, fsynced) and return it; :func:`commit_files` puts it in place."""
    return _stage(path, [frame], gap_us, codec)


def _stage(path: Path, frames: Iterable[pl.DataFrame], gap_us: int, codec: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    try:
        _write_temp(tmp, frames, gap_us, codec)
    except BaseException:
        # an ordinary exception: tidy up; a killed process leaves the file to the next write
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def stage_link(source: Path, path: Path) -> Path:
    """Stage the bytes of the lake file ``source`` as the complete new content of ``path`` (same
    folder) without a copy: a hard link under a hidden temporary name, which :func:`commit_files`
    puts in place. Neither file is written through it afterwards (every change is a new file)."""
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    os.link(source, tmp)
    return tmp


def commit_files(staged: list[tuple[Path, Path]], remove: list[Path] = ()) -> None:
    """Put staged files ``(temporary, final)`` in place in the given order, then remove the files
    ``remove`` (day files whose rows moved into hour files: their removal commits the switch)."""
    for tmp, path in staged:
        _commit(tmp, path)
    for path in remove:
        path.unlink(missing_ok=True)
        _fsync_dir(path.parent)


def clear_stale(folder: Path) -> None:
    """Before a day folder is first written in a run: left-over temporary files of killed writes
    go, and so do the hour files of an unfinished switch (:func:`repair_day`)."""
    if folder.exists():
        _remove_stale_temps(folder)
        repair_day(folder)


def read_partition(path: Path) -> pl.DataFrame | None:
    """One partition file as a sensor frame, None if there is none."""
    if not path.exists():
        return None
    return pl.read_parquet(path, hive_partitioning=False).cast(dict(SENSOR_POLARS_SCHEMA))


def list_partitions(warehouse: str | Path, valve_ids: list[str] | None = None, start: str | date | datetime | None = None, end: str | date | datetime | None = None) -> list[tuple[str, date, Path]]:
    """Lake files ``(valve_id, date, path)``, optionally only some valves and dates, in valve,
    date and time order: one per day file, or one per hour file of a day stored by the hour
    (:func:`day_files`; a date may occur several times).

    ``start`` (inclusive) and ``end`` (exclusive) select the UTC dates that can hold such times.
    """
    t0, t1 = utc_instant(start), utc_instant(end)
    out = []
    for vid, vdir in valve_folders(warehouse, valve_ids):
        for ddir in sorted(vdir.glob("date=*")):
            day = date.fromisoformat(ddir.name.split("=", 1)[1])
            if t0 is not None and day < t0.date():
                continue
            if t1 is not None and datetime(day.year, day.month, day.day, tzinfo=timezone.utc) >= t1:
                continue
            out.extend((vid, day, path) for path in day_files(ddir))
    return out


def valve_folders(warehouse: str | Path, valve_ids: list[str] | None = None) -> list[tuple[str, Path]]:
    """``(valve_id, folder)`` of the lake's ``valve_id=`` folders, optionally only some valves."""
    wanted = set(valve_ids) if valve_ids is not None else None
    out = []
    for vdir in sorted(lake_root(warehouse).glob("valve_id=*")):
        vid = vdir.name.split("=", 1)[1]
        if wanted is None or vid in wanted:
            out.append((vid, vdir))
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


# --- partitions as folders (retention) ------------------------------------------------------

DROPPED_SUFFIX = ".dropped"
"""A partition being dropped is first renamed to ``.date=<day>.<action id>.dropped`` beside the
others (hidden: no ``date=*`` glob matches it), then deleted (:func:`drop_partition`)."""


def partition_folders(warehouse: str | Path, valve_ids: list[str] | None = None) -> list[tuple[str, date, Path]]:
    """``(valve_id, date, folder)`` of every ``date=`` folder of the lake holding a ``*.parquet``
    file: the partition as retention sees it, whatever files the day is split into."""
    out = []
    for vid, vdir in valve_folders(warehouse, valve_ids):
        for ddir in sorted(vdir.glob("date=*")):
            if ddir.is_dir() and day_files(ddir):
                out.append((vid, date.fromisoformat(ddir.name.split("=", 1)[1]), ddir))
    return out


def partition_bytes(folder: Path) -> int:
    """Bytes of the partition's data files. [B]"""
    return sum(p.stat().st_size for p in day_files(folder))


def partition_rows(folder: Path) -> int:
    """Rows of the partition, from the files' footers (no data is read)."""
    return sum(pq.ParquetFile(p).metadata.num_rows for p in day_files(folder))


def iter_file_batches(
    path: Path, columns: list[str] | None = None, batch_rows: int = ROW_GROUP_MAX_ROWS, row_groups: list[int] | None = None,
) -> Iterator[pl.DataFrame]:
    """One lake file in batches of at most ``batch_rows`` rows (all columns in the canonical
    schema, or only ``columns``; all row groups or only ``row_groups``): memory holds one batch,
    never the file."""
    pf = pq.ParquetFile(path)
    schema = {c: SENSOR_POLARS_SCHEMA[c] for c in (columns or SENSOR_POLARS_SCHEMA.names())}
    if row_groups is not None and not row_groups:
        return
    for batch in pf.iter_batches(batch_size=batch_rows, columns=columns, row_groups=row_groups):
        yield pl.from_arrow(batch).cast(schema)


def read_file_ranges(path: Path, ranges: np.ndarray) -> Iterator[pl.DataFrame]:
    """The rows ``[start, stop)`` of each of ``ranges`` of one lake file, in the canonical schema,
    a range at a time: only the pages holding them are decoded (polars' slice of a scan)."""
    scan = pl.scan_parquet(path, hive_partitioning=False, schema=SENSOR_POLARS_SCHEMA)
    for start, stop in np.asarray(ranges, dtype=np.int64).tolist():
        yield scan.slice(start, stop - start).collect()


UNKNOWN_SPAN_US = (-(2**63), 2**63 - 1)
"""``(first, last)`` :func:`row_group_spans` gives a row group without statistics: all time."""


def row_group_spans(path: Path | pq.FileMetaData) -> list[tuple[int, int, int]]:
    """``(rows, first, last)`` of each row group of a lake file (or of its footer, already read):
    its rows and the range of its ``timestamp_utc`` (µs since the epoch) from the footer's
    statistics (no data is read); a group without statistics spans all time
    (:data:`UNKNOWN_SPAN_US`)."""
    md = path if isinstance(path, pq.FileMetaData) else pq.ParquetFile(path).metadata
    col = md.schema.to_arrow_schema().get_field_index("timestamp_utc")
    out = []
    for i in range(md.num_row_groups):
        rg = md.row_group(i)
        st = rg.column(col).statistics
        known = st is not None and st.has_min_max
        out.append((rg.num_rows, *((int(st.min_raw), int(st.max_raw)) if known else UNKNOWN_SPAN_US)))
    return out


def drop_partition(folder: Path, action_id: str) -> Path:
    """Take a partition out of the lake in one atomic step: rename its ``date=`` folder to a
    hidden name in the same parent and fsync the parent. Returns the hidden folder, which
    :func:`remove_dropped` deletes (a crash in between leaves it to :func:`dropped_folders`)."""
    hidden = folder.parent / f".{folder.name}.{action_id}{DROPPED_SUFFIX}"
    os.rename(folder, hidden)
    _fsync_dir(folder.parent)
    return hidden


def dropped_folders(warehouse: str | Path, valve_ids: list[str] | None = None) -> list[tuple[str, date, str, Path]]:
    """``(valve_id, date, action_id, folder)`` of partitions renamed by :func:`drop_partition`
    whose deletion has not finished (a killed run)."""
    out = []
    for vid, vdir in valve_folders(warehouse, valve_ids):
        for hidden in sorted(vdir.glob(f".date=*{DROPPED_SUFFIX}")):
            day, action_id = hidden.name[len(".date="):-len(DROPPED_SUFFIX)].split(".", 1)
            out.append((vid, date.fromisoformat(day), action_id, hidden))
    return out


def remove_dropped(hidden: Path) -> None:
    """Delete a dropped partition's hidden folder (:func:`drop_partition`) and fsync the parent."""
    shutil.rmtree(hidden)
    _fsync_dir(hidden.parent)


def remove_partition_file(path: Path) -> None:
    """Delete one of a partition's files (thinning left nothing of it) and fsync the folder."""
    path.unlink()
    _fsync_dir(path.parent)

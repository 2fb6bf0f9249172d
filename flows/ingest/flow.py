"""``valvemon ingest``: historian exports into the sensor lake (the Prefect flow and its plain core).

:func:`run_ingest` does the work file by file: read the export (:func:`read_export`), turn it into
lake partitions (``transforms.ingest.process_export``), merge each with the stored partition and
replace it atomically (``flows.common.lake``), then record the file in the manifest together with its
quarantined samples and gaps in one DuckDB transaction. A file whose content hash is in the
manifest is skipped (``force`` re-reads it; the lake then stays the same unless the
configuration changed). A run that dies part-way can simply be run again: a file is in the
manifest only after all its partitions are written, and merging rows the lake already holds
changes nothing, so the rerun ends with the same lake as one clean run.

:func:`ingest_flow` is the Prefect flow the command line runs: one task per file.
Method, rules and counts: ``docs/ingest.md``.
"""

from __future__ import annotations

import gzip
import hashlib
import mmap
import os
import re
import uuid
import zlib
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
from blake3 import blake3

from flows.common.allocator import retain_freed_memory
from flows.common.config import load_plant_config
from flows.common.errors import ValvemonError
from flows.common.lake import partition_path, read_partition, write_partition
from flows.common.locks import file_lock
from flows.common.prefect_run import flow, task
from flows.common.warehouse_db import connect, ensure_ingest_tables, insert_frame, transaction
from schemas.fields import GAP_FIELDS, GAP_SCHEMA, INGEST_RUN_FIELDS, MANIFEST_FIELDS, QUARANTINE_FIELDS, QUARANTINE_SCHEMA, polars_schema
from schemas.plant_config import ConfigError, ExportSpec, PlantConfig
from transforms.ingest import Grid, IngestError, TagTable, merge_partition, process_export, tags_by_column

EXPORT_SUFFIXES = (".csv", ".csv.gz", ".txt", ".tsv", ".tsv.gz", ".txt.gz", ".parquet", ".pq")
"""Files a folder argument contributes (searched recursively, sorted by path)."""

_GZIP_MAGIC = b"\x1f\x8b"
_PARQUET_MAGIC = b"PAR1"
_NOT_BLANK = re.compile(rb"\S")

HASH_PREFIX = "blake3:"
"""The manifest's content hash is ``blake3:<64 hex digits>`` (BLAKE3-256 of the file's bytes)."""
LEGACY_HASH_PREFIX = "sha256:"
"""Files ingested before BLAKE3 keep their SHA-256, ``sha256:<64 hex digits>`` (docs/ingest.md)."""


def content_hash(data) -> str:
    """The manifest's content hash of a file's bytes (any buffer: bytes, mmap): ``blake3:<hex>``."""
    return HASH_PREFIX + blake3(data).hexdigest()


def legacy_hash(path: Path) -> str:
    """The content hash the manifest held before BLAKE3: ``sha256:<hex>`` of the file's bytes."""
    with _mapped(path) as data:
        return LEGACY_HASH_PREFIX + hashlib.sha256(data).hexdigest()


@contextmanager
def _mapped(path: Path) -> Iterator[mmap.mmap | bytes]:
    """The file's bytes, memory-mapped (no copy; ``b""`` for an empty file)."""
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            yield b""
            return
        data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield data
        finally:
            data.close()


# --- files -----------------------------------------------------------------------------------


def discover_files(paths: list[str | Path]) -> list[Path]:
    """The export files named by the arguments: files as given, folders searched recursively.

    Raises
    ------
    ValvemonError
        For a path that does not exist, or when nothing is found.
    """
    out: list[Path] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(f for f in p.rglob("*") if f.is_file() and f.name.lower().endswith(EXPORT_SUFFIXES) and not f.name.startswith("."))
        elif p.exists():
            found = [p]
        else:
            raise ValvemonError(f"{p}: no such file or folder")
        for f in found:
            key = f.resolve()
            if key not in seen:
                seen.add(key)
                out.append(f)
    if not out:
        raise ValvemonError(f"no export files ({', '.join(EXPORT_SUFFIXES)}) in {', '.join(map(str, paths))}")
    return out


def sniff_format(path: Path, head: bytes) -> str:
    """``"parquet"``, ``"csv.gz"`` or ``"csv"``, from the file's first bytes (then its name)."""
    if head.startswith(_PARQUET_MAGIC):
        return "parquet"
    if head.startswith(_GZIP_MAGIC):
        return "csv.gz"
    if path.name.lower().endswith((".parquet", ".pq")):
        return "parquet"
    return "csv"


def _csv_options(export: ExportSpec, encoding: str = "utf8") -> dict:
    return {
        "separator": export.separator,
        "decimal_comma": export.decimal == ",",
        "infer_schema": False,
        "encoding": encoding,
        "quote_char": '"',
    }


def _value_columns(columns: list[str], export: ExportSpec) -> list[str]:
    if export.layout == "long":
        return [export.value_column] if export.value_column in columns else []
    skip = {export.timestamp_column, export.quality_column}
    return [c for c in columns if c not in skip]


def read_csv_export(data: bytes | Path, export: ExportSpec, tags: TagTable | None = None) -> pl.DataFrame:
    """A CSV export's bytes (decompressed), or its file, → frame in file order.

    Value columns are read as Float64 and, in the long layout, the tag column as an Enum of
    the plant's tags (the fast path). Only if that fails (a cell that is no number, a tag the
    plant does not have, bytes that are not UTF-8) is the file read again with those columns
    as text (invalid UTF-8 replaced), so that quarantine and the error message can show what
    the file says.
    """
    opts = _csv_options(export)
    try:
        header = pl.read_csv(data, n_rows=0, **opts).columns
    except pl.exceptions.ComputeError:
        opts = _csv_options(export, "utf8-lossy")  # not UTF-8 (e.g. Latin-1 headers): keep going
        header = pl.read_csv(data, n_rows=0, **opts).columns
    values = _value_columns(header, export)
    overrides: dict[str, pl.DataType] = {c: pl.Float64 for c in values}
    if export.layout == "long" and tags is not None and export.tag_column in header:
        overrides[export.tag_column] = tags.enum
    try:
        return pl.read_csv(data, schema_overrides=overrides, **opts)
    except pl.exceptions.ComputeError:
        pass  # a value that is no number, a tag the plant does not have, bad UTF-8: the careful path
    opts = _csv_options(export, "utf8-lossy")
    overrides.pop(export.tag_column, None)
    df = pl.read_csv(data, schema_overrides=overrides, ignore_errors=True, **opts)
    suspicious = [c for c in values if df[c].null_count()]
    if suspicious:
        text = pl.read_csv(data, columns=suspicious, **opts)
        df = df.with_columns([text[c] for c in suspicious])
    return df


def _is_text(t: pa.DataType) -> bool:
    return pa.types.is_string(t) or pa.types.is_large_string(t) or pa.types.is_string_view(t)


def enum_column(col: pa.ChunkedArray, categories: tuple[str, ...] | None = None) -> pl.Series | None:
    """A dictionary-encoded text column → a polars Enum, by its codes: no row's text is decoded.

    ``categories`` are the Enum's (the plant's tags); None: the column's distinct values. Each
    chunk's codes go through a lookup table of its own dictionary (Parquet has one per row
    group). Returns None when a value is not one of ``categories`` or a dictionary holds a null,
    so that the caller decodes the text and can name the value.
    """
    dictionaries = [ch.dictionary.to_pylist() for ch in col.chunks]
    if categories is None:
        categories = tuple(dict.fromkeys(v for d in dictionaries for v in d))
    position = {c: i for i, c in enumerate(categories)}
    if None in position or any(v not in position for d in dictionaries for v in d):
        return None
    enum = pl.Enum(list(categories))
    if len(categories) == 1 and not col.null_count:  # one code throughout (quality "Good")
        return pl.repeat(categories[0], len(col), dtype=enum, eager=True)
    physical = pl.Series(dtype=enum).to_physical().to_numpy().dtype
    codes = np.empty(len(col), dtype=physical)
    a = 0
    for ch, d in zip(col.chunks, dictionaries):
        lut = np.array([position[v] for v in d], dtype=physical)
        b = a + len(ch)
        np.take(lut, ch.indices.fill_null(0).to_numpy(), out=codes[a:b])
        a = b
    series = pl.Series(codes)
    if col.null_count:
        series = series.scatter(np.flatnonzero(col.is_null().to_numpy()), None)
    return series.cat.to(enum)


def read_parquet_export(path: Path, export: ExportSpec, tags: TagTable | None = None) -> pl.DataFrame:
    """A Parquet export → frame in file order.

    The tag and quality columns, when they hold text, are read dictionary-encoded (as Parquet
    stores such columns) and become Enum columns from their codes, without decoding a string
    per row: the tag column an Enum of the plant's tags (when every tag of the file is one,
    else text, so that the error names the tag), the quality column an Enum of its codes.
    """
    schema = pq.read_schema(path)
    wanted = [export.tag_column if export.layout == "long" else None, export.quality_column]
    coded = [c for c in wanted if c and c in schema.names and _is_text(schema.field(c).type)]
    if not coded:
        return pl.read_parquet(path)
    table = pq.read_table(path, columns=coded, read_dictionary=coded)
    columns = []
    for name in coded:
        col = table[name]
        enum = enum_column(col, tags.tags if tags is not None and name == export.tag_column else None)
        columns.append((enum if enum is not None else pl.from_arrow(col.cast(col.type.value_type))).alias(name))
    rest = [c for c in schema.names if c not in coded]  # polars decodes these faster than Arrow
    df = pl.read_parquet(path, columns=rest).with_columns(columns) if rest else pl.DataFrame(columns)
    return df.select(schema.names)


@dataclass
class ExportFile:
    """An export as read: its frame, where its rows start, and what identifies the file."""

    frame: pl.DataFrame
    first_line: int
    file_format: str
    file_hash: str
    """:func:`content_hash` of the file's bytes."""
    size_bytes: int
    path: Path | None = None


def read_export(path: Path, export: ExportSpec, tags: TagTable | None = None) -> ExportFile:
    """Read one export file (CSV, gzip CSV or Parquet) and hash its bytes.

    The file is memory-mapped and hashed (:func:`content_hash`) without a copy; a plain CSV or
    Parquet file is then decoded from the file by polars / Arrow (a gzip file from the
    decompressed bytes).

    Raises
    ------
    ValvemonError
        Naming the file: unreadable, empty, truncated gzip, not CSV/Parquet.
    """
    path = Path(path)
    empty = f"{path}: empty file (expected a {export.layout} export with a header line)"
    try:
        with _mapped(path) as raw:
            size = len(raw)
            if not size:
                raise ValvemonError(empty)
            digest = content_hash(raw)
            fmt = sniff_format(path, bytes(raw[:4]))
            data: bytes | Path = path
            if fmt == "csv.gz":
                try:
                    data = gzip.decompress(raw)
                except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
                    raise ValvemonError(f"{path}: truncated or corrupt gzip file ({exc})") from None
                if not data or data.isspace():
                    raise ValvemonError(f"{path}: empty file inside the gzip (expected a {export.layout} export with a header line)")
            elif fmt == "csv" and _NOT_BLANK.search(raw) is None:
                raise ValvemonError(empty)
    except (OSError, ValueError) as exc:
        raise ValvemonError(f"{path}: cannot read the file ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        if fmt == "parquet":
            df = read_parquet_export(path, export, tags)
            first_line = 1
        else:
            df = read_csv_export(data, export, tags)
            first_line = 2
    except ValvemonError:
        raise
    except (pl.exceptions.PolarsError, pa.ArrowException, OSError, ValueError) as exc:
        kind = "Parquet" if fmt == "parquet" else "CSV"
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValvemonError(f"{path}: not a readable {kind} export ({reason})") from None
    if df.height == 0:
        raise ValvemonError(f"{path}: no data rows (only a header)")
    return ExportFile(df, first_line, fmt, digest, size, path)


# --- one file --------------------------------------------------------------------------------


@dataclass
class FileReport:
    """What ingesting one file did."""

    path: str
    file_hash: str
    skipped: bool = False
    rows_in: int = 0
    samples_in: int = 0
    quarantined: int = 0
    duplicates: int = 0
    conflicts: int = 0
    gaps: int = 0
    rows_out: int = 0
    rows_added: int = 0
    lake_conflicts: int = 0
    partitions: int = 0
    partitions_written: int = 0
    valves: tuple[str, ...] = ()


def _now() -> datetime:
    return datetime.now(timezone.utc)


def in_manifest(warehouse: Path, ef: ExportFile | str) -> bool:
    """Whether the manifest already holds a file with this content (an :class:`ExportFile`, or a
    content hash).

    A manifest row of an older warehouse holds the file's SHA-256 (``sha256:…``); only when one
    such row has the file's size is the file's SHA-256 computed, and on a match the file's rows
    are re-keyed to its BLAKE3 hash (:func:`rekey_file`), so the next run matches it at once.
    """
    if not (Path(warehouse) / "valvemon.duckdb").exists():
        return False
    file_hash = ef if isinstance(ef, str) else ef.file_hash
    with connect(warehouse) as con:
        ensure_ingest_tables(con)
        if con.execute("SELECT count(*) FROM ingest_manifest WHERE file_hash = ?", [file_hash]).fetchone()[0] > 0:
            return True
        if isinstance(ef, str) or ef.path is None:
            return False
        legacy = {r[0] for r in con.execute(
            "SELECT file_hash FROM ingest_manifest WHERE size_bytes = ? AND starts_with(file_hash, ?)", [ef.size_bytes, LEGACY_HASH_PREFIX]
        ).fetchall()}  # fmt: skip
        if not legacy:
            return False
        old = legacy_hash(ef.path)
        if old not in legacy:
            return False
        rekey_file(con, old, file_hash)
        return True


def rekey_file(con, old: str, new: str) -> None:
    """Give a file's rows (manifest, quarantine, gaps, backfill progress) the content hash ``new``
    instead of ``old`` (its legacy SHA-256), in one transaction."""
    tables = ["ingest_manifest", "quarantine", "ingest_gaps"]
    if con.execute("SELECT count(*) FROM duckdb_tables() WHERE database_name = current_database() AND table_name = 'backfill_progress'").fetchone()[0]:
        tables.append("backfill_progress")
    with transaction(con):
        for t in tables:
            con.execute(f"UPDATE {t} SET file_hash = ? WHERE file_hash = ?", [new, old])


def _table(frame: pl.DataFrame, fields) -> pl.DataFrame:
    return frame.select([f.name for f in fields]).cast(dict(polars_schema(fields)))


def ingest_file(path: str | Path, config: PlantConfig, warehouse: str | Path, run_id: str, *, force: bool = False, tags: TagTable | None = None) -> FileReport:
    """Ingest one export file into the lake and record it (module doc).

    Raises
    ------
    ValvemonError
        Naming the file and, where it applies, the line, tag, time and what was expected.
    """
    path, warehouse = Path(path), Path(warehouse)
    retain_freed_memory()  # the next file's arrays reuse this one's heap: no page faults (flows/common/allocator.py)
    tags = tags or TagTable.from_config(config)
    ef = read_export(path, config.export, tags)
    if not force and in_manifest(warehouse, ef):
        return FileReport(str(path), ef.file_hash, skipped=True)
    report, records = merge_export(path, ef, config, warehouse, run_id, tags)
    record_file(warehouse, *records)
    return report


def _unlocked(target: Path) -> AbstractContextManager:
    return nullcontext()


def merge_export(
    path: Path,
    ef: ExportFile,
    config: PlantConfig,
    warehouse: Path,
    run_id: str,
    tags: TagTable,
    lock: Callable[[Path], AbstractContextManager] = _unlocked,
) -> tuple[FileReport, tuple[dict, pl.DataFrame, pl.DataFrame]]:
    """Turn a read export into lake partitions and merge each into the lake.

    ``lock(target)`` is held around each partition's read-merge-write. Returns the file's
    report and its database rows (:func:`file_records`), which the caller writes.

    Raises
    ------
    ValvemonError
        Naming the file and what is wrong with its content.
    """
    export = config.export
    report = FileReport(str(path), ef.file_hash)
    try:
        result = process_export(ef.frame, config, first_line=ef.first_line, tags=tags)
    except IngestError as exc:
        raise ValvemonError(f"{path}: {exc}") from None
    c = result.counts
    report.rows_in, report.samples_in, report.quarantined = c.rows_in, c.samples_in, c.quarantined
    report.duplicates, report.conflicts, report.gaps, report.rows_out = c.duplicates, c.conflicts, c.gaps, c.rows_out
    report.valves = c.valves
    report.partitions = len(result.partitions)
    gap_us = max(int(round(export.max_gap_s * 1e6)), 1)
    for part in result.partitions:
        target = partition_path(warehouse, part.valve_id, part.date)
        with lock(target):
            try:
                merged = merge_partition(read_partition(target), part.frame, export.duplicate_rule, tags_by_column(config, part.valve_id))
            except IngestError as exc:
                raise ValvemonError(f"{path}: {exc}") from None
            report.rows_added += merged.rows_added
            report.lake_conflicts += merged.lake_conflicts
            if merged.changed:
                write_partition(target, merged.frame, gap_us=gap_us)
                report.partitions_written += 1
    return report, file_records(path, ef, result, report, run_id, export.layout)


def file_records(path: Path, ef: ExportFile, result, report: FileReport, run_id: str, layout: str) -> tuple[dict, pl.DataFrame, pl.DataFrame]:
    """The manifest row, quarantine rows and gap rows of one ingested file, per the registry."""
    now = _now()
    extra = {"file_hash": ef.file_hash, "source_file": str(path), "run_id": run_id, "ingested_at": now}
    quarantine = _table(result.quarantine.with_columns(**{k: pl.lit(v) for k, v in extra.items()}), QUARANTINE_FIELDS)
    QUARANTINE_SCHEMA.validate(quarantine, lazy=True)
    gaps = _table(result.gaps.with_columns(file_hash=pl.lit(ef.file_hash), source_file=pl.lit(str(path))), GAP_FIELDS)
    GAP_SCHEMA.validate(gaps, lazy=True)
    c = result.counts
    manifest = {
        "file_hash": ef.file_hash,
        "source_file": str(path),
        "size_bytes": ef.size_bytes,
        "file_format": ef.file_format,
        "layout": layout,
        "rows_in": c.rows_in,
        "samples_in": c.samples_in,
        "quarantined": c.quarantined,
        "duplicates": c.duplicates,
        "conflicts": c.conflicts,
        "gaps": c.gaps,
        "rows_out": c.rows_out,
        "rows_added": report.rows_added,
        "lake_conflicts": report.lake_conflicts,
        "partitions": report.partitions,
        "valves": ",".join(c.valves),
        "time_start": c.time_start,
        "time_end": c.time_end,
        "run_id": run_id,
        "ingested_at": now,
    }
    return manifest, quarantine, gaps


def record_file(warehouse: Path, manifest: dict, quarantine: pl.DataFrame, gaps: pl.DataFrame) -> None:
    """Write one file's manifest row, quarantine and gaps in one transaction.

    Earlier quarantine and gap rows of the same content hash are replaced, so a file ingested
    again (``force``, or after a crash) is never counted twice.
    """
    key = manifest["file_hash"]
    with connect(warehouse) as con:
        ensure_ingest_tables(con)
        with transaction(con):
            con.execute("DELETE FROM quarantine WHERE file_hash = ?", [key])
            con.execute("DELETE FROM ingest_gaps WHERE file_hash = ?", [key])
            insert_frame(con, "quarantine", quarantine)
            insert_frame(con, "ingest_gaps", gaps)
            insert_frame(con, "ingest_manifest", pl.DataFrame([manifest], schema=polars_schema(MANIFEST_FIELDS)), replace=True)


# --- a run -----------------------------------------------------------------------------------


@dataclass
class RunSummary:
    """Counts of one ingest run (also stored in ``ingest_runs``)."""

    run_id: str
    files_seen: int = 0
    files_ingested: int = 0
    files_skipped: int = 0
    rows_read: int = 0
    samples_read: int = 0
    rows_written: int = 0
    rows_added: int = 0
    quarantined: int = 0
    duplicates: int = 0
    conflicts: int = 0
    lake_conflicts: int = 0
    gaps: int = 0
    partitions_written: int = 0
    files: list[FileReport] = field(default_factory=list)

    def add(self, r: FileReport) -> None:
        self.files.append(r)
        if r.skipped:
            self.files_skipped += 1
            return
        self.files_ingested += 1
        self.rows_read += r.rows_in
        self.samples_read += r.samples_in
        self.rows_written += r.rows_out
        self.rows_added += r.rows_added
        self.quarantined += r.quarantined
        self.duplicates += r.duplicates
        self.conflicts += r.conflicts
        self.lake_conflicts += r.lake_conflicts
        self.gaps += r.gaps
        self.partitions_written += r.partitions_written

    def counts(self) -> dict:
        d = asdict(self)
        d.pop("files")
        return d

    def line(self) -> str:
        """The one-line summary the command prints."""
        return summary_line(self.counts())


def summary_line(c: dict) -> str:
    """One line of a run's counts (:meth:`RunSummary.counts`)."""
    skipped = f" ({c['files_skipped']} already ingested, skipped)" if c["files_skipped"] else ""
    return (
        f"ingested {c['files_ingested']} of {c['files_seen']} files{skipped}: "
        f"{c['rows_read']:,} rows read, {c['rows_written']:,} lake rows written "
        f"({c['rows_added']:,} new) in {c['partitions_written']} partitions, "
        f"{c['quarantined']:,} quarantined, {c['duplicates']:,} duplicates, "
        f"{c['conflicts'] + c['lake_conflicts']:,} conflicts, {c['gaps']:,} gaps"
    )


def ingest_lock(warehouse: Path) -> AbstractContextManager:
    """One ingest at a time per warehouse (an advisory lock on ``WAREHOUSE/.ingest.lock``)."""
    return file_lock(warehouse / ".ingest.lock", f"{warehouse}: another ingest is running on this warehouse")


def _run_row(summary: RunSummary, started: datetime, config_file: str, status: str, message: str | None) -> pl.DataFrame:
    row = summary.counts() | {
        "started_at": started,
        "finished_at": None if status == "running" else _now(),
        "status": status,
        "message": message,
        "config_file": config_file,
    }
    return pl.DataFrame([{f.name: row[f.name] for f in INGEST_RUN_FIELDS}], schema=polars_schema(INGEST_RUN_FIELDS))


def _store_run(warehouse: Path, row: pl.DataFrame) -> None:
    with connect(warehouse) as con:
        ensure_ingest_tables(con)
        insert_frame(con, "ingest_runs", row, replace=True)


FileRunner = Callable[..., FileReport]


def preflight(config_path: str | Path, paths: list[str | Path]) -> tuple[PlantConfig, list[Path]]:
    """The configuration (with a grid the lake can hold) and the export files, or the error.

    Cheap; the command line calls it before the Prefect flow starts, so a typo costs no server.
    """
    config = load_plant_config(config_path)
    try:
        Grid.from_export(config.export.sample_rate_hz, config.export.max_gap_s)
    except IngestError as exc:
        raise ConfigError(f"{config_path}: {exc}") from None
    return config, discover_files(paths)


def run_ingest(
    config_path: str | Path,
    paths: list[str | Path],
    warehouse: str | Path,
    *,
    force: bool = False,
    show_progress: bool = False,
    file_runner: FileRunner | None = None,
) -> RunSummary:
    """Ingest export files into the lake, file by file; the counts are stored in ``ingest_runs``.

    Parameters
    ----------
    config_path : path
        The plant configuration.
    paths : list of path
        Export files and folders (searched recursively for :data:`EXPORT_SUFFIXES`), taken in
        the order given (a folder's files sorted by path). With ``duplicate_rule = "last"``
        a later file wins over an earlier one where they disagree.
    warehouse : path
        The warehouse folder.
    force : bool
        Read files again even if the manifest already holds their content hash.
    show_progress : bool
        A rich progress bar on stderr (only when stderr is a terminal).
    file_runner : callable, optional
        Runs one file (``ingest_file``'s signature); the Prefect flow passes its task.

    Raises
    ------
    ValvemonError
        The first file that cannot be ingested (files before it stay ingested); the run is
        stored with status ``failed`` and the message.
    """
    warehouse = Path(warehouse)
    config, files = preflight(config_path, paths)
    runner = file_runner or ingest_file
    tags = TagTable.from_config(config)
    summary = RunSummary(run_id=f"{_now():%Y%m%dT%H%M%SZ}-{uuid.uuid4().hex[:8]}", files_seen=len(files))
    started = _now()
    with ingest_lock(warehouse):
        _store_run(warehouse, _run_row(summary, started, str(config_path), "running", None))
        try:
            with _progress(files, show_progress) as advance:
                for f in files:
                    summary.add(runner(f, config, warehouse, summary.run_id, force=force, tags=tags))
                    advance(f)
        except BaseException as exc:
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            _store_run(warehouse, _run_row(summary, started, str(config_path), "failed", message))
            raise
        _store_run(warehouse, _run_row(summary, started, str(config_path), "ok", None))
    return summary


@contextmanager
def _progress(files: list[Path], show: bool) -> Iterator[Callable[[Path], None]]:
    """A rich progress bar over the files' bytes (stderr, terminals only)."""
    from rich.console import Console
    from rich.progress import BarColumn, DownloadColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    console = Console(stderr=True)
    if not show or not console.is_terminal:
        yield lambda f: None
        return
    sizes = {f: (f.stat().st_size if f.exists() else 0) for f in files}
    columns = (TextColumn("ingest"), BarColumn(), DownloadColumn(), TextColumn("files"), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console, transient=True) as progress:
        bar = progress.add_task("ingest", total=sum(sizes.values()) or 1)
        files_bar = progress.add_task("files", total=len(files), visible=False)

        def advance(f: Path) -> None:
            progress.advance(bar, sizes.get(f, 0))
            progress.advance(files_bar, 1)

        yield advance


# --- Prefect ---------------------------------------------------------------------------------


@task(name="ingest-file", persist_result=False)
def ingest_file_task(path: Path, config: PlantConfig, warehouse: Path, run_id: str, *, force: bool = False, tags: TagTable | None = None) -> FileReport:
    """One export file into the lake (:func:`ingest_file`)."""
    return ingest_file(path, config, warehouse, run_id, force=force, tags=tags)


@flow(name="valvemon-ingest", persist_result=False, validate_parameters=False)
def ingest_flow(config_path: str, paths: list[str], warehouse: str, force: bool = False, show_progress: bool = False) -> dict:
    """Historian exports into the sensor lake; returns the run's counts (:class:`RunSummary`)."""
    summary = run_ingest(config_path, paths, warehouse, force=force, show_progress=show_progress, file_runner=ingest_file_task)
    return summary.counts()

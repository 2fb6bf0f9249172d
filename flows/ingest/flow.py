"""``valvemon ingest``: historian exports into the sensor lake (the Prefect flow and its plain core).

:func:`run_ingest` does the work file by file: tell the file's format and hash it
(``flows.ingest.formats.open_export``; a file whose content hash is in the manifest is skipped,
``force`` re-reads it), read it in bounded batches (``flows.ingest.formats.iload``, the one reader
of every format), turn each into lake rows
(``transforms.ingest.stream.ExportStream``), merge them with the lake's files into staged files
that are put in place together after the last batch (``flows.ingest.staging``,
``flows.common.lake``), then record the file in the manifest together with its quarantined
samples and gaps in one DuckDB transaction. A run that dies part-way can simply be run again: a
file is in the manifest only after all its lake files are in place, and merging rows the lake
already holds changes nothing, so the rerun ends with the same lake as one clean run.

:func:`ingest_flow` is the Prefect flow the command line runs: one task per file.
Method, rules and counts: ``docs/ingest.md``.
"""

from __future__ import annotations

import sys
import uuid
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Iterable, Iterator

import polars as pl

from flows.common.allocator import retain_freed_memory
from flows.common.config import load_plant_config
from flows.common.errors import ValvemonError
from flows.common.locks import file_lock
from flows.common.prefect_run import flow, task
from flows.common.warehouse_db import connect, ensure_ingest_tables, insert_frame, transaction
from flows.ingest.hashing import LEGACY_HASH_PREFIX, legacy_hash
from flows.ingest.spill import QuarantineRows, QuarantineSpill
from schemas.fields import GAP_FIELDS, INGEST_RUN_FIELDS, MANIFEST_FIELDS, polars_schema, validate_table
from schemas.plant_config import ConfigError, PlantConfig
from transforms.ingest import ExportCounts, Grid, IngestError, TagTable


@dataclass
class FileReport:
    """What ingesting one file did: its identity and its counts (None: skipped, already ingested)."""

    path: str
    file_hash: str
    counts: ExportCounts | None = None

    @property
    def skipped(self) -> bool:
        return self.counts is None


def _now() -> datetime:
    return datetime.now(timezone.utc)


def in_manifest(warehouse: Path, ef) -> bool:
    """Whether the manifest already holds a file with this content (an
    ``flows.ingest.formats.ExportSource``, or a content hash).

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

    The file is hashed first (a file in the manifest is not read), then read, processed and
    merged batch by batch (:func:`merge_export`), so memory does not grow with the file.

    Raises
    ------
    ValvemonError
        Naming the file and, where it applies, the line, tag, time and what was expected.
    """
    from flows.ingest.formats import open_export

    path, warehouse = Path(path), Path(warehouse)
    retain_freed_memory()  # the next file's arrays reuse this one's heap: no page faults (flows/common/allocator.py)
    tags = tags or TagTable.from_config(config)
    src = open_export(path, config.export, config.timezone)
    if not force and in_manifest(warehouse, src):
        return FileReport(str(path), src.file_hash)
    report, records = merge_export(src, config, warehouse, run_id, tags)
    record_file(warehouse, *records)
    return report


def _unlocked(target: Path) -> AbstractContextManager:
    return nullcontext()


def merge_export(
    src,
    config: PlantConfig,
    warehouse: Path,
    run_id: str,
    tags: TagTable,
    lock: Callable[[Path], AbstractContextManager] = _unlocked,
) -> tuple[FileReport, tuple[dict, QuarantineRows, pl.DataFrame]]:
    """Read an opened export (``flows.ingest.formats.open_export``) batch by batch into the lake
    (:func:`merge_batches`); an export whose order does not allow that (``NotStreamable``: times
    going back across a batch edge, tags one after the other) is read again by the same reader
    as one batch. Returns the file's report and its database rows, which the caller writes."""
    from flows.ingest.formats import iload
    from transforms.ingest.stream import NotStreamable

    try:
        return merge_batches(src, iload(src, config.export, tags), config, warehouse, run_id, tags, lock)
    except NotStreamable:
        return merge_batches(src, iload(src, config.export, tags, whole=True), config, warehouse, run_id, tags, lock)


def merge_batches(
    src,
    batches: Iterable[tuple[pl.DataFrame, int, bool]],
    config: PlantConfig,
    warehouse: Path,
    run_id: str,
    tags: TagTable,
    lock: Callable[[Path], AbstractContextManager] = _unlocked,
) -> tuple[FileReport, tuple[dict, QuarantineRows, pl.DataFrame]]:
    """Turn an export's batches into lake rows and merge them into the lake's files.

    ``src`` is the export's ``ExportSource`` (identity, units, start time). The files are staged
    and committed together after the last batch (``flows.ingest.staging``); ``lock(day file)`` is
    held from a day folder's first write to the commit. Returns the file's report and its
    database rows (:func:`file_records`), which the caller writes.

    Raises
    ------
    ValvemonError
        Naming the file and what is wrong with its content (nothing of it reaches the lake).
    NotStreamable
        The export cannot be taken batch by batch (nothing of it reached the lake).
    """
    from flows.ingest.staging import LakeStager
    from transforms.ingest.stream import ExportStream
    from transforms.ingest.units import tags_with_file_units

    path = src.path
    now = _now()
    stager = LakeStager(warehouse, config, lock)
    spill = QuarantineSpill({"file_hash": src.file_hash, "source_file": str(path), "run_id": run_id, "ingested_at": now})
    try:
        stream = ExportStream(config, tags_with_file_units(tags, config, src.units), origin_ns=src.origin_ns)  # the file's own units, where it states them
        for df, first_line, final in batches:
            for frame in stream.feed(df, first_line=first_line, final=final):
                stager.add(frame)
            stager.flush(None if final else stream.given_to())
            spill.take(stream.quarantine, final)
        stager.commit()
    except IngestError as exc:
        stager.discard()
        spill.rows.remove()
        raise ValvemonError(f"{path}: {exc}") from None
    except BaseException:
        stager.discard()
        spill.rows.remove()
        raise
    finally:
        stager.release()
    c = stream.counts
    if c.clock_step_message:  # ingested, with the rows after the step quarantined: say so
        print(f"valvemon: warning: {path}: {c.clock_step_message}", file=sys.stderr)
    c.partitions, c.partitions_written = len(stager.days), len(stager.days_written)
    c.rows_added, c.lake_conflicts = stager.rows_added, stager.lake_conflicts
    return FileReport(str(path), src.file_hash, c), file_records(src, c, spill.rows, stream.gap_frame(), run_id, config.export.layout, now)


def file_records(src, c: ExportCounts, quarantine: QuarantineRows, gap_frame: pl.DataFrame, run_id: str, layout: str, now: datetime) -> tuple[dict, QuarantineRows, pl.DataFrame]:
    """The manifest row, quarantine rows (already rows of the table) and gap rows of one
    ingested file (``src``: its ``ExportSource``), per the registry."""
    path, ef = src.path, src
    gaps = _table(gap_frame.with_columns(file_hash=pl.lit(ef.file_hash), source_file=pl.lit(str(path))), GAP_FIELDS)
    validate_table(gaps, "GAP_SCHEMA")
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
        "rows_added": c.rows_added,
        "lake_conflicts": c.lake_conflicts,
        "partitions": c.partitions,
        "valves": ",".join(c.valves),
        "time_start": c.time_start,
        "time_end": c.time_end,
        "run_id": run_id,
        "ingested_at": now,
        "bad_timestamp": c.bad_timestamp,
        "implausible_time": c.implausible_time,
        "out_of_range": c.out_of_range,
        "other_tags": len(c.other_tags),
        "other_samples": sum(c.other_tags.values()),
        "other_tag_names": ",".join(c.other_tags),
        "field_count": c.field_count,
        "truncated": c.truncated,
        "clock_step": c.clock_step,
    }
    return manifest, quarantine, gaps


def record_file(warehouse: Path, manifest: dict, quarantine: QuarantineRows, gaps: pl.DataFrame) -> None:
    """Write one file's manifest row, quarantine (also the rows spilled to disk, which are then
    removed) and gaps in one transaction.

    Earlier quarantine and gap rows of the same content hash are replaced, so a file ingested
    again (``force``, or after a crash) is never counted twice.
    """
    key = manifest["file_hash"]
    with connect(warehouse) as con:
        ensure_ingest_tables(con)
        with transaction(con):
            con.execute("DELETE FROM quarantine WHERE file_hash = ?", [key])
            con.execute("DELETE FROM ingest_gaps WHERE file_hash = ?", [key])
            for part in quarantine.spilled:
                con.execute("INSERT INTO quarantine BY NAME SELECT * FROM read_parquet(?)", [str(part)])
            insert_frame(con, "quarantine", quarantine.frame)
            insert_frame(con, "ingest_gaps", gaps)
            insert_frame(con, "ingest_manifest", pl.DataFrame([manifest], schema=polars_schema(MANIFEST_FIELDS)), replace=True)
    quarantine.remove()


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
        c = r.counts
        if c is None:
            self.files_skipped += 1
            return
        self.files_ingested += 1
        self.rows_read += c.rows_in
        self.samples_read += c.samples_in
        self.rows_written += c.rows_out
        self.rows_added += c.rows_added
        self.quarantined += c.quarantined
        self.duplicates += c.duplicates
        self.conflicts += c.conflicts
        self.lake_conflicts += c.lake_conflicts
        self.gaps += c.gaps
        self.partitions_written += c.partitions_written

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


def preflight(config_path: str | Path, paths: list[str | Path], *, warn: bool = False) -> tuple[PlantConfig, list[Path]]:
    """The configuration (with a grid the lake can hold) and the export files, or the error;
    ``warn``: a word on stderr for each file of a folder that is not read (:func:`warn_skipped`).

    Cheap; the command line calls it before the Prefect flow starts, so a typo costs no server.
    """
    config = load_plant_config(config_path)
    try:
        Grid.from_export(config.export.sample_rate_hz, config.export.max_gap_s)
    except IngestError as exc:
        raise ConfigError(f"{config_path}: {exc}") from None
    from flows.ingest.formats import discover_files

    return config, discover_files(paths, warn_skipped if warn else None)


def warn_skipped(path: Path, why: str) -> None:
    """A file of an export folder that is not read, said on stderr."""
    print(f"valvemon: warning: {path}: {why}", file=sys.stderr)


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
    config, files = preflight(config_path, paths, warn=True)
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
    """A rich progress bar over the files' bytes (stderr, terminals only; rich is imported only then)."""
    if not show or sys.stderr is None or not sys.stderr.isatty():
        yield lambda f: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, DownloadColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    console = Console(stderr=True)
    if not console.is_terminal:
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

"""``valvemon backfill``: ingest + monitor over a span of years, in units, resumable (``docs/orchestration.md``).

A backfill is cut into **units** that run as tasks, at most ``concurrency`` in flight: Prefect
tasks on threads of this process or on a Dask cluster (:mod:`flows.orchestration.dask_runner`)
when the backfill is a Prefect flow run; otherwise (no Prefect API configured) the same task
functions, with the same retries, on a pool of threads of this process
(:mod:`flows.common.prefect_run`):

1. **ingest** — one unit per export file of ``--exports`` (files whose name carries a date
   outside the span are left out). The task reads and hashes the file; content the manifest
   already holds is skipped; otherwise it turns the file into lake partitions and merges each
   into the lake under a per-partition file lock (two files may touch the same UTC day). It
   returns the file's manifest, quarantine and gap rows, which *this process* writes;
2. **baselines** — one task per valve whose baseline characteristic is missing or outdated
   (the step-4a fit of its commissioning window or the nominal characteristic); the rows come
   back and this process stores them;
3. **monitor** — one unit per valve × ``unit_days`` of the span. A unit owns the monitoring
   windows whose *first sample* lies in ``[start, end)``: it drops the tail of a window that
   began before ``start`` and reads past ``end`` until the window that is open there ends, so
   every window is fitted whole, exactly once, whatever the cut. The task returns the unit's
   ``edge_fits`` and ``selection_stats`` rows; this process replaces the valve's rows with
   ``window_start`` in ``[start, end)`` by them, up to :data:`WRITE_BATCH_UNITS` units in one
   transaction.

Workers therefore compute and write only lake partitions (atomic renames, locked); every
DuckDB write happens here, in short transactions, so the warehouse database never sees two
writers from one backfill, on one machine or a cluster.

**Resumable and idempotent.** Each finished unit is recorded in table ``backfill_progress``
(a monitor unit in the same transaction as its rows, an ingest unit after its manifest row):

* an ingest unit by the file's path, size and mtime and its content hash — a rerun skips the
  file without reading it (if the manifest still holds that hash);
* a monitor unit by a fingerprint of what its result depends on: the valve's monitoring
  parameters, commissioning time and baseline versions, and the size and mtime of the lake
  partitions it reads (the unit's days, ±1). A rerun skips a unit whose fingerprint is
  unchanged, and redoes it when new data reached its days or the baseline changed.

A backfill killed at any moment is continued by running the same command again; a second
run of a finished backfill changes nothing (same rows, same bytes in the lake). A unit that
fails after its retries is reported and left unrecorded; the others go on, and the run ends
with an error naming the first failure (run it again to retry them).

Runs are logged in ``backfill_runs``. :func:`backfill_flow` is the Prefect flow behind the
command.
"""

from __future__ import annotations

import hashlib
import json
import math
import queue
import re
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone
from pathlib import Path
from typing import Any, Callable, Iterator

import polars as pl

from flows.common.allocator import retain_freed_memory
from flows.common.batches import WriteBatch
from flows.common.config import load_plant_config, plant_valves
from flows.common.errors import ValvemonError
from flows.common.instants import utc_instant
from flows.common.lake import list_partitions
from flows.common.locks import file_lock, partition_lock
from flows.common.prefect_run import flow, in_flow_run, task
from flows.common.warehouse_db import connect, ensure_ingest_tables, insert_frame, migrate_hash_column, query_frame
from flows.ingest.flow import FileReport, ingest_lock, merge_export, record_file, rekey_file, warn_skipped
from flows.ingest.formats import discover_files, open_export
from flows.ingest.hashing import LEGACY_HASH_PREFIX, legacy_hash
from flows.monitor.flow import (
    Baseline,
    _baseline_rows,
    _fits_table,
    _latest_baselines,
    baseline_definition,
    ensure_monitor_tables,
    lake_chunks,
    monitor_params,
    monitor_rows,
    plant_monitor_params,
    store_spans,
)
from schemas.fields import EDGE_FIT_FIELDS, EDGES, SELECTION_FIELDS, polars_schema
from schemas.plant_config import ConfigError, PlantConfig
from transforms.ingest import Grid, IngestError, TagTable
from transforms.monitor import LAKE_COLUMNS

UNIT_DAYS = 7
"""Days of one valve per monitor unit: a week of hourly 10 s windows at 1 kHz is 1.7 M lake rows."""
CONCURRENCY = 2
"""Units in flight by default on this process's threads (the fits are compiled loops that hold
the GIL, so more threads mostly add memory; use Dask for more CPUs)."""
RETRIES = 2
"""Prefect task retries of a unit (a transient failure: a file system hiccup, a lock timeout)."""
RETRY_DELAY_S = (2.0, 10.0)

PROGRESS_TABLE = "backfill_progress"
RUNS_TABLE = "backfill_runs"

_PROGRESS_SQL = f"""
CREATE TABLE IF NOT EXISTS {PROGRESS_TABLE} (
    unit_kind VARCHAR NOT NULL,
    unit_key VARCHAR NOT NULL,
    valve_id VARCHAR,
    span_start TIMESTAMPTZ,
    span_end TIMESTAMPTZ,
    source_file VARCHAR,
    size_bytes BIGINT,
    mtime_ns BIGINT,
    file_hash VARCHAR,
    fingerprint VARCHAR,
    windows INTEGER,
    fits INTEGER,
    fits_ok INTEGER,
    rows_read BIGINT,
    run_id VARCHAR NOT NULL,
    finished_at TIMESTAMPTZ NOT NULL,
    PRIMARY KEY (unit_kind, unit_key)
)"""

_RUNS_SQL = f"""
CREATE TABLE IF NOT EXISTS {RUNS_TABLE} (
    run_id VARCHAR PRIMARY KEY,
    kind VARCHAR NOT NULL,
    started_at TIMESTAMPTZ NOT NULL,
    finished_at TIMESTAMPTZ,
    status VARCHAR NOT NULL,
    span_start TIMESTAMPTZ,
    span_end TIMESTAMPTZ,
    valves VARCHAR,
    exports VARCHAR,
    task_runner VARCHAR,
    concurrency INTEGER,
    files_ingested INTEGER,
    files_skipped INTEGER,
    files_failed INTEGER,
    units_done INTEGER,
    units_skipped INTEGER,
    units_failed INTEGER,
    windows BIGINT,
    fits BIGINT,
    rows_read BIGINT,
    wall_s DOUBLE,
    message VARCHAR
)"""

_PROGRESS_SCHEMA = {
    "unit_kind": pl.String, "unit_key": pl.String, "valve_id": pl.String,
    "span_start": pl.Datetime("us", "UTC"), "span_end": pl.Datetime("us", "UTC"),
    "source_file": pl.String, "size_bytes": pl.Int64, "mtime_ns": pl.Int64, "file_hash": pl.String,
    "fingerprint": pl.String, "windows": pl.Int32, "fits": pl.Int32, "fits_ok": pl.Int32, "rows_read": pl.Int64,
    "run_id": pl.String, "finished_at": pl.Datetime("us", "UTC"),
}  # fmt: skip

_DATE_IN_NAME = re.compile(r"(?<!\d)(\d{4}-\d{2}-\d{2})(?!\d)")


def ensure_backfill_tables(con) -> None:
    """Create ``backfill_progress`` and ``backfill_runs`` if missing (and migrate an older
    warehouse's ``file_sha256`` column, ``flows.common.warehouse_db.migrate_hash_column``)."""
    migrate_hash_column(con, PROGRESS_TABLE)
    con.execute(_PROGRESS_SQL)
    con.execute(_RUNS_SQL)


def _now() -> datetime:
    return datetime.now(timezone.utc)


# --- units -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class MonitorUnit:
    """One valve's monitoring windows that start in ``[start, end)``."""

    valve_id: str
    start: datetime
    end: datetime

    @property
    def key(self) -> str:
        return f"{self.valve_id}/{self.start.isoformat()}/{self.end.isoformat()}"

    def days(self) -> list[date]:
        """The UTC dates whose partitions can hold a window start of the unit."""
        last = (self.end - timedelta(microseconds=1)).date()
        return [self.start.date() + timedelta(days=i) for i in range((last - self.start.date()).days + 1)]


def unit_grid(start: datetime, end: datetime, unit_days: float) -> list[tuple[datetime, datetime]]:
    """``[start, end)`` cut into spans of ``unit_days`` (the last one shorter)."""
    step = timedelta(days=unit_days)
    out, lo = [], start
    while lo < end:
        hi = min(lo + step, end)
        out.append((lo, hi))
        lo = hi
    return out


def extra_units(start: datetime, unit_days: float, spans: list[tuple[str, datetime, datetime]]) -> list[MonitorUnit]:
    """Units before ``start`` (on the same grid) covering the given ``(valve, t0, t1)`` spans,
    e.g. late exports the nightly run ingested for days it had already done."""
    step = timedelta(days=unit_days)
    out = set()
    for valve_id, t0, t1 in spans:
        if t0 >= start:
            continue
        k0 = math.floor((t0 - start) / step)
        k1 = min(math.floor((min(t1, start) - start) / step), -1)
        for k in range(k0, k1 + 1):
            out.add(MonitorUnit(valve_id, start + k * step, start + (k + 1) * step))
    return sorted(out, key=lambda u: (u.valve_id, u.start))


def export_in_span(path: Path, start: datetime, end: datetime) -> bool:
    """False only for a file whose name carries a date (``YYYY-MM-DD``, the last one) more than a
    day outside ``[start, end)``; names without a date are always in (the day of slack allows
    for exports cut at local midnight)."""
    found = _DATE_IN_NAME.findall(path.name)
    if not found:
        return True
    try:
        day = date.fromisoformat(found[-1])
    except ValueError:
        return True
    return start.date() - timedelta(days=1) <= day <= (end - timedelta(microseconds=1)).date() + timedelta(days=1)


# --- ingest unit (runs on a worker) -----------------------------------------------------------


@dataclass
class IngestOutcome:
    """What an ingest unit did; the flow writes ``records`` (manifest, quarantine, gaps)."""

    path: str
    size_bytes: int
    mtime_ns: int
    report: FileReport
    records: tuple[dict, pl.DataFrame, pl.DataFrame] | None = None
    rekey: tuple[str, str] | None = None
    """(legacy SHA-256 hash, BLAKE3 hash) of a skipped file the manifest knew by its SHA-256."""


def ingest_export(path: str | Path, config: PlantConfig, warehouse: str | Path, known: KnownFiles, run_id: str) -> IngestOutcome:
    """Open one export, skip it if its content is ``known``, else merge it into the lake batch by batch.

    Like :func:`flows.ingest.flow.ingest_file`, but the partitions are locked while merged (other
    files are being ingested at the same time) and the database rows are returned, not written.
    """
    path, warehouse = Path(path), Path(warehouse)
    retain_freed_memory()  # the next file's arrays reuse this one's heap (flows/common/allocator.py)
    st = path.stat()
    tags = TagTable.from_config(config)
    src = open_export(path, config.export, config.timezone)
    if src.file_hash in known:
        return IngestOutcome(str(path), st.st_size, st.st_mtime_ns, FileReport(str(path), src.file_hash))
    if src.size_bytes in known.legacy_sizes:
        old = legacy_hash(path)
        if old in known:
            report = FileReport(str(path), src.file_hash)
            return IngestOutcome(str(path), st.st_size, st.st_mtime_ns, report, rekey=(old, src.file_hash))
    report, records = merge_export(src, config, warehouse, run_id, tags, lock=lambda target: partition_lock(warehouse, target))
    return IngestOutcome(str(path), st.st_size, st.st_mtime_ns, report, records)


# --- monitor unit (runs on a worker) ----------------------------------------------------------


@dataclass
class MonitorOutcome:
    """A monitor unit's rows for ``edge_fits`` and ``selection_stats``."""

    unit: MonitorUnit
    fits: pl.DataFrame
    selection: pl.DataFrame
    windows: int
    rows_read: int


def unit_chunks(
    warehouse: Path, valve_id: str, start: datetime, end: datetime, gap_s: float, window_s: float | None = None
) -> Iterator[pl.DataFrame]:
    """The lake columns the monitor reads (``LAKE_COLUMNS``) of the windows whose first sample
    lies in ``[start, end)``, whole, in chunks of whole windows: :func:`flows.monitor.flow.lake_chunks`
    for the span (windows of ``transforms.windows.window_starts`` with the gap limit ``gap_s``
    and the length ``window_s``, the same windows as ``valvemon monitor`` cuts, whatever the
    unit borders: a window belongs to the unit it starts in)."""
    days = (end - start).days + 2  # every partition the span and its last window can touch
    yield from lake_chunks(warehouse, valve_id, gap_s, start, end, days, LAKE_COLUMNS, window_s)


def monitor_unit(config: PlantConfig, unit: MonitorUnit, baselines: dict[str, Baseline], warehouse: str | Path) -> MonitorOutcome:
    """Steps 2–4b for one unit (chunk by chunk of :func:`unit_chunks`) against the given baselines."""
    valve = config.valve(unit.valve_id)
    params = plant_monitor_params(config, valve)
    gap_s = params.gap_limit_periods * params.sample_period_s
    selection_schema = polars_schema(SELECTION_FIELDS)
    fits = [pl.DataFrame(schema=polars_schema(EDGE_FIT_FIELDS))]
    selection = [pl.DataFrame(schema=selection_schema)]
    windows = rows_read = 0
    for rows in unit_chunks(Path(warehouse), unit.valve_id, unit.start, unit.end, gap_s, params.window_s):
        res = monitor_rows(valve, params, baselines, rows)
        fits.append(_fits_table(res.fits, valve, baselines, _now()))
        selection.append(res.selection.select([f.name for f in SELECTION_FIELDS]).cast(dict(selection_schema)))
        windows += res.windows.height
        rows_read += rows.height
    return MonitorOutcome(unit, pl.concat(fits), pl.concat(selection), windows, rows_read)


def baseline_rows(config: PlantConfig, valve_id: str, warehouse: str | Path, versions: dict[str, int]) -> pl.DataFrame:
    """New baseline rows of one valve (step 4a + 5a on its commissioning window, or nominal)."""
    valve = config.valve(valve_id)
    return _baseline_rows(valve, monitor_params(valve, config.export.sample_rate_hz), Path(warehouse), versions)


# --- Prefect tasks -----------------------------------------------------------------------------


@task(name="backfill-ingest-file", persist_result=False, retries=RETRIES, retry_delay_seconds=list(RETRY_DELAY_S))
def ingest_export_task(path: str, config: PlantConfig, warehouse: str, known: KnownFiles, run_id: str) -> IngestOutcome:
    """One export file into the lake (:func:`ingest_export`)."""
    return ingest_export(path, config, warehouse, known, run_id)


@task(name="backfill-baseline", persist_result=False, retries=RETRIES, retry_delay_seconds=list(RETRY_DELAY_S))
def baseline_task(config: PlantConfig, valve_id: str, warehouse: str, versions: dict[str, int]) -> pl.DataFrame:
    """One valve's new baseline rows (:func:`baseline_rows`)."""
    return baseline_rows(config, valve_id, warehouse, versions)


@task(name="backfill-monitor-unit", persist_result=False, retries=RETRIES, retry_delay_seconds=list(RETRY_DELAY_S))
def monitor_unit_task(config: PlantConfig, unit: MonitorUnit, baselines: dict[str, Baseline], warehouse: str) -> MonitorOutcome:
    """One valve × span of windows (:func:`monitor_unit`)."""
    return monitor_unit(config, unit, baselines, warehouse)


# --- bounded submission ------------------------------------------------------------------------


class Window:
    """Submit tasks with at most ``limit`` in flight; completed ones are handed to
    ``on_done(tag, result)`` / ``on_error(tag, exc)`` in the calling (flow) thread.

    In a Prefect flow run a task is submitted to the flow's task runner; outside one (no Prefect
    API configured, :mod:`flows.common.prefect_run`) it is called, with the task's retries, on a
    pool of ``limit`` threads of this process."""

    def __init__(self, limit: int, on_done: Callable[[Any, Any], None], on_error: Callable[[Any, BaseException], None]):
        if limit < 1:
            raise ValvemonError("--concurrency must be at least 1")
        self.limit = limit
        self.on_done, self.on_error = on_done, on_error
        self._done: queue.Queue = queue.Queue()
        self._pool: ThreadPoolExecutor | None = None
        self.in_flight = 0
        self.max_in_flight = 0

    def submit(self, tag: Any, task_, *args) -> None:
        while self.in_flight >= self.limit:
            self._take()
        if in_flow_run():
            future = task_.submit(*args)
        else:
            self._pool = self._pool or ThreadPoolExecutor(self.limit, thread_name_prefix="valvemon-unit")
            future = self._pool.submit(task_, *args)
        self.in_flight += 1
        self.max_in_flight = max(self.max_in_flight, self.in_flight)
        future.add_done_callback(lambda f, tag=tag: self._done.put((tag, f)))

    def _take(self) -> None:
        tag, future = self._done.get()
        self.in_flight -= 1
        try:
            result = future.result()
        except Exception as exc:  # a unit that failed after its retries
            self.on_error(tag, exc)
            return
        self.on_done(tag, result)

    def drain(self) -> None:
        while self.in_flight:
            self._take()
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


# --- the run ---------------------------------------------------------------------------------


@dataclass
class BackfillSummary:
    """Counts of one backfill run (also stored in ``backfill_runs``)."""

    run_id: str
    span_start: datetime
    span_end: datetime
    files_seen: int = 0
    files_out_of_span: int = 0
    files_ingested: int = 0
    files_skipped: int = 0
    files_resumed: int = 0
    files_failed: int = 0
    lake_rows_added: int = 0
    baselines_made: int = 0
    units_planned: int = 0
    units_done: int = 0
    units_skipped: int = 0
    units_failed: int = 0
    windows: int = 0
    fits: int = 0
    fits_ok: int = 0
    rows_read: int = 0
    max_in_flight: int = 0
    wall_s: float = 0.0
    new_spans: list[tuple[str, datetime, datetime]] = field(default_factory=list)
    failures: list[tuple[str, str]] = field(default_factory=list)

    def line(self) -> str:
        """The one-line summary the command prints."""
        files = (
            f"files: {self.files_ingested} ingested, {self.files_skipped + self.files_resumed} already in the manifest"
            + (f", {self.files_failed} failed" if self.files_failed else "")
            + (f", {self.files_out_of_span} outside the span" if self.files_out_of_span else "")
        )
        units = (
            f"monitor units: {self.units_done} done, {self.units_skipped} unchanged"
            + (f", {self.units_failed} failed" if self.units_failed else "")
        )
        return (
            f"backfill {self.span_start:%Y-%m-%d %H:%M} – {self.span_end:%Y-%m-%d %H:%M} UTC: {files}; {units}; "
            f"{self.windows:,} windows, {self.fits_ok:,} of {self.fits:,} fits ok, {self.rows_read:,} lake rows read "
            f"in {self.wall_s:,.1f} s"
        )


class BackfillFailed(ValvemonError):
    """Some units failed after their retries; the others are done and recorded."""

    def __init__(self, summary: BackfillSummary):
        self.summary = summary
        unit, message = summary.failures[0]
        n = len(summary.failures)
        super().__init__(f"{n} backfill unit{'s' if n > 1 else ''} failed (first: {unit}: {message}); run the same command again to retry")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _progress_rows(warehouse: Path) -> dict[tuple[str, str], dict]:
    if not (warehouse / "valvemon.duckdb").exists():
        return {}
    with connect(warehouse) as con:
        ensure_backfill_tables(con)
        rows = query_frame(con, f"SELECT unit_kind, unit_key, size_bytes, mtime_ns, file_hash, fingerprint FROM {PROGRESS_TABLE}")
    return {(r["unit_kind"], r["unit_key"]): r for r in rows.iter_rows(named=True)}


def _progress_frame(rows: list[dict]) -> pl.DataFrame:
    return pl.DataFrame([{k: r.get(k) for k in _PROGRESS_SCHEMA} for r in rows], schema=_PROGRESS_SCHEMA)


def _store_run_row(warehouse: Path, s: BackfillSummary, kind: str, started: datetime, status: str, message: str | None, meta: dict) -> None:
    row = {
        "run_id": s.run_id, "kind": kind, "started_at": started, "finished_at": None if status == "running" else _now(),
        "status": status, "span_start": s.span_start, "span_end": s.span_end, **meta,
        "files_ingested": s.files_ingested, "files_skipped": s.files_skipped + s.files_resumed, "files_failed": s.files_failed,
        "units_done": s.units_done, "units_skipped": s.units_skipped, "units_failed": s.units_failed,
        "windows": s.windows, "fits": s.fits, "rows_read": s.rows_read, "wall_s": s.wall_s, "message": message,
    }  # fmt: skip
    with connect(warehouse) as con:
        ensure_backfill_tables(con)
        cols = list(row)
        con.execute(
            f"INSERT OR REPLACE INTO {RUNS_TABLE} ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
            [row[c] for c in cols],
        )


def _lake_stats(warehouse: Path, valve_ids: list[str]) -> dict[str, dict[date, tuple[int, int]]]:
    out: dict[str, dict[date, tuple[int, int]]] = {v: {} for v in valve_ids}
    for vid, day, path in list_partitions(warehouse, valve_ids):
        try:
            st = path.stat()
        except FileNotFoundError:
            continue
        size, mtime = out.setdefault(vid, {}).get(day, (0, 0))  # a day stored by the hour: all its files
        out[vid][day] = (size + st.st_size, max(mtime, st.st_mtime_ns))
    return out


def _valve_signature(config: PlantConfig, valve_id: str, baselines: dict[str, Baseline]) -> str:
    valve = config.valve(valve_id)
    return json.dumps(
        {
            "params": repr(plant_monitor_params(config, valve)),
            "commissioned": valve.commissioned.isoformat(),
            "baselines": {e: baselines[e].version for e in EDGES},
            "definition": baseline_definition(valve),
        },
        sort_keys=True,
    )


def unit_fingerprint(signature: str, parts: dict[date, tuple[int, int]], unit: MonitorUnit) -> str:
    """What a monitor unit's result depends on (module doc), hashed."""
    days = [unit.start.date() - timedelta(days=1), *unit.days(), unit.days()[-1] + timedelta(days=1)]
    lake = [f"{d.isoformat()}:{parts[d][0]}:{parts[d][1]}" for d in days if d in parts]
    return hashlib.sha256((signature + "|" + ";".join(lake)).encode()).hexdigest()


def _baselines_from_rows(config: PlantConfig, valve_id: str, rows: pl.DataFrame) -> dict[str, Baseline]:
    valve = config.valve(valve_id)
    params = monitor_params(valve, config.export.sample_rate_hz)
    return {r["edge"]: Baseline.from_row(valve, params, r) for r in rows.iter_rows(named=True)}


@contextmanager
def _progress_bars(show: bool) -> Iterator[Callable[..., Any]]:
    """Rich progress bars on stderr (terminals only): ``bar(name, total)`` → advance(n=1)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = Console(stderr=True)
    if not show or not console.is_terminal:
        yield lambda name, total: (lambda n=1: None)
        return
    columns = (TextColumn("{task.description:<16}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console) as progress:

        def bar(name: str, total: int):
            t = progress.add_task(name, total=max(total, 0))
            return lambda n=1: progress.advance(t, n)

        yield bar


def _backfill_lock(warehouse: Path) -> AbstractContextManager:
    return file_lock(warehouse / ".backfill.lock", f"{warehouse}: another backfill or nightly run is working on this warehouse")


@flow(name="valvemon-backfill", persist_result=False, validate_parameters=False)
def backfill_flow(
    config_path: str | Path,
    warehouse: str | Path,
    start: str | date | datetime,
    end: str | date | datetime,
    *,
    valve_ids: list[str] | None = None,
    exports: str | Path | None = None,
    concurrency: int = CONCURRENCY,
    unit_days: float = UNIT_DAYS,
    retries: int = RETRIES,
    force: bool = False,
    show_progress: bool = False,
    filter_exports_by_name: bool = True,
    monitor_new_data: bool = False,
    kind: str = "backfill",
    task_runner_name: str = "threads",
) -> BackfillSummary:
    """The Prefect flow behind ``valvemon backfill``: ingest ``exports`` and monitor ``[start, end)``
    unit by unit (module doc).

    Parameters
    ----------
    config_path, warehouse : path
        Plant configuration and warehouse folder.
    start, end : ISO-8601 str, date or datetime
        The span (end exclusive); naive values are UTC.
    valve_ids : list of str, optional
        Monitor only these valves (ingest writes whatever valves the files hold).
    exports : path, optional
        Export files or a folder (searched recursively); without it only the lake is monitored.
    concurrency : int
        Units in flight at once.
    unit_days : float
        Length of a monitor unit.
    retries : int
        Prefect task retries per unit.
    force : bool
        Redo every monitor unit and re-read every file (content the manifest holds is still skipped).
    filter_exports_by_name : bool
        Leave out files whose name carries a date outside the span (:func:`export_in_span`).
    monitor_new_data : bool
        Also monitor, before ``start``, the days newly ingested files cover (the nightly run).
    """
    t_wall = time.monotonic()
    started = _now()
    warehouse = Path(warehouse)
    config = load_plant_config(config_path)
    try:
        Grid.from_export(config.export.sample_rate_hz, config.export.max_gap_s)
    except IngestError as exc:
        raise ConfigError(f"{config_path}: {exc}") from None
    t0, t1 = utc_instant(start, "--from"), utc_instant(end, "--to")
    if t1 <= t0:
        raise ValvemonError("--to must be later than --from")
    if unit_days <= 0:
        raise ValvemonError("--unit-days must be positive")
    valves = plant_valves(config, valve_ids, config_path)
    files = discover_files([exports], warn_skipped) if exports is not None else []

    summary = BackfillSummary(run_id=f"{kind}-{started:%Y%m%dT%H%M%SZ}-{uuid.uuid4().hex[:8]}", span_start=t0, span_end=t1, files_seen=len(files))
    meta = {"valves": ",".join(valves), "exports": str(exports) if exports else None, "task_runner": task_runner_name, "concurrency": concurrency}
    opts = {"retries": retries, "retry_delay_seconds": list(RETRY_DELAY_S)}

    with _backfill_lock(warehouse):
        with connect(warehouse) as con:
            ensure_ingest_tables(con)
            ensure_monitor_tables(con)
            ensure_backfill_tables(con)
        _store_run_row(warehouse, summary, kind, started, "running", None, meta)
        try:
            with _progress_bars(show_progress) as bar:
                _ingest_phase(config, warehouse, files, summary, concurrency, opts, force, filter_exports_by_name, bar)
                _monitor_phase(config, warehouse, valves, summary, concurrency, opts, unit_days, force, monitor_new_data, bar)
        except BaseException as exc:
            summary.wall_s = time.monotonic() - t_wall
            _store_run_row(warehouse, summary, kind, started, "failed", _first_line(exc), meta)
            raise
        summary.wall_s = time.monotonic() - t_wall
        if summary.failures:
            _store_run_row(warehouse, summary, kind, started, "failed", f"{summary.failures[0][0]}: {summary.failures[0][1]}", meta)
            raise BackfillFailed(summary)
        _store_run_row(warehouse, summary, kind, started, "ok", None, meta)
    return summary


def _ingest_phase(config, warehouse, files, summary, concurrency, opts, force, filter_by_name, bar) -> None:
    if not files:
        return
    if filter_by_name:
        in_span = [f for f in files if export_in_span(f, summary.span_start, summary.span_end)]
        summary.files_out_of_span = len(files) - len(in_span)
        files = in_span
    progress = _progress_rows(warehouse)
    known = manifest_hashes(warehouse)
    todo = []
    for f in files:
        key = str(f.resolve())
        done = progress.get(("ingest", key))
        if done and not force:
            st = f.stat()
            if done["size_bytes"] == st.st_size and done["mtime_ns"] == st.st_mtime_ns and done["file_hash"] in known:
                summary.files_resumed += 1
                continue
        todo.append(f)
    if not todo:
        return
    advance = bar("ingest files", len(todo))

    def done(path: Path, out: IngestOutcome) -> None:
        if out.records is not None:
            record_file(warehouse, *out.records)
            manifest = out.records[0]
            summary.files_ingested += 1
            summary.lake_rows_added += out.report.counts.rows_added
            if manifest["time_start"] is not None:
                for v in out.report.counts.valves:
                    summary.new_spans.append((v, manifest["time_start"], manifest["time_end"]))
        else:
            summary.files_skipped += 1
            if out.rekey is not None:
                with connect(warehouse) as con:
                    rekey_file(con, *out.rekey)
        progress_rows.add({
            "unit_kind": "ingest", "unit_key": str(Path(out.path).resolve()), "source_file": out.path,
            "size_bytes": out.size_bytes, "mtime_ns": out.mtime_ns, "file_hash": out.report.file_hash,
            "run_id": summary.run_id, "finished_at": _now(),
        })  # fmt: skip
        advance()

    def store_progress(rows: list[dict]) -> None:
        with connect(warehouse) as con:
            insert_frame(con, PROGRESS_TABLE, _progress_frame(rows), replace=True)

    # the progress rows of ingested files are written in batches: one lost in a crash only
    # costs the rerun a read of the file (its content is then found in the manifest)
    progress_rows: WriteBatch[dict] = WriteBatch(store_progress, max_items=WRITE_BATCH_UNITS)

    def failed(path: Path, exc: BaseException) -> None:
        summary.files_failed += 1
        summary.failures.append((str(path), _first_line(exc)))
        advance()

    window = Window(concurrency, done, failed)
    task_ = ingest_export_task.with_options(**opts)
    with ingest_lock(warehouse):
        try:
            for f in todo:
                window.submit(f, task_, str(f), config, str(warehouse), known, summary.run_id)
            window.drain()
        finally:
            progress_rows.flush()
    summary.max_in_flight = max(summary.max_in_flight, window.max_in_flight)


@dataclass(frozen=True)
class KnownFiles:
    """The content hashes of the ingest manifest, and the sizes of its files that it knows only by
    their legacy SHA-256 (``flows.ingest.flow.in_manifest``)."""

    hashes: frozenset[str]
    legacy_sizes: frozenset[int] = frozenset()

    def __contains__(self, file_hash: object) -> bool:
        return file_hash in self.hashes


def manifest_hashes(warehouse: Path) -> KnownFiles:
    """Content hashes of the files the ingest manifest holds."""
    with connect(warehouse) as con:
        ensure_ingest_tables(con)
        rows = query_frame(con, "SELECT file_hash, size_bytes FROM ingest_manifest")
    legacy = rows.filter(pl.col("file_hash").str.starts_with(LEGACY_HASH_PREFIX))["size_bytes"]
    return KnownFiles(frozenset(rows["file_hash"].to_list()), frozenset(legacy.to_list()))


def _current_baselines(warehouse: Path, valves: list[str]) -> dict[str, pl.DataFrame]:
    with connect(warehouse) as con:
        return {v: _latest_baselines(con, v) for v in valves}


def _monitor_phase(config, warehouse, valves, summary, concurrency, opts, unit_days, force, monitor_new_data, bar) -> None:
    stats = _lake_stats(warehouse, valves)
    grid = unit_grid(summary.span_start, summary.span_end, unit_days)
    units = [MonitorUnit(v, lo, hi) for v in valves for lo, hi in grid]
    if monitor_new_data:
        spans = [s for s in summary.new_spans if s[0] in set(valves)]
        units = extra_units(summary.span_start, unit_days, spans) + units
    # time-major: a stopped backfill has finished the earliest days of every valve, and the
    # rows arrive in time order (DuckDB's zone maps on window_start then prune the deletes)
    units = sorted((u for u in units if any(d in stats.get(u.valve_id, {}) for d in u.days())), key=lambda u: (u.start, u.valve_id))
    if not units:
        return
    summary.units_planned = len(units)

    # baselines: made (as tasks) where missing or outdated, stored here
    needed = sorted({u.valve_id for u in units})
    latest = _current_baselines(warehouse, needed)
    make = []
    for v in needed:
        definition = baseline_definition(config.valve(v))
        if latest[v].filter(pl.col("definition") == definition).height < len(EDGES):
            make.append(v)
    if make:
        advance = bar("baselines", len(make))

        def stored(v: str, rows: pl.DataFrame) -> None:
            with connect(warehouse) as con:
                insert_frame(con, "baselines", rows)
            summary.baselines_made += 1
            advance()

        def failed(v: str, exc: BaseException) -> None:
            summary.failures.append((f"baseline {v}", _first_line(exc)))
            advance()

        window = Window(concurrency, stored, failed)
        for v in make:
            versions = dict(zip(latest[v]["edge"].to_list(), latest[v]["version"].to_list()))
            window.submit(v, baseline_task.with_options(**opts), config, v, str(warehouse), versions)
        window.drain()
        latest = _current_baselines(warehouse, needed)
    baselines = {}
    for v in needed:
        rows = latest[v].filter(pl.col("definition") == baseline_definition(config.valve(v)))
        if rows.height == len(EDGES):
            baselines[v] = _baselines_from_rows(config, v, rows)
        elif v not in make or not any(f[0] == f"baseline {v}" for f in summary.failures):
            summary.failures.append((f"baseline {v}", "no stored baseline matches the valve's current definition"))
    signatures = {v: _valve_signature(config, v, b) for v, b in baselines.items()}

    progress = _progress_rows(warehouse)
    todo = []
    for u in units:
        if u.valve_id not in baselines:
            summary.units_failed += 1  # its baseline failed: reported above
            continue
        fp = unit_fingerprint(signatures[u.valve_id], stats[u.valve_id], u)
        done = progress.get(("monitor", u.key))
        if done and done["fingerprint"] == fp and not force:
            summary.units_skipped += 1
            continue
        todo.append((u, fp))
    if not todo:
        return
    advance = bar("monitor units", len(todo))
    fingerprints = dict((u.key, fp) for u, fp in todo)

    def store(batch: list[tuple[MonitorUnit, pl.DataFrame, pl.DataFrame, dict]]) -> None:
        store_units(warehouse, [(u, f, s) for u, f, s, _ in batch], _progress_frame([r for *_, r in batch]))
        for _, fits, _, row in batch:
            summary.units_done += 1
            summary.windows += row["windows"]
            summary.fits += fits.height
            summary.fits_ok += row["fits_ok"]
            summary.rows_read += row["rows_read"]

    writer: WriteBatch[tuple[MonitorUnit, pl.DataFrame, pl.DataFrame, dict]] = WriteBatch(store, max_items=WRITE_BATCH_UNITS)

    def done(u: MonitorUnit, out: MonitorOutcome) -> None:
        row = {
            "unit_kind": "monitor", "unit_key": u.key, "valve_id": u.valve_id, "span_start": u.start, "span_end": u.end,
            "fingerprint": fingerprints[u.key], "windows": out.windows, "fits": out.fits.height,
            "fits_ok": int((out.fits["status"] == "ok").sum()), "rows_read": out.rows_read, "run_id": summary.run_id,
            "finished_at": _now(),
        }  # fmt: skip
        writer.add((u, out.fits, out.selection, row))
        advance()

    def failed(u: MonitorUnit, exc: BaseException) -> None:
        summary.units_failed += 1
        summary.failures.append((f"monitor {u.key}", _first_line(exc)))
        advance()

    window = Window(concurrency, done, failed)
    task_ = monitor_unit_task.with_options(**opts)
    try:
        for u, _ in todo:
            window.submit(u, task_, config, u, baselines[u.valve_id], str(warehouse))
        window.drain()
    finally:
        writer.flush()  # what finished is kept, also when the run is interrupted
    summary.max_in_flight = max(summary.max_in_flight, window.max_in_flight)


WRITE_BATCH_UNITS = 32
"""Finished units whose rows are written in one transaction at most (or once the oldest has
waited :data:`flows.common.batches.WRITE_BATCH_S`): per unit, the transaction would be the serial part
of a large backfill."""


def store_units(warehouse: Path, units: list[tuple[MonitorUnit, pl.DataFrame, pl.DataFrame]], progress: pl.DataFrame) -> None:
    """For each unit replace the valve's rows with ``window_start`` in ``[start, end)`` by its rows
    and record the units' progress rows, all in one transaction (:func:`flows.monitor.flow.store_spans`)."""
    store_spans(
        warehouse, [(u.valve_id, u.start, u.end, f, s) for u, f, s in units],
        also=lambda con: insert_frame(con, PROGRESS_TABLE, progress, replace=True),
    )  # fmt: skip

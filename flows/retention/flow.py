"""``valvemon retention``: thin or drop old lake partitions once their fits exist.

For every lake partition (one valve, one UTC ``date=`` folder, all its ``*.parquet`` files) of
the plant's valves, :func:`run_retention` decides with :func:`transforms.retention.decide`
(older than ``keep_days``, not a commissioning day, every sample inside a fitted window, read by
the standstill check; thin mode: not thinned yet) and, unless it is a dry run, applies it:

Every action is recorded before it changes the lake: an *intent* row of ``retention_log``
(``state = 'intent'``, with the rows before and after) is committed first, then the data changes,
then the row is completed (``state = 'done'``, the sizes measured, ``applied_at``). So a run
killed at any point leaves a record of what it was removing, and the next run completes it
(:func:`complete_interrupted`) before anything else:

* **drop**: intent; the ``date=`` folder is renamed to a hidden name beside it and the parent
  fsynced (the commit point: from then on no reader sees the partition); the hidden folder is
  deleted; done. Killed before the rename, the partition is whole and the intent is withdrawn
  (nothing was removed; the run decides the partition again); after it, the hidden folder is
  deleted and the intent completed.
* **thin**: intent; each file of the partition is replaced atomically by its kept rows, read
  range by range (:func:`count_kept` finds them as row ranges; memory holds one range, never a
  day) and written with :func:`flows.common.lake.write_partition_pieces`; done. Killed in between, some files are
  thinned and some not, never a mix within a file; the next run thins the partition again
  (thinning a thinned file keeps it as it is) and completes the intent, whose ``rows_before``
  is the partition's before the first run touched it.

The lake and the database are read first; a dry run (and the summary it prints) writes nothing,
not even the database's tables. Only the hidden folders of interrupted drops are handled before
anything else (a dry run reports them). An ``as_of`` later than today, or more than a day after
the warehouse's latest ingest, is refused unless forced (:func:`check_as_of`): a typo in a year
would otherwise make every partition old. One retention run at a time per warehouse
(``WAREHOUSE/.retention.lock``); each partition is locked like an ingest's merge while it is read
and changed, so an ingest of late data into the same day waits.

``docs/warehouse.md``, "Retention", explains the rules and the storage arithmetic.
"""

from __future__ import annotations

import uuid
from contextlib import nullcontext
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import polars as pl

from flows.common.config import load_plant_config, plant_valves
from flows.common.errors import ValvemonError
from flows.common.lake import (
    PART_NAME,
    day_files,
    drop_partition,
    dropped_folders,
    iter_file_batches,
    partition_bytes,
    partition_path,
    partition_folders,
    partition_rows,
    read_file_ranges,
    remove_dropped,
    remove_partition_file,
    row_group_spans,
    write_partition_pieces,
)
from flows.common.locks import file_lock, partition_lock
from flows.common.prefect_run import flow
from flows.common.warehouse_db import add_missing_columns, connect, db_path, ensure_tables, insert_frame, query_frame
from schemas.fields import RETENTION_LOG_FIELDS, polars_schema
from schemas.plant_config import PlantConfig, RetentionSpec
from transforms.retention import (
    KEEP,
    REASON_THINNED,
    Decision,
    PartitionScan,
    decide,
    decide_fitted,
    decide_unscanned,
    fitted_cover,
    kept_row_groups,
    protected_days,
)

RETENTION_TABLES = {"retention_log": (RETENTION_LOG_FIELDS, "action_id")}
"""Table → (fields, primary key)."""

TIME = "timestamp_utc"


@dataclass
class PartitionOutcome:
    """What retention did (or, in a dry run, would do) to one partition."""

    valve_id: str
    day: date
    action: str
    """drop, thin or keep."""
    reason: str
    bytes_before: int
    rows_before: int | None = None
    """None: kept without reading it (recent or a commissioning day)."""
    rows_after: int | None = None
    bytes_after: int | None = None
    """In a dry run of a thinning: estimated in proportion to the rows."""


@dataclass
class RetentionSummary:
    """One retention run: its settings and every partition's outcome."""

    as_of: date
    spec: RetentionSpec
    dry_run: bool
    outcomes: list[PartitionOutcome] = field(default_factory=list)
    interrupted: list[tuple[str, date]] = field(default_factory=list)
    """Actions a killed run had begun (recorded as intents, or renamed for a drop) but not
    finished; completed by this run (reported only, in a dry run)."""
    today: date | None = None
    """The real date of the run, for the age of the oldest data it touches."""

    def groups(self) -> list[tuple[str, str, int, int, int, int, int]]:
        """(action, reason, partitions, rows before, rows after, bytes before, bytes after) per
        reason, acted-on groups first. Rows of unread partitions count from the files' footers."""
        acc: dict[tuple[str, str], list[int]] = {}
        for o in self.outcomes:
            g = acc.setdefault((o.action, o.reason), [0, 0, 0, 0, 0])
            before = o.rows_before or 0
            g[0] += 1
            g[1] += before
            g[2] += before if o.rows_after is None else o.rows_after
            g[3] += o.bytes_before
            g[4] += o.bytes_before if o.bytes_after is None else o.bytes_after
        order = {"drop": 0, "thin": 1, KEEP: 2}
        return [(a, r, *v) for (a, r), v in sorted(acc.items(), key=lambda kv: (order[kv[0][0]], kv[0][1]))]

    def freed_bytes(self) -> int:
        """Bytes the actions free (estimated for thinning in a dry run). [B]"""
        return sum(o.bytes_before - (o.bytes_after or 0) for o in self.outcomes if o.action != KEEP)

    def lines(self) -> list[str]:
        """The summary the command prints."""
        s = self.spec
        how = f"mode {s.mode}" + (f", first {s.thin_keep_s_per_hour:g} s of every hour kept" if s.mode == "thin" else "")
        head = f"retention as of {self.as_of} (keep_days {s.keep_days}, {how})" + (": DRY RUN, nothing changed" if self.dry_run else "")
        out = [head]
        for action, reason, n, r0, r1, b0, b1 in self.groups():
            verb = action if action != KEEP else "keep"
            if action == KEEP:
                out.append(f"  {verb:5} {n:6d} partitions  {reason}  ({_size(b0)})")
            else:
                approx = "≈" if self.dry_run and action == "thin" else ""
                out.append(f"  {verb:5} {n:6d} partitions  {reason}  rows {r0:,} -> {r1:,}  bytes {_size(b0)} -> {approx}{_size(b1)}")
        if self.interrupted:
            verb = "would complete" if self.dry_run else "completed"
            out.append(f"  {verb} {len(self.interrupted)} action(s) a killed run had begun: " + ", ".join(f"{v} {d}" for v, d in self.interrupted))
        touched = [o for o in self.outcomes if o.action != KEEP]
        if touched and self.today is not None:
            oldest = min(touched, key=lambda o: o.day)
            newest = max(touched, key=lambda o: o.day)
            verb = "would touch" if self.dry_run else "touched"
            out.append(
                f"  oldest data it {verb}: {oldest.valve_id} {oldest.day}, {(self.today - oldest.day).days:,} days old today ({self.today}); "
                f"newest {newest.valve_id} {newest.day}, {(self.today - newest.day).days:,} days old"
            )
        if not self.outcomes:
            out.append("  no lake partitions")
        out.append(("would free " if self.dry_run else "freed ") + _size(self.freed_bytes()))
        return out


def _size(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.2f} {unit}"
    return f"{n} B"


def _us(t: datetime) -> int:
    return int((t - datetime(1970, 1, 1, tzinfo=timezone.utc)) / timedelta(microseconds=1))


@dataclass(frozen=True)
class WarehouseState:
    """What retention reads from the database, once, before touching the lake."""

    covers: dict[str, tuple[np.ndarray, np.ndarray]]
    """valve → its fitted windows (:func:`transforms.retention.fitted_cover`) over the candidate days."""
    checked_through_us: dict[str, int]
    """valve → ``standstill_progress.checked_through`` (µs since the epoch)."""
    logged: frozenset[str]
    """``action_id`` of the interrupted drops that are already in ``retention_log``."""
    thinned: dict[tuple[str, date], tuple[int, int, float]] = field(default_factory=dict)
    """(valve, date) → (size_after_bytes, applied_at µs, thin_keep_s_per_hour) of its latest thinning."""

    def thinned_as_logged(self, valve_id: str, day: date, folder: Path, keep_s: float) -> bool:
        """Whether the partition is still exactly as its latest thinning with ``keep_s`` left it
        (same bytes, no file written since): it is then kept without being read again, so the
        thinned days of past years cost nothing each night."""
        entry = self.thinned.get((valve_id, day))
        if entry is None or entry[2] != keep_s:
            return False
        files = day_files(folder)
        return sum(f.stat().st_size for f in files) == entry[0] and max(f.stat().st_mtime_ns for f in files) // 1000 <= entry[1]


def read_state(warehouse: Path, candidates: dict[str, tuple[date, date]], action_ids: list[str]) -> WarehouseState:
    """Fitted windows of each valve over its candidate days ``[first, last]``, the standstill
    progress and which interrupted drops are logged; read-only (a warehouse without a database or
    without the tables has none of them)."""
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    covers = {v: empty for v in candidates}
    if not db_path(warehouse).exists():
        return WarehouseState(covers, {}, frozenset())
    with connect(warehouse, read_only=True) as con:
        have = {r[0] for r in con.execute("SELECT table_name FROM duckdb_tables() WHERE database_name = current_database()").fetchall()}
        if "edge_fits" in have:
            for v, (first, last) in candidates.items():
                lo = datetime.combine(first, datetime.min.time(), timezone.utc)
                hi = datetime.combine(last + timedelta(days=1), datetime.min.time(), timezone.utc)
                w = query_frame(
                    con,
                    "SELECT DISTINCT epoch_us(window_start) AS s, epoch_us(window_end) AS e FROM edge_fits "
                    "WHERE valve_id = ? AND window_end >= ? AND window_start < ?",
                    [v, lo, hi],
                )
                covers[v] = fitted_cover(w["s"].to_numpy(), w["e"].to_numpy()) if w.height else empty
        checked: dict[str, int] = {}
        if "standstill_progress" in have:
            checked = dict(con.execute("SELECT valve_id, epoch_us(checked_through) FROM standstill_progress").fetchall())
        logged: set[str] = set()
        thinned: dict[tuple[str, date], tuple[int, int, float]] = {}
        if "retention_log" in have and action_ids:
            logged = {r[0] for r in con.execute("SELECT action_id FROM retention_log WHERE list_contains(?, action_id)", [action_ids]).fetchall()}
        if "retention_log" in have and candidates:
            done = "" if "state" not in log_columns(con) else f" AND state <> '{INTENT}'"
            rows = con.execute(
                "SELECT valve_id, date, size_after_bytes, epoch_us(applied_at), thin_keep_s_per_hour FROM retention_log "
                f"WHERE action = 'thin'{done} AND list_contains(?, valve_id) QUALIFY applied_at = max(applied_at) OVER (PARTITION BY valve_id, date)",
                [list(candidates)],
            ).fetchall()
            thinned = {(v, d): (b, t, k) for v, d, b, t, k in rows}
    return WarehouseState(covers, checked, frozenset(logged), thinned)


def scan_partition(folder: Path, cover: tuple[np.ndarray, np.ndarray], hours: bool) -> PartitionScan:
    """First pass over a partition's time stamps, file by file, batch by batch (``hours``: note
    each hour's first sample, for thinning)."""
    scan = PartitionScan(cover, hours)
    for f in day_files(folder):
        for batch in iter_file_batches(f, [TIME]):
            scan.add(batch[TIME].to_physical().to_numpy())
    return scan


@dataclass(frozen=True)
class FileThinning:
    """One file of a partition in thin mode: its rows, the rows kept, as ``[start, stop)`` row
    ranges of the file."""

    rows: int
    kept: int
    ranges: np.ndarray


def count_kept(folder: Path, scan: PartitionScan, keep_s: float) -> dict[Path, FileThinning]:
    """Second pass (thin mode): the rows thinning keeps (into ``scan``), per file, as row ranges;
    only the time stamps of the row groups whose time range can hold kept samples are read
    (:func:`kept_row_groups`), one row group at a time."""
    scan.rows_kept = 0
    per_file = {}
    for f in day_files(folder):
        spans = row_group_spans(f)
        offsets = np.r_[0, np.cumsum([n for n, _, _ in spans])]
        before = scan.rows_kept
        ranges = []
        for g in kept_row_groups(spans, scan.firsts, keep_s):
            at = int(offsets[g])  # the file's row of the batch's first (a large row group of an older file comes in batches)
            for batch in iter_file_batches(f, [TIME], row_groups=[g]):
                ranges.append(scan.count_kept(batch[TIME].to_physical().to_numpy(), keep_s) + at)
                at += batch.height
        per_file[f] = FileThinning(int(offsets[-1]), scan.rows_kept - before, np.concatenate(ranges) if ranges else np.zeros((0, 2), np.int64))
    return per_file


def thin_partition(per_file: dict[Path, FileThinning], codec: str) -> int:
    """Replace each file of the partition by its kept rows, read range by range (only the pages
    holding them are decoded; memory holds one range and one row group of kept rows), written with
    ``codec`` (``[lake] codec``), atomically per file; a file that keeps all its rows is left
    alone, one that keeps none is deleted. Returns the rows kept."""
    for f, ft in per_file.items():
        if ft.kept == ft.rows:
            continue
        if ft.kept == 0:
            remove_partition_file(f)
            continue
        write_partition_pieces(f, read_file_ranges(f, ft.ranges), codec=codec)
    return sum(ft.kept for ft in per_file.values())


INTENT, DONE = "intent", "done"
"""``retention_log.state``: recorded before the data change, and completed after it."""


def _log_row(action_id: str, o: PartitionOutcome, spec: RetentionSpec, as_of: date, state: str = DONE) -> pl.DataFrame:
    return pl.DataFrame(
        [{
            "action_id": action_id, "valve_id": o.valve_id, "date": o.day, "action": o.action,
            "rows_before": o.rows_before, "rows_after": o.rows_after,
            "size_before_bytes": o.bytes_before, "size_after_bytes": o.bytes_after,
            "keep_days": spec.keep_days, "thin_keep_s_per_hour": spec.thin_keep_s_per_hour if o.action == "thin" else None,
            "as_of": as_of, "applied_at": datetime.now(timezone.utc), "state": state,
        }],
        schema=polars_schema(RETENTION_LOG_FIELDS),
    )  # fmt: skip


def _ensure_log(con) -> None:
    """``retention_log`` as the registry has it; rows of an older warehouse (no ``state``) are done."""
    ensure_tables(con, RETENTION_TABLES)
    add_missing_columns(con, {"retention_log": RETENTION_LOG_FIELDS})
    con.execute(f"UPDATE retention_log SET state = '{DONE}' WHERE state = ''")


def record(warehouse: Path, rows: pl.DataFrame) -> None:
    """Append actions to ``retention_log`` (created from the field registry if missing): an
    intent before the data change, or a completed action."""
    with connect(warehouse) as con:
        _ensure_log(con)
        insert_frame(con, "retention_log", rows)


def complete(warehouse: Path, action_id: str, rows_after: int, bytes_after: int) -> None:
    """Mark an intent done, with what the partition holds after the change."""
    with connect(warehouse) as con:
        _ensure_log(con)
        con.execute(
            f"UPDATE retention_log SET state = '{DONE}', rows_after = ?, size_after_bytes = ?, applied_at = ? WHERE action_id = ?",
            [rows_after, bytes_after, datetime.now(timezone.utc), action_id],
        )


def withdraw(warehouse: Path, action_id: str) -> None:
    """Delete an intent whose data change never began (the partition is whole)."""
    with connect(warehouse) as con:
        con.execute("DELETE FROM retention_log WHERE action_id = ? AND state = ?", [action_id, INTENT])


def log_columns(con) -> set[str]:
    """The columns ``retention_log`` has (none without the table; no ``state`` in an older warehouse)."""
    return {r[0] for r in con.execute(
        "SELECT column_name FROM duckdb_columns() WHERE database_name = current_database() AND table_name = 'retention_log'"
    ).fetchall()}  # fmt: skip


def pending_intents(warehouse: Path, valve_ids: list[str] | None) -> list[tuple[str, str, date, str]]:
    """``(action_id, valve_id, date, action)`` of the intents a killed run left (read-only)."""
    if not db_path(warehouse).exists():
        return []
    with connect(warehouse, read_only=True) as con:
        if "state" not in log_columns(con):
            return []
        rows = con.execute("SELECT action_id, valve_id, date, action FROM retention_log WHERE state = ? ORDER BY valve_id, date", [INTENT]).fetchall()
    return [r for r in rows if valve_ids is None or r[1] in valve_ids]


def complete_interrupted(warehouse: Path, spec: RetentionSpec, as_of: date, valve_ids: list[str] | None, dry_run: bool, codec: str) -> list[tuple[str, date]]:
    """Finish what a killed run began (module doc): the drops it renamed but did not delete
    (recorded first if an older version left them without a record), and its intents: a drop
    completed or, if the partition was never renamed, withdrawn; a thinning done again and
    completed. Returns the partitions completed (in a dry run: that would be)."""
    left = dropped_folders(warehouse, valve_ids)
    pending = pending_intents(warehouse, valve_ids)
    begun = sorted({(v, d) for v, d, _, _ in left} | {(v, d) for _, v, d, _ in pending})
    if dry_run or not begun:
        return begun
    logged = read_state(warehouse, {}, [a for _, _, a, _ in left]).logged
    for vid, day, action_id, hidden in left:
        if action_id not in logged:
            o = PartitionOutcome(vid, day, "drop", "", partition_bytes(hidden), partition_rows(hidden), 0, 0)
            record(warehouse, _log_row(action_id, o, spec, as_of))
        remove_dropped(hidden)
    for action_id, vid, day, action in pending:
        folder = partition_path(warehouse, vid, day).parent
        present = folder.is_dir() and bool(day_files(folder))
        if action == "drop":
            if present:
                withdraw(warehouse, action_id)
                begun.remove((vid, day))
            else:
                complete(warehouse, action_id, 0, 0)
            continue
        if not present:
            complete(warehouse, action_id, 0, 0)
            continue
        with partition_lock(warehouse, folder / PART_NAME):
            scan = scan_partition(folder, (np.zeros(0, np.int64), np.zeros(0, np.int64)), True)
            per_file = count_kept(folder, scan, spec.thin_keep_s_per_hour)
            complete(warehouse, action_id, thin_partition(per_file, codec), partition_bytes(folder))
    return begun


AS_OF_AFTER_INGEST = timedelta(days=1)
"""How far after the warehouse's latest ingest an ``as_of`` may lie without ``force``."""
EARLIEST_ZONE = timedelta(hours=14)
"""The furthest any time zone is ahead of UTC (UTC+14): "today" there is the latest ``as_of`` that
is today somewhere (the nightly run's is the plant's local today)."""


def latest_today(now: datetime) -> date:
    """The latest date that is today in some time zone at ``now``."""
    return (now.astimezone(timezone.utc) + EARLIEST_ZONE).date()


def check_as_of(warehouse: Path, as_of: date, today: date) -> None:
    """Refuse an ``as_of`` later than ``today`` (:func:`latest_today`) or more than
    :data:`AS_OF_AFTER_INGEST` after the latest ingest (``ingest_manifest.ingested_at``): it would
    make data look older than it is.

    Raises
    ------
    ValvemonError
        Naming the date, the limit and ``--force``.
    """
    if as_of > today:
        raise ValvemonError(f"--as-of {as_of} is later than today ({today}): data would count as older than it is; give --force if that is meant")
    if not db_path(warehouse).exists():
        return
    with connect(warehouse, read_only=True) as con:
        if not con.execute("SELECT count(*) FROM duckdb_tables() WHERE database_name = current_database() AND table_name = 'ingest_manifest'").fetchone()[0]:
            return
        latest = con.execute("SELECT max(ingested_at) FROM ingest_manifest").fetchone()[0]
    if latest is not None and as_of > (latest + AS_OF_AFTER_INGEST).date():
        raise ValvemonError(
            f"--as-of {as_of} is more than a day after the latest ingest ({latest:%Y-%m-%d %H:%M} UTC): "
            "data would count as older than it is; give --force if that is meant"
        )


def run_retention(
    config: PlantConfig, warehouse: str | Path, *, valve_ids: list[str] | None = None, as_of: date | None = None, dry_run: bool = False,
    force: bool = False,
) -> RetentionSummary:
    """Apply (or with ``dry_run`` only report) the plant's ``[retention]`` to the lake (module doc).

    ``as_of`` (default today) later than today or more than a day after the latest ingest is
    refused unless ``force`` (:func:`check_as_of`); a dry run only reports."""
    spec = config.retention
    if spec is None:
        raise ValueError("run_retention: the plant configures no [retention]")
    warehouse = Path(warehouse)
    ids = plant_valves(config, valve_ids, "--valves")
    now = datetime.now(timezone.utc)
    today = now.date()
    if as_of is not None and not force and not dry_run:
        check_as_of(warehouse, as_of, latest_today(now))
    as_of = as_of or today
    summary = RetentionSummary(as_of, spec, dry_run, today=today)
    # a dry run takes no lock either: even a lock file would be a write
    lock = nullcontext() if dry_run else file_lock(warehouse / ".retention.lock", f"{warehouse}: another retention run is working on this warehouse")
    with lock:
        summary.interrupted = complete_interrupted(warehouse, spec, as_of, ids, dry_run, config.lake.codec)
        protected = {v.id: protected_days([v.baseline_window] if v.baseline_window else []) for v in config.valves}
        todo: list[tuple[str, date, Path]] = []
        for vid, day, folder in partition_folders(warehouse, ids):
            early = decide_unscanned(day, as_of, spec, protected[vid])
            if early is not None:
                summary.outcomes.append(PartitionOutcome(vid, day, early.action, early.reason, partition_bytes(folder)))
            else:
                todo.append((vid, day, folder))
        spans: dict[str, tuple[date, date]] = {}
        for vid, day, _ in todo:
            first, last = spans.get(vid, (day, day))
            spans[vid] = (min(first, day), max(last, day))
        state = read_state(warehouse, spans, [])
        for vid, day, folder in todo:
            if spec.mode == "thin" and state.thinned_as_logged(vid, day, folder, spec.thin_keep_s_per_hour):
                summary.outcomes.append(PartitionOutcome(vid, day, KEEP, REASON_THINNED, partition_bytes(folder)))
                continue
            with nullcontext() if dry_run else partition_lock(warehouse, folder / PART_NAME):
                summary.outcomes.append(_one_partition(warehouse, vid, day, folder, spec, protected[vid], state, as_of, dry_run, config.lake.codec))
    summary.outcomes.sort(key=lambda o: (o.valve_id, o.day))
    return summary


def _one_partition(
    warehouse: Path, vid: str, day: date, folder: Path, spec: RetentionSpec, protected: frozenset[date], state: WarehouseState,
    as_of: date, dry_run: bool, codec: str,
) -> PartitionOutcome:
    """Decide one partition past steps 1–2 and, unless ``dry_run``, apply the decision."""
    bytes_before = partition_bytes(folder)
    scan = scan_partition(folder, state.covers[vid], spec.mode == "thin")
    checked = state.checked_through_us.get(vid)
    per_file: dict[Path, FileThinning] = {}
    if spec.mode == "thin" and decide_fitted(scan, checked) is None:
        per_file = count_kept(folder, scan, spec.thin_keep_s_per_hour)
    d: Decision = decide(day, as_of, spec, protected, scan, checked)
    o = PartitionOutcome(vid, day, d.action, d.reason, bytes_before, scan.rows)
    if d.action == "drop":
        o.rows_after, o.bytes_after = 0, 0
        if not dry_run:
            action_id = uuid.uuid4().hex
            record(warehouse, _log_row(action_id, o, spec, as_of, INTENT))
            remove_dropped(drop_partition(folder, action_id))
            complete(warehouse, action_id, 0, 0)
    elif d.action == "thin":
        o.rows_after = scan.rows_kept
        o.bytes_after = round(bytes_before * scan.rows_kept / scan.rows) if scan.rows else 0
        if not dry_run:
            action_id = uuid.uuid4().hex
            record(warehouse, _log_row(action_id, o, spec, as_of, INTENT))  # rows after exact, bytes after estimated
            o.rows_after = thin_partition(per_file, codec)
            o.bytes_after = partition_bytes(folder)
            complete(warehouse, action_id, o.rows_after, o.bytes_after)
    return o


@flow(name="valvemon-retention", persist_result=False, validate_parameters=False)
def retention_flow(
    config_path: str, warehouse: str, valve_ids: list[str] | None = None, as_of: str | None = None, dry_run: bool = False, force: bool = False
) -> RetentionSummary | None:
    """The Prefect flow behind ``valvemon retention`` (and the nightly run's last step); None when
    the plant configures no ``[retention]``."""
    config = load_plant_config(config_path)
    if config.retention is None:
        return None
    try:
        day = date.fromisoformat(as_of) if as_of else None
    except ValueError:
        raise ValvemonError(f"--as-of: {as_of!r} is not an ISO date (YYYY-MM-DD)") from None
    return run_retention(config, warehouse, valve_ids=valve_ids, as_of=day, dry_run=dry_run, force=force)

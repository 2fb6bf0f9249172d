"""The ``sql/`` views: found, ordered by their dependencies, created in the warehouse database;
and the read-only snapshot that readers query.

Views
-----
One view per file, ``sql/<layer>/<name>.sql`` → view ``<name>``; layers ``staging`` (reads only
tables), ``core`` (staging and core) and ``report`` (anything). A view depends on every other
view whose name appears in its SQL as a word (comments stripped); :func:`ordered_views` sorts
them so each is created after what it reads, and rejects cycles and layer violations.
:func:`create_views` runs ``CREATE OR REPLACE VIEW`` for all of them, in one transaction, unless
they are already those (their comments hold a fingerprint of their SQL and the tables' columns).

Readers and the writer
----------------------
DuckDB lets one process hold a database file read-write, and then no other process may open it
at all (not even read-only); a read-only connection in turn keeps every writer out. So readers
never touch the live ``valvemon.duckdb``: every writing command ends by publishing a
consistent copy, ``WAREHOUSE/snapshot/valvemon.duckdb`` (:func:`publish_snapshot`, called by
:func:`flows.report.publish.publish`): the writer, inside its own short-lived read-write
connection, checkpoints the database and copies the file's bytes into a temporary file (nothing
writes meanwhile: the connection holds the write lock), then ``os.replace``-s it over the snapshot. Readers (``valvemon query``, the DuckDB CLI with
``-readonly``, BI tools) open the snapshot read-only (:func:`connect_snapshot`): a reader that
has the old file open keeps reading the old file (the rename does not touch it), the next one
gets the new file, and the writer never waits for a reader nor a reader for the writer.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import duckdb

from flows.common.errors import ValvemonError
from flows.common.warehouse_db import DB_NAME, add_missing_columns, db_path, ensure_tables, transaction
from schemas.fields import (
    ALARM_WINDOW_FIELDS,
    CONDITION_BOUNDS_FIELDS,
    CONDITION_HISTORY_FIELDS,
    EDGE_DAY_FIELDS,
    NOTIFICATION_FIELDS,
    PARAMETER_DAY_FIELDS,
    STANDSTILL_FIELDS,
    STANDSTILL_PROGRESS_FIELDS,
    SUMMARY_WATERMARK_FIELDS,
)

SQL_DIR = Path(__file__).resolve().parents[2] / "sql"
"""The repository's ``sql/`` folder."""

LAYERS: tuple[str, ...] = ("staging", "core", "report")
"""Layers in dependency order; a view may read views of its own layer and the layers before."""

SNAPSHOT_DIR = "snapshot"
"""Folder of the published read-only copy of the database inside the warehouse."""

REPORT_TABLES = {
    "condition_bounds": CONDITION_BOUNDS_FIELDS,
    "standstill_checks": STANDSTILL_FIELDS,
    "standstill_progress": STANDSTILL_PROGRESS_FIELDS,
    "edge_day_summaries": EDGE_DAY_FIELDS,
    "parameter_day_summaries": PARAMETER_DAY_FIELDS,
    "alarm_windows": ALARM_WINDOW_FIELDS,
    "summary_watermarks": SUMMARY_WATERMARK_FIELDS,
    "condition_history": CONDITION_HISTORY_FIELDS,
    "notifications": NOTIFICATION_FIELDS,
}
"""Tables the report and the publish write (besides the monitor's), created empty if missing so the views bind."""


@dataclass(frozen=True)
class ViewFile:
    """One view: its name, layer, SQL and the views it reads."""

    name: str
    layer: str
    path: Path
    sql: str
    depends_on: tuple[str, ...]


def _strip_comments(sql: str) -> str:
    sql = re.sub(r"/\*.*?\*/", " ", sql, flags=re.S)
    return re.sub(r"--[^\n]*", " ", sql)


def discover_views(sql_dir: Path = SQL_DIR) -> dict[str, ViewFile]:
    """All ``sql/<layer>/*.sql`` files as :class:`ViewFile`, with their dependencies."""
    if not sql_dir.is_dir():
        raise ValvemonError(f"{sql_dir}: the view folder is missing")
    found: dict[str, tuple[str, Path, str]] = {}
    for layer in LAYERS:
        for path in sorted((sql_dir / layer).glob("*.sql")):
            name = path.stem
            if not re.fullmatch(r"[a-z_][a-z0-9_]*", name):
                raise ValvemonError(f"{path}: a view file name must be a lower-case SQL identifier")
            if name in found:
                raise ValvemonError(f"{path}: view {name!r} is also defined in {found[name][1]}")
            found[name] = (layer, path, path.read_text())
    views = {}
    for name, (layer, path, sql) in found.items():
        body = _strip_comments(sql).lower()
        deps = tuple(sorted(o for o in found if o != name and re.search(rf"\b{o}\b", body)))
        views[name] = ViewFile(name, layer, path, sql.strip().rstrip(";"), deps)
    return views


def ordered_views(views: dict[str, ViewFile]) -> list[ViewFile]:
    """Views in creation order (each after what it reads); layer violations and cycles raise."""
    rank = {layer: i for i, layer in enumerate(LAYERS)}
    for v in views.values():
        for d in v.depends_on:
            if rank[views[d].layer] > rank[v.layer]:
                raise ValvemonError(f"{v.path}: a {v.layer} view may not read the {views[d].layer} view {d!r}")
            if v.layer == "staging" and views[d].layer == "staging":
                pass  # staging views may build on each other (e.g. long form of a staged table)
    done: list[ViewFile] = []
    state: dict[str, int] = {}

    def visit(name: str, chain: tuple[str, ...]) -> None:
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            raise ValvemonError(f"views depend on each other in a cycle: {' -> '.join(chain + (name,))}")
        state[name] = 1
        for d in views[name].depends_on:
            visit(d, chain + (name,))
        state[name] = 2
        done.append(views[name])

    for name in sorted(views, key=lambda n: (rank[views[n].layer], n)):
        visit(name, ())
    return done


def ensure_report_tables(con: duckdb.DuckDBPyConnection) -> None:
    """Create the tables of :data:`REPORT_TABLES` (and the monitor's tables) if missing."""
    from flows.monitor.tables import ensure_monitor_tables

    ensure_monitor_tables(con)
    ensure_tables(con, {name: (fields, None) for name, fields in REPORT_TABLES.items()})
    add_missing_columns(con, REPORT_TABLES)
    con.execute("CREATE UNIQUE INDEX IF NOT EXISTS standstill_checks_key ON standstill_checks (valve_id, window_start)")


def views_stamp(con: duckdb.DuckDBPyConnection, views: list[ViewFile]) -> str:
    """A fingerprint of what the views are bound from: their SQL in creation order, the columns
    of the database's tables and DuckDB's version (a view's columns are fixed when it is made)."""
    columns = con.execute(
        "SELECT table_name, column_name, data_type FROM duckdb_columns() c WHERE database_name = current_database() AND NOT internal"
        " AND EXISTS (SELECT 1 FROM duckdb_tables() t WHERE t.database_name = c.database_name AND t.schema_name = c.schema_name"
        " AND t.table_name = c.table_name) ORDER BY schema_name, table_name, column_index"
    ).fetchall()
    digest = hashlib.sha256(duckdb.__version__.encode())
    for v in views:
        digest.update(f"\0{v.name}\0{v.sql}".encode())
    digest.update(repr(columns).encode())
    return digest.hexdigest()


def create_views(con: duckdb.DuckDBPyConnection, sql_dir: Path = SQL_DIR) -> list[str]:
    """``CREATE OR REPLACE VIEW`` every view of ``sql_dir`` in dependency order, in one transaction;
    each view's comment then holds :func:`views_stamp`. When every view already carries the stamp
    (the same SQL over the same tables, what every command's publish meets but the first after an
    upgrade) nothing is created: binding the 23 views of `sql/` cost each command ~0.35 CPU-s.

    The tables the views read must exist (:func:`ensure_report_tables`). Returns the view names
    in the order they were created.
    """
    views = ordered_views(discover_views(sql_dir))
    stamp = views_stamp(con, views)
    stamps = dict(con.execute(
        "SELECT view_name, comment FROM duckdb_views() WHERE database_name = current_database() AND schema_name = 'main' AND NOT internal"
    ).fetchall())  # fmt: skip
    if all(stamps.get(v.name) == stamp for v in views):
        return [v.name for v in views]
    with transaction(con):
        for v in views:
            try:
                con.execute(f"CREATE OR REPLACE VIEW {v.name} AS\n{v.sql}")
            except duckdb.Error as exc:
                raise ValvemonError(f"{v.path}: {str(exc).splitlines()[0]}") from None
            con.execute(f"COMMENT ON VIEW {v.name} IS '{stamp}'")
    return [v.name for v in views]


def materialise_views(con: duckdb.DuckDBPyConnection, names: tuple[str, ...], sql_dir: Path = SQL_DIR) -> list[str]:
    """Compute the views ``names`` and the core and report views they read once each, in
    dependency order, into temporary tables of the same names in this connection.

    DuckDB resolves a name to a temporary object before the database's own, also inside a view's
    body, so every later query of this connection reads the tables: a report that reads
    ``valve_condition``, ``fleet_ranking``, ``parameter_trends`` and ``trend_daily`` evaluates
    ``fit_checks`` (the rolling median and quartiles over every ok window) once, not once per
    query and valve. Nothing is written to the database (a read-only connection will do).
    Returns the views materialised, in order."""
    views = discover_views(sql_dir)
    wanted: set[str] = set()

    def add(name: str) -> None:
        if name not in wanted and views[name].layer != "staging":
            wanted.add(name)
            for d in views[name].depends_on:
                add(d)

    for name in names:
        add(name)
    db = con.execute("SELECT current_database()").fetchone()[0]
    done = [v.name for v in ordered_views(views) if v.name in wanted]
    for name in done:
        con.execute(f'CREATE OR REPLACE TEMP TABLE {name} AS SELECT * FROM "{db}".main.{name}')
    return done


def snapshot_path(warehouse: str | Path) -> Path:
    """``WAREHOUSE/snapshot/valvemon.duckdb``, the copy readers open."""
    return Path(warehouse) / SNAPSHOT_DIR / DB_NAME


def publish_snapshot(con: duckdb.DuckDBPyConnection, warehouse: str | Path) -> Path:
    """Copy the database of the open read-write connection ``con`` to the snapshot, atomically.

    ``con`` holds the database's write lock, so no other process writes it meanwhile (and the
    commands publish after their own work, so nothing in this process does either). A
    ``CHECKPOINT`` moves everything committed into the database file, leaving the write-ahead
    log empty; the file's bytes are then copied into a hidden temporary file beside the snapshot,
    which is checked to open and then replaces the snapshot by ``os.replace``; a reader holding
    the previous snapshot keeps reading it undisturbed. A byte copy costs a fraction of DuckDB's
    ``COPY FROM DATABASE``, which re-encodes every row (``docs/warehouse.md``, "Readers and the writer").
    """
    target = snapshot_path(warehouse)
    target.parent.mkdir(parents=True, exist_ok=True)
    for stale in target.parent.glob(f".{DB_NAME}.*.tmp*"):
        stale.unlink(missing_ok=True)
    tmp = target.parent / f".{DB_NAME}.{uuid.uuid4().hex}.tmp"
    source = con.execute("SELECT path FROM duckdb_databases() WHERE database_name = current_database()").fetchall()[0][0]
    try:
        con.execute("CHECKPOINT")
        shutil.copyfile(source, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        check = duckdb.connect(str(tmp), read_only=True)
        try:
            check.execute("SELECT count(*) FROM duckdb_tables()").fetchall()
        finally:
            check.close()
        os.replace(tmp, target)
        fd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except BaseException:
        tmp.unlink(missing_ok=True)
        Path(f"{tmp}.wal").unlink(missing_ok=True)
        raise
    return target


def connect_snapshot(warehouse: str | Path, *, live: bool = False, wait_s: float = 10.0) -> duckdb.DuckDBPyConnection:
    """A read-only connection for readers: the published snapshot, or the live file if ``live``.

    The snapshot never waits: no process ever opens it read-write. ``live=True`` opens
    ``valvemon.duckdb`` itself read-only, retrying for ``wait_s`` while a writer holds it (and
    keeping writers out while open): for when the snapshot is not recent enough.
    """
    path = db_path(warehouse) if live else snapshot_path(warehouse)
    if not path.exists():
        hint = "" if live else " (every writing command publishes it: ingest, monitor, backfill, report; --live reads the live database)"
        raise ValvemonError(f"{path}: no such database{hint}")
    deadline = time.monotonic() + wait_s
    delay = 0.05
    while True:
        try:
            con = duckdb.connect(str(path), read_only=True)
            break
        except duckdb.IOException as exc:
            if not live or "lock" not in str(exc).lower() or time.monotonic() > deadline:
                raise ValvemonError(f"{path}: cannot open the database: {str(exc).splitlines()[0]}") from None
            time.sleep(delay)
            delay = min(delay * 2, 1.0)
    con.execute("SET TimeZone = 'UTC'")
    return con

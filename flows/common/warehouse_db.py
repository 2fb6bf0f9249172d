"""Short-lived connections to ``WAREHOUSE/valvemon.duckdb`` and the ingest's tables.

A read-write DuckDB connection locks the file against other processes, so every user opens a
connection for one unit of work and closes it (:func:`connect`); a locked file is retried for a
while before the caller gets a :class:`ValvemonError`. The file is attached to one in-memory
DuckDB instance per process (:class:`_Host`) rather than opened as an instance of its own: the
same lock, at ~1.5 instead of ~30 ms of CPU per unit of work. Results are fetched before the next
statement (DuckDB 2.0 requires it). Tables are created from the field registry
(:func:`create_table_sql`), so their columns are the ones ``schemas.fields`` documents.

Ingest tables: ``ingest_manifest`` (one row per ingested file, key ``file_hash``),
``ingest_runs`` (one row per run, key ``run_id``), ``quarantine`` and ``ingest_gaps``
(rows keyed by the file's ``file_hash``, replaced whole when a file is ingested again).
Warehouses from before the BLAKE3 content hash are migrated when the tables are first ensured
(:func:`migrate_hash_column`).
"""

from __future__ import annotations

import atexit
import os
import threading
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Mapping, TypeVar

import duckdb
import polars as pl

from flows.common.errors import ValvemonError
from schemas.fields import GAP_FIELDS, INGEST_RUN_FIELDS, MANIFEST_FIELDS, QUARANTINE_FIELDS, Field

DB_NAME = "valvemon.duckdb"
T = TypeVar("T")

INGEST_TABLES: dict[str, tuple[tuple[Field, ...], str | None]] = {
    "ingest_manifest": (MANIFEST_FIELDS, "file_hash"),
    "ingest_runs": (INGEST_RUN_FIELDS, "run_id"),
    "quarantine": (QUARANTINE_FIELDS, None),
    "ingest_gaps": (GAP_FIELDS, None),
}
"""Table name → (fields, primary key)."""


def db_path(warehouse: str | Path) -> Path:
    """The warehouse's DuckDB file."""
    return Path(warehouse) / DB_NAME


def duckdb_type(dtype: pl.DataType) -> str:
    """DuckDB column type of a registry dtype."""
    if isinstance(dtype, pl.Datetime):
        return "TIMESTAMPTZ" if dtype.time_zone else "TIMESTAMP"
    if isinstance(dtype, pl.List):
        return f"{duckdb_type(dtype.inner)}[]"
    simple = {
        pl.String: "VARCHAR",
        pl.Int64: "BIGINT",
        pl.Int32: "INTEGER",
        pl.Float64: "DOUBLE",
        pl.Float32: "FLOAT",
        pl.Boolean: "BOOLEAN",
        pl.Date: "DATE",
    }
    for k, v in simple.items():
        if dtype == k:
            return v
    raise TypeError(f"no DuckDB type for {dtype}")


def create_table_sql(name: str, fields: tuple[Field, ...], primary_key: str | None = None) -> str:
    """``CREATE TABLE IF NOT EXISTS`` from registry fields (with a comment-free, stable column order)."""
    cols = []
    for f in fields:
        null = "" if f.nullable else " NOT NULL"
        pk = " PRIMARY KEY" if f.name == primary_key else ""
        cols.append(f'"{f.name}" {duckdb_type(f.dtype)}{null}{pk}')
    return f"CREATE TABLE IF NOT EXISTS {name} ({', '.join(cols)})"


@dataclass
class _Attachment:
    """A warehouse file attached to the host."""

    alias: str
    users: int
    read_only: bool


class _Host:
    """One in-memory DuckDB instance per process that attaches warehouse files on demand.

    Creating a DuckDB instance costs ~30 ms of CPU; attaching a file to a running one ~2 ms. So
    :func:`connect` attaches the warehouse file to this host (``ATTACH``, which takes the same
    file lock a ``duckdb.connect`` would), hands out a connection of its own with the file as
    the default database, and detaches the file (checkpoint, lock released) when the last user
    in the process is done. Users in several threads share one attachment, as they would have
    shared one instance before."""

    def __init__(self):
        self.guard = threading.Lock()
        self.instance: duckdb.DuckDBPyConnection | None = None
        self.attached: dict[str, _Attachment] = {}
        """file → its attachment"""

    def acquire(self, path: Path, read_only: bool) -> str | None:
        """The alias of the attached file (attached now if needed); None while the file is
        attached read-only and read-write access is wanted (retry later)."""
        key = str(path)
        with self.guard:
            entry = self.attached.get(key)
            if entry is not None:
                if entry.read_only and not read_only:
                    return None
                entry.users += 1
                return entry.alias
            if self.instance is None:
                self.instance = duckdb.connect()
            alias = f"warehouse_{uuid.uuid4().hex[:12]}"
            quoted = key.replace("'", "''")
            self.instance.execute(f"ATTACH '{quoted}' AS {alias}" + (" (READ_ONLY)" if read_only else ""))
            self.attached[key] = _Attachment(alias, 1, read_only)
            return alias

    def release(self, path: Path) -> None:
        key = str(path)
        with self.guard:
            entry = self.attached[key]
            entry.users -= 1
            if entry.users == 0:
                del self.attached[key]
                self.instance.execute(f"DETACH {entry.alias}")

    def close(self) -> None:
        """At exit: detach everything (a checkpoint each) and close the instance."""
        with self.guard:
            if self.instance is not None:
                self.instance.close()
            self.instance = None
            self.attached = {}

    def forget(self) -> None:
        """In a forked child: the parent's instance and its threads are not ours to use (nor to
        destroy: it is kept, unused, until the child exits)."""
        if self.instance is not None:
            _ABANDONED.append(self.instance)
        self.guard = threading.Lock()
        self.instance = None
        self.attached = {}


_ABANDONED: list[duckdb.DuckDBPyConnection] = []
_HOST = _Host()
atexit.register(_HOST.close)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_HOST.forget)


@contextmanager
def connect(warehouse: str | Path, *, read_only: bool = False, wait_s: float = 30.0) -> Iterator[duckdb.DuckDBPyConnection]:
    """Open the warehouse database for one unit of work; closed on exit.

    The connection's default database is the warehouse file, attached to the process's DuckDB
    host (:class:`_Host`) for as long as some user in the process has it open.

    Parameters
    ----------
    warehouse : path
        The warehouse folder (created if missing, unless ``read_only``).
    read_only : bool
        Open without the write lock (the file must exist).
    wait_s : float
        How long to retry while another process holds the lock.
    """
    path = db_path(warehouse).resolve()
    if not read_only:
        path.parent.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + wait_s
    delay = 0.05
    while True:
        try:
            alias = _HOST.acquire(path, read_only)
            if alias is not None:
                break
            reason = "it is open read-only in this process"
        except (duckdb.IOException, duckdb.BinderException) as exc:
            reason = str(exc).splitlines()[0]
            if "lock" not in reason.lower():
                raise ValvemonError(f"{path}: cannot open the warehouse database: {reason}") from None
        if time.monotonic() > deadline:
            raise ValvemonError(f"{path}: cannot open the warehouse database: {reason}")
        time.sleep(delay)
        delay = min(delay * 2, 1.0)
    try:
        con = _HOST.instance.cursor()
        try:
            con.execute(f"USE {alias}")
            con.execute("SET TimeZone = 'UTC'")
            yield con
        finally:
            con.close()
    finally:
        _HOST.release(path)


@contextmanager
def transaction(con: duckdb.DuckDBPyConnection) -> Iterator[duckdb.DuckDBPyConnection]:
    """The statements of the block in one transaction: committed at its end, rolled back if it
    raises (or is interrupted)."""
    con.execute("BEGIN TRANSACTION")
    try:
        yield con
        con.execute("COMMIT")
    except BaseException:
        con.execute("ROLLBACK")
        raise


def ensure_tables(con: duckdb.DuckDBPyConnection, tables: Mapping[str, tuple[tuple[Field, ...], str | None]]) -> None:
    """Create those of ``tables`` (name → (fields, primary key or None)) that the connection's
    database lacks: one catalog query, DDL only for the missing ones (every unit of work calls
    this; a warehouse that has its tables costs no DDL)."""
    have = {r[0] for r in con.execute(
        "SELECT table_name FROM duckdb_tables() WHERE database_name = current_database()"
    ).fetchall()}  # fmt: skip
    for name, (fields, key) in tables.items():
        if name not in have:
            con.execute(create_table_sql(name, fields, key))


def add_missing_columns(con: duckdb.DuckDBPyConnection, tables: Mapping[str, tuple[Field, ...]]) -> None:
    """Add to existing ``tables`` (name → fields) the fields the registry gained after the
    warehouse was created, after their own columns, with the value that means "none" for the rows
    already there (null, or '' / 0 for a non-nullable text / number; a time has no "none" but
null); one catalog query, DDL only when
    something is missing."""
    names = list(tables)
    have: dict[str, set[str]] = {}
    for t, c in con.execute(
        f"SELECT table_name, column_name FROM duckdb_columns() WHERE database_name = current_database() "
        f"AND table_name IN ({', '.join('?' * len(names))})", names,
    ).fetchall():  # fmt: skip
        have.setdefault(t, set()).add(c)
    for name, fields in tables.items():
        for f in fields:
            if name in have and f.name not in have[name]:
                default = "NULL" if f.nullable else ("''" if f.dtype == pl.Utf8 else "0" if f.dtype.is_numeric() else "NULL")
                con.execute(f'ALTER TABLE {name} ADD COLUMN "{f.name}" {duckdb_type(f.dtype)} DEFAULT {default}')


def ensure_ingest_tables(con: duckdb.DuckDBPyConnection) -> None:
    """Create the ingest's tables if they do not exist (and migrate an older warehouse's)."""
    have: dict[str, set[str]] = {}
    for table, column in con.execute(
        "SELECT table_name, column_name FROM duckdb_columns() WHERE database_name = current_database()"
    ).fetchall():  # fmt: skip
        have.setdefault(table, set()).add(column)
    if all({f.name for f in fields} <= have.get(name, set()) and "file_sha256" not in have[name] for name, (fields, _) in INGEST_TABLES.items()):
        return  # a current warehouse (every ingest file's two units of work ask): one catalog query, no DDL
    for name in INGEST_TABLES:
        if "file_sha256" in have.get(name, ()):
            migrate_hash_column(con, name)
    ensure_tables(con, INGEST_TABLES)
    add_missing_columns(con, {name: fields for name, (fields, _) in INGEST_TABLES.items()})


def migrate_hash_column(con: duckdb.DuckDBPyConnection, table: str) -> None:
    """A table of a warehouse from before the BLAKE3 content hash: its column ``file_sha256``
    becomes ``file_hash`` and its values ``sha256:<hex>`` (the ingest still recognises those
    files, ``flows.ingest.flow.in_manifest``). Nothing happens to a table that is new or migrated."""
    cols = {r[0] for r in con.execute(
        "SELECT column_name FROM duckdb_columns() WHERE database_name = current_database() AND table_name = ?", [table]
    ).fetchall()}  # fmt: skip
    if "file_sha256" not in cols or "file_hash" in cols:
        return
    with transaction(con):
        con.execute(f"ALTER TABLE {table} RENAME COLUMN file_sha256 TO file_hash")
        con.execute(f"UPDATE {table} SET file_hash = 'sha256:' || file_hash WHERE NOT starts_with(file_hash, 'sha256:')")


def insert_frame(con: duckdb.DuckDBPyConnection, table: str, frame: pl.DataFrame, *, replace: bool = False) -> None:
    """Insert a polars frame into a table by column name (``INSERT OR REPLACE`` if ``replace``)."""
    if frame.height == 0:
        return
    con.register("_valvemon_frame", frame.to_arrow())
    try:
        verb = "INSERT OR REPLACE" if replace else "INSERT"
        con.execute(f"{verb} INTO {table} BY NAME SELECT * FROM _valvemon_frame")
    finally:
        con.unregister("_valvemon_frame")


INTERRUPT_WAIT_S = 5.0
"""After Ctrl-C, how long :func:`interruptible` waits for DuckDB to stop the interrupted statement
(it stops within milliseconds; the wait only bounds a statement that ignores the interrupt). [s]"""


def interruptible(con: duckdb.DuckDBPyConnection, work: Callable[[], T]) -> T:
    """``work()`` (statements on ``con``) run in a worker thread, so that Ctrl-C stops it at once.

    A statement running inside DuckDB does not see Python's SIGINT until it returns (a cross join
    ran on for minutes). Here the main thread only waits; on ``KeyboardInterrupt`` it calls
    ``con.interrupt()`` (DuckDB cancels the statement within milliseconds), waits for the worker
    to give up and raises ``KeyboardInterrupt``, so the caller's ``finally`` closes the
    connection and the command exits with 130, leaving the database as before.
    """
    result: dict[str, object] = {}
    done = threading.Event()

    def run() -> None:
        try:
            result["value"] = work()
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            result["error"] = exc
        finally:
            done.set()

    threading.Thread(target=run, name="valvemon-duckdb", daemon=True).start()
    try:
        while not done.wait(0.05):
            pass
    except KeyboardInterrupt:
        con.interrupt()
        done.wait(INTERRUPT_WAIT_S)
        raise
    if "error" in result:
        raise result["error"]
    return result["value"]


def query_frame(con: duckdb.DuckDBPyConnection, sql: str, params: list | None = None) -> pl.DataFrame:
    """Run a query and fetch its whole result as a polars frame."""
    rel = con.sql(sql, params=params) if params else con.sql(sql)
    return pl.from_arrow(rel.to_arrow_table())

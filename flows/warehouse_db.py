"""Short-lived connections to ``WAREHOUSE/valvemon.duckdb`` and the ingest's tables.

A read-write DuckDB connection locks the file against other processes, so every user opens a
connection for one unit of work and closes it (:func:`connect`); a locked file is retried for a
while before the caller gets a :class:`ValvemonError`. Results are fetched before the next
statement (DuckDB 2.0 requires it). Tables are created from the field registry
(:func:`create_table_sql`), so their columns are the ones ``schemas.fields`` documents.

Ingest tables: ``ingest_manifest`` (one row per ingested file, key ``file_sha256``),
``ingest_runs`` (one row per run, key ``run_id``), ``quarantine`` and ``ingest_gaps``
(rows keyed by the file's ``file_sha256``, replaced whole when a file is ingested again).
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import duckdb
import polars as pl

from flows.errors import ValvemonError
from schemas.fields import GAP_FIELDS, INGEST_RUN_FIELDS, MANIFEST_FIELDS, QUARANTINE_FIELDS, Field

DB_NAME = "valvemon.duckdb"

INGEST_TABLES: dict[str, tuple[tuple[Field, ...], str | None]] = {
    "ingest_manifest": (MANIFEST_FIELDS, "file_sha256"),
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


@contextmanager
def connect(warehouse: str | Path, *, read_only: bool = False, wait_s: float = 30.0) -> Iterator[duckdb.DuckDBPyConnection]:
    """Open the warehouse database for one unit of work; closed on exit.

    Parameters
    ----------
    warehouse : path
        The warehouse folder (created if missing, unless ``read_only``).
    read_only : bool
        Open without the write lock (the file must exist).
    wait_s : float
        How long to retry while another process holds the lock.
    """
    path = db_path(warehouse)
    if not read_only:
        path.parent.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + wait_s
    delay = 0.05
    while True:
        try:
            con = duckdb.connect(str(path), read_only=read_only)
            break
        except duckdb.IOException as exc:
            if "lock" not in str(exc).lower() or time.monotonic() > deadline:
                raise ValvemonError(f"{path}: cannot open the warehouse database: {str(exc).splitlines()[0]}") from None
            time.sleep(delay)
            delay = min(delay * 2, 1.0)
    try:
        con.execute("SET TimeZone = 'UTC'")
        yield con
    finally:
        con.close()


def ensure_ingest_tables(con: duckdb.DuckDBPyConnection) -> None:
    """Create the ingest's tables if they do not exist."""
    for name, (fields, key) in INGEST_TABLES.items():
        con.execute(create_table_sql(name, fields, key))


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


def query_frame(con: duckdb.DuckDBPyConnection, sql: str, params: list | None = None) -> pl.DataFrame:
    """Run a query and fetch its whole result as a polars frame."""
    rel = con.sql(sql, params=params) if params else con.sql(sql)
    return pl.from_arrow(rel.to_arrow_table())

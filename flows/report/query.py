"""``valvemon query``: an ad-hoc SQL query against the warehouse, printed or written to a file.

Reads the read-only snapshot the last writing command published (``--live``: the live
database, read-only), so a query never waits for the nightly writer and never holds it up
(:mod:`flows.report.views`). Output: a rich table (default), CSV (nested columns as JSON text), JSON (an array of objects,
times as ISO-8601 UTC) or Parquet (``--out`` required).

A query never changes the warehouse or writes a file (:func:`check_read_only`,
:func:`lock_down`): the database is attached read-only, only a single ``SELECT`` (or
``EXPLAIN`` of one) runs, and DuckDB's file system is closed except for reading the lake.
``--out`` writes only outside the warehouse folder, and over an existing file only with
``--force`` (:func:`check_out`), by replacing its name, never writing through it.
Ctrl-C stops a running query at once (``flows.common.warehouse_db.interruptible``): the command
exits with 130 and the database is released.
"""

from __future__ import annotations

import json
import os
import re
import sys
import tempfile
from contextlib import contextmanager
from decimal import Decimal
from pathlib import Path
from typing import IO, Iterator

import duckdb
import polars as pl

from flows.common.errors import ValvemonError
from flows.common.warehouse_db import interruptible
from flows.report.views import connect_snapshot

FORMATS = ("table", "csv", "json", "parquet")

_EXPLAIN_PREFIX = re.compile(r"\s*explain\s*(\([^)]*\))?\s*(analy[sz]e\b)?", re.IGNORECASE)
_REFUSED = "valvemon query runs one SELECT (or EXPLAIN of one) and never writes the warehouse or a file"


def _statements(sql: str) -> list:
    try:
        return duckdb.extract_statements(sql)
    except duckdb.Error as exc:
        raise ValvemonError(f"query failed: {str(exc).splitlines()[0]}") from None


def check_read_only(sql: str) -> None:
    """Refuse anything but one ``SELECT`` (``WITH``, ``FROM``, ``DESCRIBE``, ``SHOW``, ``SUMMARIZE``
    are SELECTs to DuckDB) or ``EXPLAIN`` of one. ``COPY ... TO``, ``EXPORT``, ``ATTACH``,
    ``INSTALL``, ``LOAD``, ``SET``, ``CREATE`` and the rest are refused before anything runs,
    including ``EXPLAIN ANALYZE COPY``, which would execute the copy.
    """
    statements = _statements(sql)
    if len(statements) != 1:
        raise ValvemonError(f"query refused: {len(statements)} statements; {_REFUSED}")
    statement = statements[0]
    kind = statement.type
    if kind == duckdb.StatementType.EXPLAIN:
        inner = _statements(statement.query[_EXPLAIN_PREFIX.match(statement.query).end() :])
        kind = inner[0].type if len(inner) == 1 else kind
    if kind != duckdb.StatementType.SELECT:
        raise ValvemonError(f"query refused: a {kind.name} statement; {_REFUSED}")


def lock_down(con: duckdb.DuckDBPyConnection, warehouse: Path) -> None:
    """Close DuckDB's file system for ``con`` except for the lake, turn off the progress bar
    (DuckDB prints it on stdout, into the result), then lock the settings.

    ``enable_external_access = false`` refuses every file, extension install or load and
    ``ATTACH`` outside ``allowed_directories``; the lake stays readable for
    ``read_parquet('WAREHOUSE/lake/sensors/**/*.parquet')``; ``lock_configuration`` refuses any
    ``SET`` that would reopen them. Writing into the lake is refused by :func:`check_read_only`.
    """
    lake = str((Path(warehouse) / "lake").resolve()).replace("'", "''")
    con.execute(f"SET allowed_directories = ['{lake}/']")
    con.execute("SET enable_external_access = false")
    con.execute("SET enable_progress_bar = false")  # DuckDB draws it on stdout, into the result (a query over 2 s)
    con.execute("SET lock_configuration = true")


def fetch(sql: str, warehouse: Path, *, live: bool = False) -> pl.DataFrame:
    """Run ``sql`` on the snapshot (or the live file) and return the whole result."""
    check_read_only(sql)
    con = connect_snapshot(warehouse, live=live)
    try:
        lock_down(con, warehouse)

        def run():
            rel = con.sql(sql)
            if rel is None:
                raise ValvemonError("the statement returned no result (only queries are supported)")
            return rel.to_arrow_table()

        try:
            return pl.from_arrow(interruptible(con, run))  # Ctrl-C stops the query (exit 130)
        except duckdb.Error as exc:
            raise ValvemonError(f"query failed: {str(exc).splitlines()[0]}") from None
    finally:
        con.close()


def check_out(out: Path, warehouse: Path, *, force: bool = False) -> None:
    """Refuse ``--out`` inside the warehouse folder (both resolved, so a symlink to the database,
    to a lake file or to the folder counts as inside), whatever ``force`` says: every file there
    belongs to a writer of the warehouse. Outside, refuse a folder, and an existing file unless
    ``force``."""
    where = Path(out).resolve()
    home = Path(warehouse).resolve()
    if where == home or home in where.parents:
        raise ValvemonError(f"--out {out}: inside the warehouse {warehouse} ({where}); a query never writes there, choose a file outside it")
    if where.is_dir():
        raise ValvemonError(f"--out {out}: is a folder; expected a file name")
    if os.path.lexists(out) and not force:
        raise ValvemonError(f"--out {out}: exists; add --force to replace it")


@contextmanager
def _replacing(out: Path, mode: str = "w") -> Iterator[IO]:
    """A temporary file beside ``out`` that replaces it (``os.replace``) once written whole: an
    existing ``out`` is replaced by name, so neither a hard link nor a symlink there is written
    through, and an interrupted query leaves ``out`` as it was."""
    out = Path(out)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _table(frame: pl.DataFrame, max_rows: int):
    from rich.table import Table

    t = Table(show_lines=False, header_style="bold")
    for name, dtype in frame.schema.items():
        t.add_column(f"{name}\n[dim]{dtype}[/dim]", justify="right" if dtype.is_numeric() else "left")
    for row in frame.head(max_rows).iter_rows():
        t.add_row(*("NULL" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v)) for v in row))
    return t


def _jsonable(value: object) -> str | float:
    """A value ``json`` cannot write: a decimal as a number, times as ISO-8601, the rest as text."""
    if isinstance(value, Decimal):
        return float(value)
    return value.isoformat() if hasattr(value, "isoformat") else str(value)


def flat_columns(frame: pl.DataFrame) -> pl.DataFrame:
    """``frame`` with every nested column (list, array, struct; CSV has no cells for them) as
    compact JSON text, e.g. ``[1,2]`` or ``{"a":1}``; null stays null."""
    nested = [c for c, dtype in frame.schema.items() if dtype.is_nested()]
    return frame.with_columns(
        pl.Series(c, [None if v is None else json.dumps(v, separators=(",", ":"), default=_jsonable) for v in frame[c].to_list()], dtype=pl.String)
        for c in nested
    )


def _broken_pipe() -> None:
    raise BrokenPipeError


def _print(frame: pl.DataFrame, fmt: str, max_rows: int, fh: IO | None) -> None:
    """Write ``frame`` in ``fmt`` to ``fh`` (standard output when None)."""
    if fmt == "parquet":
        frame.write_parquet(fh)
    elif fmt == "csv":
        (fh or sys.stdout).write(flat_columns(frame).write_csv())
    elif fmt == "json":
        (fh or sys.stdout).write(frame.write_json() + "\n")
    else:
        from rich.console import Console

        wide = fh is not None or not sys.stdout.isatty()
        console = Console(file=fh, width=250 if wide else None)
        console.on_broken_pipe = _broken_pipe  # rich's own exits 1; the command line decides (flows.cli.main)
        console.print(_table(frame, max_rows))
        note = f"{frame.height} row(s)" + (f", first {max_rows} shown" if frame.height > max_rows else "")
        console.print(f"[dim]{note}[/dim]")


def run_query(
    sql: str, warehouse: Path, *, fmt: str = "table", out: Path | None = None, live: bool = False, max_rows: int = 200, force: bool = False
) -> pl.DataFrame:
    """``valvemon query``: fetch and print (or write to ``out``, :func:`check_out`) the result in ``fmt``."""
    if fmt not in FORMATS:
        raise ValvemonError(f"--format: {fmt!r} is not one of {', '.join(FORMATS)}")
    if fmt == "parquet" and out is None:
        raise ValvemonError("--format parquet needs --out FILE")
    if max_rows < 0:
        raise ValvemonError(f"--max-rows: {max_rows} is negative; expected the number of rows to show (0 or more)")
    if out is not None:
        check_out(out, warehouse, force=force)
    frame = fetch(sql, warehouse, live=live)
    if out is None:
        _print(frame, fmt, max_rows, None)
    else:
        with _replacing(out, "wb" if fmt == "parquet" else "w") as fh:
            _print(frame, fmt, max_rows, fh)
    return frame

"""The BI hand-off: ``WAREHOUSE/export/``, Parquet files with a stable schema from the registry.

Layout::

    export/edge_fits/valve_id=<id>/date=<YYYY-MM-DD>/part-0.parquet   the valve's edge_fits rows of a UTC day
    export/edge_fits/_exported_through             the latest monitored_at exported
    export/valve_condition.parquet                  view valve_condition
    export/fleet_ranking.parquet                    view fleet_ranking

Each file's schema is built from the field registry (:func:`bi_schema`) (``schemas.fields.EDGE_FIT_FIELDS``,
``VALVE_CONDITION_FIELDS`` / ``FLEET_RANKING_FIELDS``): the same column
names, order and types on every export, timestamps ``timestamp[us, tz=UTC]``, each field's unit
and description in the Parquet field metadata. The partition key ``valve_id`` is also inside
the files, so a tool that ignores hive partitioning still sees it. Every file is written to a
hidden temporary name and renamed into place (a reader sees the old file or the new one, never
half of one); partitions of valves no longer in ``edge_fits`` are removed.

A night writes only the days that changed: the days of the rows monitored after
``_exported_through`` (written last, so a run killed halfway writes the same days again), each
day's partition whole. Without the marker (a first export, or one made before the days were
partitions) every day is written and the per-valve files of the old layout are removed.
"""

from __future__ import annotations

import os
import shutil
import uuid
from datetime import datetime, timedelta, timezone
from pathlib import Path

import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.fields import EDGE_FIT_FIELDS, FLEET_RANKING_FIELDS, VALVE_CONDITION_FIELDS, Field, arrow_schema, polars_schema

EXPORT_DIR = "export"
PART_NAME = "part-0.parquet"
EXPORTED_THROUGH = "_exported_through"
"""File in ``export/edge_fits/``: the latest ``edge_fits.monitored_at`` exported (ISO 8601)."""

EXPORTS: dict[str, tuple[str, tuple[Field, ...]]] = {
    "valve_condition": ("SELECT * FROM valve_condition ORDER BY valve_id, edge_order", VALVE_CONDITION_FIELDS),
    "fleet_ranking": ("SELECT * FROM fleet_ranking ORDER BY urgency_rank", FLEET_RANKING_FIELDS),
}
"""Single-file exports: name → (query against the views, fields)."""


def export_dir(warehouse: str | Path) -> Path:
    """``WAREHOUSE/export``."""
    return Path(warehouse) / EXPORT_DIR


def conform(frame: pl.DataFrame, fields: tuple[Field, ...]) -> pa.Table:
    """The frame as an Arrow table in exactly the registry's columns, order, types and metadata."""
    missing = [f.name for f in fields if f.name not in frame.columns]
    if missing:
        raise ValueError(f"export: columns missing from the query result: {', '.join(missing)}")
    table = frame.select([f.name for f in fields]).cast(dict(polars_schema(fields))).to_arrow()
    schema = bi_schema(fields)
    return pa.Table.from_arrays([table.column(f.name).cast(schema.field(f.name).type) for f in fields], schema=schema)


def _plain(t: pa.DataType) -> pa.DataType:
    if pa.types.is_large_string(t):
        return pa.string()
    if pa.types.is_large_list(t):
        return pa.list_(_plain(t.value_type))
    return t


def bi_schema(fields: tuple[Field, ...]) -> pa.Schema:
    """The registry's Arrow schema with plain ``string``/``list`` types instead of polars' large
    ones: what BI tools and pyarrow's hive partitioning (which infers ``string`` keys) expect."""
    schema = arrow_schema(fields)
    return pa.schema([pa.field(f.name, _plain(f.type), nullable=f.nullable, metadata=f.metadata) for f in schema])


def write_parquet_atomic(table: pa.Table, path: Path) -> None:
    """Write ``table`` to ``path`` via a temporary file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    try:
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def export_bi(con, warehouse: str | Path) -> dict[str, Path]:
    """Write the hand-off from an open (read-only) connection that has the tables and views.

    Returns
    -------
    dict
        ``edge_fits`` → its dataset folder, ``valve_condition`` and ``fleet_ranking`` → their files.
    """
    root = export_dir(warehouse)
    out: dict[str, Path] = {}
    fits_dir = root / "edge_fits"
    fits_dir.mkdir(parents=True, exist_ok=True)
    marker = fits_dir / EXPORTED_THROUGH
    since = datetime.fromisoformat(marker.read_text().strip()) if marker.is_file() else None
    if since is None:
        for old in fits_dir.glob(f"valve_id=*/{PART_NAME}"):  # the layout of one file per valve
            old.unlink()
    days = con.execute(
        "SELECT valve_id, cast(timezone('UTC', window_start) AS date) AS day, max(max(monitored_at)) OVER () "
        "FROM edge_fits WHERE monitored_at > coalesce(?::timestamptz, '-infinity'::timestamptz) GROUP BY ALL ORDER BY 1, 2",
        [since],
    ).fetchall()
    for vid, day, _ in days:
        lo = datetime(day.year, day.month, day.day, tzinfo=timezone.utc)
        rows = pl.from_arrow(con.sql(
            "SELECT * FROM edge_fits WHERE valve_id = ? AND window_start >= ? AND window_start < ? ORDER BY edge, window_start",
            params=[vid, lo, lo + timedelta(days=1)],
        ).to_arrow_table())  # fmt: skip
        path = fits_dir / f"valve_id={vid}" / f"date={day.isoformat()}" / PART_NAME
        if rows.height:
            write_parquet_atomic(conform(rows, EDGE_FIT_FIELDS), path)
        else:
            path.unlink(missing_ok=True)
    valves = {r[0] for r in con.execute("SELECT DISTINCT valve_id FROM edge_fits").fetchall()} if since is None or days else None
    for stale in fits_dir.glob("valve_id=*"):
        if valves is not None and stale.name.split("=", 1)[1] not in valves:
            shutil.rmtree(stale, ignore_errors=True)
    if days:
        tmp = fits_dir / f".{EXPORTED_THROUGH}.{uuid.uuid4().hex}.tmp"
        tmp.write_text(days[0][2].isoformat())
        os.replace(tmp, marker)
    out["edge_fits"] = fits_dir
    for name, (sql, fields) in EXPORTS.items():
        frame = pl.from_arrow(con.sql(sql).to_arrow_table())
        path = root / f"{name}.parquet"
        write_parquet_atomic(conform(frame, fields), path)
        out[name] = path
    return out

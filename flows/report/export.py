"""The BI hand-off: ``WAREHOUSE/export/``, Parquet files with a stable schema from the registry.

Layout::

    export/edge_fits/valve_id=<id>/part-0.parquet   every edge_fits row of the valve
    export/valve_condition.parquet                  view valve_condition
    export/fleet_ranking.parquet                    view fleet_ranking

Each file's schema is built from the field registry (:func:`bi_schema`) (``schemas.fields.EDGE_FIT_FIELDS``,
``VALVE_CONDITION_FIELDS`` / ``FLEET_RANKING_FIELDS``): the same column
names, order and types on every export, timestamps ``timestamp[us, tz=UTC]``, each field's unit
and description in the Parquet field metadata. The partition key ``valve_id`` is also inside
the files, so a tool that ignores hive partitioning still sees it. Every file is written to a
hidden temporary name and renamed into place (a reader sees the old file or the new one, never
half of one); partitions of valves no longer in ``edge_fits`` are removed.
"""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path

import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.fields import EDGE_FIT_FIELDS, FLEET_RANKING_FIELDS, VALVE_CONDITION_FIELDS, Field, arrow_schema, polars_schema

EXPORT_DIR = "export"
PART_NAME = "part-0.parquet"

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
    valves = [r[0] for r in con.execute("SELECT DISTINCT valve_id FROM edge_fits ORDER BY 1").fetchall()]
    for vid in valves:
        rows = pl.from_arrow(
            con.sql("SELECT * FROM edge_fits WHERE valve_id = ? ORDER BY edge, window_start", params=[vid]).to_arrow_table()
        )
        write_parquet_atomic(conform(rows, EDGE_FIT_FIELDS), fits_dir / f"valve_id={vid}" / PART_NAME)
    for stale in fits_dir.glob("valve_id=*"):
        if stale.name.split("=", 1)[1] not in valves:
            shutil.rmtree(stale, ignore_errors=True)
    out["edge_fits"] = fits_dir
    for name, (sql, fields) in EXPORTS.items():
        frame = pl.from_arrow(con.sql(sql).to_arrow_table())
        path = root / f"{name}.parquet"
        write_parquet_atomic(conform(frame, fields), path)
        out[name] = path
    return out

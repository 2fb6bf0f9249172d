"""The monitor's tables in the warehouse (``baselines``, ``edge_fits``, ``selection_stats``):
their fields, keys and creation, without the monitor's algorithms (the commands that only make
sure the tables exist — the publish after an ingest — import this alone)."""

from __future__ import annotations

from flows.common.warehouse_db import add_missing_columns, ensure_tables
from schemas.fields import BASELINE_FIELDS, EDGE_FIT_FIELDS, SELECTION_FIELDS

MONITOR_TABLES = {
    "baselines": (BASELINE_FIELDS, ("valve_id", "edge", "version")),
    "edge_fits": (EDGE_FIT_FIELDS, ("valve_id", "edge", "window_start")),
    "selection_stats": (SELECTION_FIELDS, ("valve_id", "edge", "window_start", "rule")),
}
"""Table → (fields, unique key)."""

INDEXED_TABLES = frozenset({"baselines"})
"""Tables whose key DuckDB enforces with a unique index. ``edge_fits`` and ``selection_stats``
keep theirs by construction instead: every write deletes the spans it replaces and inserts their
rows in one transaction (:func:`flows.monitor.flow.store_spans`). A unique (ART) index on them made each such write
about 4× as expensive (~45 against ~12 ms CPU for a valve-week)."""

def ensure_monitor_tables(con) -> None:
    """Create ``baselines``, ``edge_fits`` and ``selection_stats`` if missing, with a unique index
    on the :data:`INDEXED_TABLES` (one on the others, made by earlier versions, is dropped).
    Catalog queries first, so that a warehouse that has them costs no DDL. A table made by an
    earlier version gets the columns added since (after its own: ``leak_*``), NULL in old rows."""
    ensure_tables(con, {name: (fields, None) for name, (fields, _) in MONITOR_TABLES.items()})
    add_missing_columns(con, {name: fields for name, (fields, _) in MONITOR_TABLES.items()})
    indexes = {r[0] for r in con.execute(
        "SELECT index_name FROM duckdb_indexes() WHERE database_name = current_database()"
    ).fetchall()}  # fmt: skip
    for name, (_, key) in MONITOR_TABLES.items():
        if name in INDEXED_TABLES and f"{name}_key" not in indexes:
            con.execute(f"CREATE UNIQUE INDEX IF NOT EXISTS {name}_key ON {name} ({', '.join(key)})")
        if name not in INDEXED_TABLES and f"{name}_key" in indexes:
            con.execute(f"DROP INDEX {name}_key")

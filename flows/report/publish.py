"""Making what a command wrote queryable: condition bounds, the ``sql/`` views and the snapshot.

Every command that writes the warehouse (``ingest``, ``monitor``, ``backfill`` and the nightly
run, ``discrepancy``, ``report``) ends with :func:`publish`, so ``valvemon query`` sees its rows
(the ingest manifest and quarantine, the fits, the condition views) at once, without a
``valvemon report`` first. In one short write connection it

1. creates the tables the views read if they are missing (:func:`flows.report.views.ensure_report_tables`);
2. replaces table ``condition_bounds`` by the configuration's bounds (:func:`bounds_frame`), so
   ``valve_condition`` and ``fleet_ranking`` have a row per configured valve as soon as there
   are fits (the Eq. 9 standstill columns stay empty until ``valvemon report`` checks the lake);
3. creates or refreshes the views (:func:`flows.report.views.create_views`);
4. brings the daily summaries the condition views read up to the latest day
   (:func:`flows.report.summaries.update_summaries`);
5. publishes the read-only snapshot readers open (:func:`flows.report.views.publish_snapshot`:
   a byte copy of the checkpointed file, replaced atomically, so a reader never waits for the
   writer nor the writer for a reader).

The cost grows with the database, not with what the command did (``docs/warehouse.md``,
"Readers and the writer", has the figures).
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import polars as pl

from flows.common.config import load_plant_config
from flows.common.warehouse_db import connect, insert_frame, transaction
from flows.report.standstill import expected_residual
from flows.report.summaries import update_summaries
from flows.report.views import create_views, ensure_report_tables, publish_snapshot
from schemas.fields import CONDITION_BOUNDS_FIELDS, polars_schema
from schemas.plant_config import BOUND_KEYS, PlantConfig


def bounds_frame(config: PlantConfig, now: datetime) -> pl.DataFrame:
    """One ``condition_bounds`` row per configured valve."""
    cache: dict[tuple, float] = {}
    rows = []
    for v in config.valves:
        b = v.design.bounds
        row = {k: getattr(b, k) for k in BOUND_KEYS}
        if row["eq9_expected"] is None:
            key = (v.design, v.piston_diameter_m, v.rod_diameter_m)
            if key not in cache:
                cache[key] = expected_residual(v, config.export)
            row["eq9_expected"] = cache[key]
        row |= {"valve_id": v.id, "valve_type": v.type, "x_max_mm": v.design.x_max_m * 1e3, "updated_at": now}
        rows.append(row)
    return pl.DataFrame(rows, schema=polars_schema(CONDITION_BOUNDS_FIELDS))


def publish(config: PlantConfig | str | Path, warehouse: str | Path, now: datetime | None = None) -> tuple[list[str], Path]:
    """Bounds table, views and the published snapshot (module doc); returns the views and the snapshot's path."""
    if not isinstance(config, PlantConfig):
        config = load_plant_config(config)
    now = now or datetime.now(timezone.utc).replace(microsecond=0)
    bounds = bounds_frame(config, now)
    with connect(warehouse) as con:
        ensure_report_tables(con)
        with transaction(con):
            con.execute("DELETE FROM condition_bounds")
            insert_frame(con, "condition_bounds", bounds)
        views = create_views(con)
        update_summaries(con, now)
        snapshot = publish_snapshot(con, warehouse)
    return views, snapshot

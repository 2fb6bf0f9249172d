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

import json
import os
import uuid
from datetime import datetime, timezone
from functools import cache
from pathlib import Path

import polars as pl

from flows.common.config import load_plant_config
from flows.common.warehouse_db import connect, insert_frame, transaction
from flows.report.standstill import expected_residual
from flows.report.summaries import update_summaries
from flows.report.views import create_views, ensure_report_tables, publish_snapshot
from schemas.fields import CONDITION_BOUNDS_FIELDS, polars_schema
from schemas.plant_config import BOUND_KEYS, PlantConfig


RESIDUALS_FILE = ".eq9_expected.json"
"""The warehouse's record of the Eq. 9 residuals at rest already computed (:func:`residual_key`
→ value): each command that publishes would otherwise solve the rest state again (~0.6 CPU s,
most of it loading the model's compiled kernels)."""
RESIDUAL_CODE = ("model", "flows/simulate/archive.py", "flows/report/standstill.py")
"""The code the residual is computed by: a change to it computes the residuals again."""


@cache
def _code_digest() -> str:
    from blake3 import blake3  # noqa: PLC0415

    root, h = Path(__file__).resolve().parents[2], blake3()
    for name in RESIDUAL_CODE:
        for f in sorted((root / name).rglob("*.py")) if (root / name).is_dir() else [root / name]:
            h.update(f.read_bytes())
    return h.hexdigest()


def residual_key(valve, export) -> str:
    """What :func:`expected_residual` of ``valve`` is computed from: the valve's design, cylinder
    and fluid, the export's sample rate and the code (:data:`RESIDUAL_CODE`)."""
    from blake3 import blake3  # noqa: PLC0415

    inputs = (valve.design, valve.piston_diameter_m, valve.rod_diameter_m, valve.stroke_m, valve.v01_m3, valve.v02_m3,
              valve.bulk_modulus_pa, valve.density_kg_m3, export.sample_rate_hz)  # fmt: skip
    return blake3((repr(inputs) + _code_digest()).encode()).hexdigest()


def _stored_residuals(warehouse: Path | None) -> dict[str, float]:
    try:
        stored = json.loads((Path(warehouse) / RESIDUALS_FILE).read_text()) if warehouse is not None else {}
    except (OSError, ValueError):
        return {}
    return {k: v for k, v in stored.items() if isinstance(v, float)} if isinstance(stored, dict) else {}


def _store_residuals(warehouse: Path, residuals: dict[str, float]) -> None:
    path = Path(warehouse) / RESIDUALS_FILE
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    tmp.write_text(json.dumps(residuals))
    os.replace(tmp, path)


def bounds_frame(config: PlantConfig, now: datetime, warehouse: str | Path | None = None) -> pl.DataFrame:
    """One ``condition_bounds`` row per configured valve; a residual at rest the warehouse has
    recorded (:data:`RESIDUALS_FILE`) is taken from there."""
    cache: dict[tuple, float] = {}
    stored = _stored_residuals(warehouse)
    known = len(stored)
    rows = []
    for v in config.valves:
        b = v.design.bounds
        row = {k: getattr(b, k) for k in BOUND_KEYS}
        if row["eq9_expected"] is None:
            key = (v.design, v.piston_diameter_m, v.rod_diameter_m)
            if key not in cache:  # the first valve of a design computes it for all
                digest = residual_key(v, config.export)
                if digest not in stored:
                    stored[digest] = expected_residual(v, config.export)
                cache[key] = stored[digest]
            row["eq9_expected"] = cache[key]
        row |= {"valve_id": v.id, "valve_type": v.type, "x_max_mm": v.design.x_max_m * 1e3, "updated_at": now}
        rows.append(row)
    if warehouse is not None and len(stored) > known and Path(warehouse).is_dir():
        _store_residuals(warehouse, stored)
    return pl.DataFrame(rows, schema=polars_schema(CONDITION_BOUNDS_FIELDS))


def publish(config: PlantConfig | str | Path, warehouse: str | Path, now: datetime | None = None) -> tuple[list[str], Path]:
    """Bounds table, views and the published snapshot (module doc); returns the views and the snapshot's path."""
    if not isinstance(config, PlantConfig):
        config = load_plant_config(config)
    now = now or datetime.now(timezone.utc).replace(microsecond=0)
    bounds = bounds_frame(config, now, warehouse)
    with connect(warehouse) as con:
        ensure_report_tables(con)
        with transaction(con):
            con.execute("DELETE FROM condition_bounds")
            insert_frame(con, "condition_bounds", bounds)
        views = create_views(con)
        update_summaries(con, now)
        snapshot = publish_snapshot(con, warehouse)
    return views, snapshot

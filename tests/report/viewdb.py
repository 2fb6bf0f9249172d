"""A hand-built warehouse database for the view tests and the remaining-life study
(``bench/remaining_life_horizon.py``): an in-memory DuckDB with the registry's tables, the views
of ``sql/`` and helpers that write fits with known answers."""

from __future__ import annotations

import dataclasses
from datetime import datetime, timedelta, timezone

import duckdb
import numpy as np
import polars as pl

from flows.common.warehouse_db import create_table_sql, insert_frame, query_frame
from flows.report.views import REPORT_TABLES, create_views
from schemas.fields import BASELINE_FIELDS, CONDITION_BOUNDS_FIELDS, EDGE_FIT_FIELDS, EDGES, STANDSTILL_FIELDS, polars_schema
from schemas.plant_config import ConditionBounds

COMMISSIONED = datetime(2025, 1, 1, tzinfo=timezone.utc)


class Warehouse:
    """An in-memory warehouse database with the views created."""

    def __init__(self) -> None:
        self.con = duckdb.connect()
        self.con.execute("SET TimeZone = 'UTC'")
        self.con.execute(create_table_sql("edge_fits", EDGE_FIT_FIELDS))
        self.con.execute(create_table_sql("baselines", BASELINE_FIELDS))
        for name, fields in REPORT_TABLES.items():
            self.con.execute(create_table_sql(name, fields))
        create_views(self.con)

    def add_valve(self, valve_id: str, *, eq9_expected: float = -0.17, **bounds) -> None:
        b = dataclasses.replace(ConditionBounds(), **bounds)
        row = {f.name: None for f in CONDITION_BOUNDS_FIELDS}
        row |= {k: getattr(b, k) for k in row if hasattr(b, k)}
        row |= {"valve_id": valve_id, "valve_type": "servo_4w", "x_max_mm": 3.5, "eq9_expected": eq9_expected,
                "updated_at": COMMISSIONED}
        insert_frame(self.con, "condition_bounds", pl.DataFrame([row], schema=polars_schema(CONDITION_BOUNDS_FIELDS)))

    def add_fits(self, valve_id: str, edge: str, hours, alpha, x_pct, e, status="ok", baseline_version: int = 1,
                 x_determined=None, leak=None, leak_held=None, monitored_at: datetime = COMMISSIONED) -> None:
        hours = np.asarray(hours, float)
        n = hours.size
        col = lambda v: np.broadcast_to(np.asarray(v, float), (n,)).copy()  # noqa: E731
        start = [COMMISSIONED + timedelta(hours=float(h)) for h in hours]
        status = np.broadcast_to(np.asarray(status, object), (n,)).tolist()
        ok = np.array([s == "ok" for s in status])
        a, x, err = col(alpha), col(x_pct), col(e)
        frame = pl.DataFrame(
            {
                "valve_id": [valve_id] * n,
                "edge": [edge] * n,
                "window_start": start,
                "window_end": [t + timedelta(seconds=10) for t in start],
                "operating_hours": hours,
                "n_points": [3000 if s else 10 for s in ok],
                "alpha_hat": np.where(ok, a, np.nan),
                "x_hat_mm": np.where(ok, x * 3.5 / 100, np.nan),
                "x_hat_pct": np.where(ok, x, np.nan),
                "e_mm2": np.where(ok, err, np.nan),
                "status": status,
                "alpha_ci_low": None, "alpha_ci_high": None, "x_hat_ci_low_mm": None, "x_hat_ci_high_mm": None,
                "u_min_mm": None, "u_max_mm": None,
                "baseline_version": [baseline_version] * n,
                "monitored_at": [monitored_at] * n,
                "leak_scale": None if leak is None else np.where(ok, col(leak), np.nan), "leak_scale_ci_low": None, "leak_scale_ci_high": None,
                "u_spread_mm": None,
                "x_hat_determined": None if x_determined is None else np.broadcast_to(np.asarray(x_determined, bool), (n,)).tolist(),
                "leak_scale_held": None if leak_held is None else np.broadcast_to(np.asarray(leak_held, bool), (n,)).tolist(),
                "row_stride": [1] * n,
            },
            schema_overrides={k: v for k, v in polars_schema(EDGE_FIT_FIELDS).items()},
        ).cast(dict(polars_schema(EDGE_FIT_FIELDS)))
        insert_frame(self.con, "edge_fits", frame)

    def add_healthy_edges(self, valve_id: str, hours, seed: int = 0, skip: tuple[str, ...] = ()) -> None:
        """Normal scatter (Table 2's normal valve) on every edge not in ``skip``."""
        rng = np.random.default_rng(seed)
        hours = np.asarray(hours, float)
        for edge in EDGES:
            if edge in skip:
                continue
            self.add_fits(valve_id, edge, hours, 0.98 + 0.01 * rng.standard_normal(hours.size),
                          0.23 + 0.1 * rng.standard_normal(hours.size), 0.10 + 0.01 * rng.standard_normal(hours.size))

    def add_standstill(self, valve_id: str, hours, residual) -> None:
        hours = np.asarray(hours, float)
        n = hours.size
        start = [COMMISSIONED + timedelta(hours=float(h)) for h in hours]
        frame = pl.DataFrame(
            {
                "valve_id": [valve_id] * n, "window_start": start, "window_end": [t + timedelta(seconds=10) for t in start],
                "operating_hours": hours, "n_samples": [500] * n, "ps_bar": [200.0] * n, "pr_bar": [0.0] * n,
                "p1_bar": [33.0] * n, "p2_bar": [146.0] * n, "x_spool_mm": [-0.03] * n,
                "eq9_residual": np.broadcast_to(np.asarray(residual, float), (n,)).copy(), "computed_at": [COMMISSIONED] * n,
            },
            schema=polars_schema(STANDSTILL_FIELDS),
        )
        insert_frame(self.con, "standstill_checks", frame)

    def q(self, sql: str, params: list | None = None) -> pl.DataFrame:
        return query_frame(self.con, sql, params)

    def condition(self, valve_id: str, edge: str) -> dict:
        rows = self.q("SELECT * FROM valve_condition WHERE valve_id = ? AND edge = ?", [valve_id, edge]).to_dicts()
        assert len(rows) == 1, rows
        return rows[0]

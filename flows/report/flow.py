"""``valvemon report``: fits → decisions (step 5b), pictures and one HTML report.

:func:`run_report`

1. writes each configured valve's condition bounds (``[valve_types.NAME.bounds]``, with the
   Eq. 9 rest residual of its design) to table ``condition_bounds``;
2. brings table ``standstill_checks`` up to date from the lake (Eq. 9 per window,
   :mod:`flows.report.standstill`; only windows from the latest one already checked onwards are read)
   and records how far it has read in ``standstill_progress`` (retention waits for it);
3. creates or refreshes the ``sql/`` views (:mod:`flows.report.views`) and publishes the read-only
   snapshot ``WAREHOUSE/snapshot/valvemon.duckdb`` that readers query (:mod:`flows.report.publish`,
   which every writing command ends with);
4. computes the views it reads once each (``REPORT_VIEWS`` and what they read, into temporary
   tables of its read-only snapshot connection: :func:`flows.report.views.materialise_views`),
   reads them and writes the BI hand-off (:mod:`flows.report.export`), the PNG
   pictures (:mod:`flows.report.figures`, drawn in a pool of processes: :func:`render_figures`) and
   ``WAREHOUSE/reports/report.html`` (:mod:`flows.report.html`), which also shows the latest
   ``valvemon discrepancy`` run of every valve analysed (:func:`discrepancy_results`; its overlay pictures are the workflow's own)
   and the ingest's data quality (:mod:`flows.report.quality`);
5. records every edge's condition in ``condition_history`` and opens the report with what changed
   since the previous report (view ``condition_changes``), then sends the night's message and any
   an earlier run could not send (``[notify]``; :mod:`flows.notify.night`: a failed send is kept
   for the next run, never a failed report) and publishes the snapshot again with them.

Every write to ``valvemon.duckdb`` happens in a short-lived connection; the pictures and the
export are made from the snapshot, without holding the live database.

:func:`report_flow` is the Prefect flow the command line runs.
"""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import polars as pl

from flows.common.allocator import retain_freed_memory
from flows.common.batches import WriteBatch
from flows.common.config import load_plant_config, plant_valves
from flows.common.prefect_run import flow
from flows.common.warehouse_db import connect, insert_frame, query_frame, transaction
from flows.notify.night import Delivery, deliver_pending, record_run
from flows.report.export import export_bi
from flows.report.figures import characteristics_figure, fleet_figure, render_figures, trends_figure
from flows.report.html import render_report
from flows.report.publish import publish
from flows.report.quality import data_quality
from flows.report.views import connect_snapshot, ensure_report_tables, materialise_views
from model.area import edge_area
from schemas.fields import EDGES
from schemas.plant_config import PlantConfig
from transforms.standstill import STANDSTILL_COLUMNS, standstill_rows

REPORTS_DIR = "reports"
REPORT_NAME = "report.html"
DISCREPANCY_DIR = Path(REPORTS_DIR) / "discrepancy"
"""Where ``valvemon discrepancy`` writes its overlay pictures, inside the warehouse."""
DETAIL_VALVES = 20
"""Valves shown with pictures in the HTML report by default: the most urgent ones."""
REPORT_VIEWS = ("valve_condition", "fleet_ranking", "parameter_trends", "trend_daily")
"""The views the report reads, each computed once per run (:func:`flows.report.views.materialise_views`)."""
REPORT_MEMORY = "2GB"
"""DuckDB's memory limit for the report's queries; beyond it they spill to ``WAREHOUSE/.report_tmp``."""
U_GRID_POINTS = 281


@dataclass
class ReportResult:
    """What a report run produced."""

    html: Path
    snapshot: Path
    pngs: list[Path] = field(default_factory=list)
    exports: dict[str, Path] = field(default_factory=dict)
    views: list[str] = field(default_factory=list)
    standstill_rows: int = 0
    ranking: pl.DataFrame | None = None
    changes: pl.DataFrame | None = None
    """View ``condition_changes``: what changed since the previous report."""
    delivery: Delivery | None = None
    """The messages sent at the end of the run (``[notify]``)."""


def update_standstill(config: PlantConfig, warehouse: Path, now: datetime) -> int:
    """Add Eq. 9 rows for the lake's windows not yet checked (from each valve's latest on); the
    chunks' rows and progress are written together a few seconds' work at a time
    (:class:`flows.common.batches.WriteBatch`: one transaction, not one per chunk)."""
    from flows.monitor.flow import lake_chunks  # the monitor's gap-aligned chunks of the lake

    retain_freed_memory()  # each chunk's arrays reuse the last one's heap (flows/common/allocator.py)
    with connect(warehouse) as con:
        ensure_report_tables(con)
        last = dict(con.execute("SELECT valve_id, max(window_start) FROM standstill_checks GROUP BY 1").fetchall())
    added = 0
    checked: WriteBatch[tuple[str, datetime, datetime, pl.DataFrame]] = WriteBatch(lambda batch: store_standstill(warehouse, batch, now))
    for v in config.valves:
        start = last.get(v.id)
        window_s = config.monitor.window_s
        for rows in lake_chunks(warehouse, v.id, config.export.max_gap_s, start, None, columns=("valve_id", *STANDSTILL_COLUMNS), window_s=window_s):
            frame = standstill_rows(rows, max_gap_s=config.export.max_gap_s, commissioned=v.commissioned, computed_at=now, window_s=window_s)
            checked.add((v.id, rows["timestamp_utc"][0], rows["timestamp_utc"][-1], frame))
            added += frame.height
    checked.flush()
    return added


def store_standstill(warehouse: Path, chunks: list[tuple[str, datetime, datetime, pl.DataFrame]], now: datetime) -> None:
    """Replace each chunk's ``standstill_checks`` rows of (valve, first to last sample read) by
    its new rows and record the progress, in one transaction: a rerun replaces, never
    duplicates, and a crash leaves every chunk as before or complete."""
    with connect(warehouse) as con:
        with transaction(con):
            for valve_id, lo, hi, _ in chunks:
                con.execute("DELETE FROM standstill_checks WHERE valve_id = ? AND window_start BETWEEN ? AND ?", [valve_id, lo, hi])
                mark_standstill_progress(con, valve_id, hi, now)
            insert_frame(con, "standstill_checks", pl.concat([c[3] for c in chunks]))


def mark_standstill_progress(con, valve_id: str, checked_through: datetime, now: datetime) -> None:
    """Record that the standstill check has read the valve's lake up to ``checked_through``
    (table ``standstill_progress``; retention keeps a partition until it has)."""
    con.execute("DELETE FROM standstill_progress WHERE valve_id = ? AND checked_through <= ?", [valve_id, checked_through])
    con.execute(
        "INSERT INTO standstill_progress SELECT ?, ?, ? WHERE NOT EXISTS (SELECT 1 FROM standstill_progress WHERE valve_id = ?)",
        [valve_id, checked_through, now, valve_id],
    )


def _edge_curves(config: PlantConfig, valve_id: str, baselines: pl.DataFrame, latest: dict[str, dict]) -> dict[str, dict]:
    """Nominal, baseline and current characteristic of each edge on one u grid (mm, mm²)."""
    valve = config.valve(valve_id)
    d = valve.design
    x_max_mm = d.x_max_m * 1e3
    u_mm = np.linspace(-x_max_mm, x_max_mm, U_GRID_POINTS)
    out = {}
    for edge in EDGES:
        b = baselines.filter(pl.col("edge") == edge)
        if b.height == 0:
            continue
        knots = np.asarray(b["knots_u_mm"][0], float)
        values = np.asarray(b["values_mm2"][0], float)

        def base(u: np.ndarray) -> np.ndarray:  # piecewise linear, linear beyond the end knots
            y = np.interp(u, knots, values)
            lo_slope = (values[1] - values[0]) / (knots[1] - knots[0])
            hi_slope = (values[-1] - values[-2]) / (knots[-1] - knots[-2])
            y = np.where(u < knots[0], values[0] + lo_slope * (u - knots[0]), y)
            return np.maximum(np.where(u > knots[-1], values[-1] + hi_slope * (u - knots[-1]), y), 0.0)  # an area is never negative

        nominal = d.contraction_coefficient * edge_area(
            u_mm * 1e-3, d.underlap_m[EDGES.index(edge)], d.taper_angle_rad(edge), d.bore_radius_m, d.spool_radius_m
        ) * 1e6
        info = latest.get(edge) or {}
        current = None
        if info.get("alpha_hat") is not None and info.get("x_hat_pct") is not None:
            current = info["alpha_hat"] * base(u_mm + info["x_hat_pct"] / 100 * x_max_mm)
        out[edge] = {"u_mm": u_mm, "nominal_mm2": nominal, "baseline_mm2": base(u_mm), "current_mm2": current}
    return out


def discrepancy_results(con, warehouse: Path) -> dict[str, list[dict]]:
    """The findings of the latest ``valvemon discrepancy`` run of every valve analysed (none if
    the workflow never ran): valve id → its ``discrepancy_findings`` rows in rank order, each
    with ``png``, its overlay picture under ``WAREHOUSE/reports/discrepancy/`` (looked up by file
    name, so a moved warehouse still finds it; None if there is none)."""
    if not con.execute("SELECT count(*) FROM duckdb_tables() WHERE table_name = 'discrepancy_findings'").fetchall()[0][0]:
        return {}
    rows = query_frame(
        con,
        "SELECT * FROM discrepancy_findings QUALIFY run_id = arg_max(run_id, run_at) OVER (PARTITION BY valve_id) "
        "ORDER BY valve_id, rank",
    )
    out: dict[str, list[dict]] = {}
    for r in rows.iter_rows(named=True):
        png = warehouse / DISCREPANCY_DIR / Path(r["plot_path"]).name if r["plot_path"] else None
        out.setdefault(r["valve_id"], []).append(r | {"png": png if png and png.is_file() else None})
    return out


def _write_html(path: Path, text: str) -> None:
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def run_report(config_path: str | Path, warehouse: str | Path, *, detail: int = DETAIL_VALVES, valve_ids: list[str] | None = None) -> ReportResult:
    """The whole report (module docstring). ``detail`` most urgent valves (or ``valve_ids``) get pictures."""
    config = load_plant_config(config_path)
    warehouse = Path(warehouse)
    plant_valves(config, valve_ids, config_path)
    now = datetime.now(timezone.utc).replace(microsecond=0)
    n_standstill = update_standstill(config, warehouse, now)
    views, snapshot = publish(config, warehouse, now)
    out_dir = warehouse / REPORTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    con = connect_snapshot(warehouse)
    try:
        con.execute(f"SET memory_limit = '{REPORT_MEMORY}'")
        con.execute("SET temp_directory = ?", [str(warehouse / ".report_tmp")])
        materialise_views(con, REPORT_VIEWS)
        exports = export_bi(con, warehouse)
        ranking = query_frame(con, "SELECT * FROM fleet_ranking ORDER BY urgency_rank")
        conditions = query_frame(con, "SELECT * FROM valve_condition ORDER BY valve_id, edge_order")
        chosen = valve_ids or ranking["valve_id"].head(detail).to_list()
        chosen = [v for v in ranking["valve_id"].to_list() if v in set(chosen)]
        jobs = [(fleet_figure, (ranking, conditions, out_dir / "fleet_overview.png"))]
        # the chosen valves' rows, one query each: a point a day (trend_daily), the trend lines, the bounds, the leakage by day
        daily, lines, bounds, leak = (query_frame(con, sql, [chosen]) for sql in (
            "SELECT * FROM trend_daily WHERE list_contains(?, valve_id)",
            "SELECT * FROM parameter_trends WHERE list_contains(?, valve_id)",
            "SELECT * FROM stg_condition_bounds WHERE list_contains(?, valve_id)",
            "SELECT d.valve_id, d.edge, d.leak_operating_hours AS operating_hours, d.leak_scale_median AS median_leak_scale, "
            "d.leak_scale_min AS min_leak_scale, d.leak_scale_max AS max_leak_scale, c.leak_scale_baseline "
            "FROM edge_days d JOIN valve_condition c USING (valve_id, edge) WHERE list_contains(?, d.valve_id) AND d.leak_n > 0",
        ))  # fmt: skip
        for vid in chosen:
            cond = conditions.filter(pl.col("valve_id") == vid)
            latest = {r["edge"]: r for r in cond.iter_rows(named=True)}
            baselines = query_frame(
                con,
                "SELECT * FROM baselines WHERE valve_id = ? QUALIFY version = max(version) OVER (PARTITION BY edge)",
                [vid],
            )
            mine = [f.filter(pl.col("valve_id") == vid) for f in (daily, lines, bounds, leak)]
            jobs += [(characteristics_figure, (vid, _edge_curves(config, vid, baselines, latest), latest, out_dir / f"characteristics_{vid}.png")),
                     (trends_figure, (vid, *mine[:3], latest, out_dir / f"trends_{vid}.png", mine[3]))]  # fmt: skip
        discrepancy = discrepancy_results(con, warehouse)
        quality = data_quality(con)
    finally:
        con.close()
    pngs = render_figures(jobs)
    valve_pngs = {vid: [("Opening-area characteristics (nominal, baseline, current)", ch),
                        ("α̂, x̂ and e over operating hours with bounds and end of life", tr)]
                  for vid, ch, tr in zip(chosen, pngs[1::2], pngs[2::2])}  # fmt: skip
    html_path = out_dir / REPORT_NAME
    night = record_run(config, warehouse, conditions, now=now, kind="report", report=str(html_path.resolve()))
    _write_html(html_path, render_report(
        plant=config.name, generated_at=now, ranking=ranking, conditions=conditions,
        fleet_png=pngs[0], valve_pngs=valve_pngs, discrepancy=discrepancy, snapshot=snapshot, quality=quality,
        changes=night.changes, previous_run_at=night.previous_run_at,
    ))  # fmt: skip
    delivery = deliver_pending(config, warehouse, now)
    return ReportResult(html_path, snapshot, pngs, exports, views, n_standstill, ranking, night.changes, delivery)


@flow(name="valvemon-report", persist_result=False, validate_parameters=False)
def report_flow(config_path: str, warehouse: str, detail: int = DETAIL_VALVES, valve_ids: list[str] | None = None) -> ReportResult:
    """The Prefect flow behind ``valvemon report``."""
    return run_report(config_path, warehouse, detail=detail, valve_ids=valve_ids)

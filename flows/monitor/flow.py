"""``valvemon monitor``: sensor lake → opening-area points → α̂/x̂/e fits in DuckDB (steps 2–6).

For every valve of the plant, :func:`run_monitor`

1. builds its :class:`~transforms.params.MonitorParams` from the plant configuration;
2. makes sure a baseline characteristic Â exists per edge (table ``baselines``): the step-4a fit
   of the valve's commissioning window when the configuration names one
   (:func:`transforms.monitor.commissioning_baseline`: nominal-shaped, checked against the
   nominal Eq. 3 characteristic, step 5a), otherwise the nominal α_nominal·A(u) (paper
   Sec. 5.1). A baseline whose definition changed (other design data, another window, other
   method settings) is stored as a new version; an unchanged one is reused;
3. reads the lake in chunks (days, or spans of a day holding a continuous recording; each cut
   at a window boundary, so no window is split; windows are runs cut by the clock at the
   plant's ``[monitor] window_s``, :mod:`transforms.windows`), runs steps 2–4b
   (:func:`transforms.monitor.monitor`, with the closed-edge leakage correction that follows
   each window's own estimates, built from the nominal characteristic and the baseline's state
   α_b, x_b against it) and replaces the chunk's rows of ``edge_fits`` and ``selection_stats``
   in one transaction: a rerun replaces, never duplicates, and a run killed halfway leaves
   every chunk either as before or complete.

docs/monitoring.md describes the algorithm, its defaults and its measured accuracy.

:func:`monitor_flow` is the Prefect flow the command line runs (one task per valve).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone
from pathlib import Path
from typing import Callable, Iterator

import duckdb
import numpy as np
import polars as pl
import pyarrow.parquet as pq

from flows.common.allocator import retain_freed_memory
from flows.common.batches import WriteBatch
from flows.common.config import load_plant_config, plant_valves
from flows.common.errors import ValvemonError
from flows.common.instants import utc_instant
from flows.common.lake import SENSOR_POLARS_SCHEMA, grid_rows_before, grid_series, UNKNOWN_SPAN_US, list_partitions, read_lake, row_group_spans, time_grid
from flows.common.prefect_run import flow, task
from flows.common.warehouse_db import connect, insert_frame, query_frame, transaction
from flows.monitor.tables import INDEXED_TABLES, MONITOR_TABLES, ensure_monitor_tables  # noqa: F401 - the monitor's tables, also for the callers of this module
from model.area import edge_area
from schemas.fields import BASELINE_FIELDS, EDGE_FIT_FIELDS, EDGES, SELECTION_FIELDS, polars_schema
from schemas.plant_config import PlantConfig, ValveSpec
from transforms.characteristic import Characteristic, scaled_shifted
from transforms.leakage import closed_leakage
from transforms.monitor import LAKE_COLUMNS, MonitorResult, commissioning_baseline, monitor
from transforms.params import MonitorParams
from transforms.windows import LONG_RUN_FRACTION, window_starts

LEAK_Z95 = 1.959963984540054
"""Normal 97.5 % quantile: the baselines' 95 % interval of ``leak_scale`` (a pooled commissioning
fit of thousands of block means)."""

CHUNK_DAYS = 7
"""Days of lake read at once per valve: a week of hourly 10 s windows at 1 kHz is 1.7 M rows."""

NOMINAL_GRID_STEP_M = 0.05e-3
"""Knot spacing of the nominal characteristic; Eq. 3 is nearly linear on this scale (the
piecewise-linear interpolation error is below 0.01 mm² on the open branch)."""


def monitor_params(valve: ValveSpec, sample_rate_hz: float, window_s: float | None = None, window_rows: int | None = None) -> MonitorParams:
    """The algorithm's view of one valve: design data from the configuration, default settings,
    the plant's window length (``[monitor] window_s``; None: a window is a whole run) and rows
    evaluated per window (``[monitor] window_rows``; None or 0: every row)."""
    return MonitorParams.from_design(
        piston_diameter_m=valve.piston_diameter_m,
        rod_diameter_m=valve.rod_diameter_m,
        v01_m3=valve.v01_m3,
        v02_m3=valve.v02_m3,
        bulk_modulus_pa=valve.bulk_modulus_pa,
        density_kg_m3=valve.density_kg_m3,
        underlap_m=valve.design.underlap_m,
        x_max_m=valve.design.x_max_m,
        sample_period_s=1.0 / sample_rate_hz,
        window_s=window_s,
        window_rows=window_rows or None,
    )


def plant_monitor_params(config: PlantConfig, valve: ValveSpec) -> MonitorParams:
    """:func:`monitor_params` with the plant's sample rate and ``[monitor]`` settings: what every
    monitoring path (the command, the backfill) fits a valve's windows with."""
    return monitor_params(valve, config.export.sample_rate_hz, config.monitor.window_s, config.monitor.window_rows)


def nominal_characteristic(valve: ValveSpec, edge: str, x_hat_bound_m: float, area_law: str = "eq3") -> Characteristic:
    """α_nominal · A(u) of Eq. 3 (or of another edge law, ``model.area``) for one edge, sampled
    over [−x_max, x_max + x̂ bound]."""
    d = valve.design
    u = np.arange(-d.x_max_m, d.x_max_m + x_hat_bound_m + NOMINAL_GRID_STEP_M / 2, NOMINAL_GRID_STEP_M)
    area = edge_area(u, d.underlap_m[EDGES.index(edge)], d.taper_angle_rad(edge), d.bore_radius_m, d.spool_radius_m,
                     area_law=area_law)  # fmt: skip
    return Characteristic.from_arrays(u, d.contraction_coefficient * area)


OTHER_EDGE_LAWS = ("sharp",)
"""The edge laws besides Eq. 3 that step 4a may recognise from a commissioning window (the
linear-gradient edge is one of them: straight, like the sharp-edged law)."""


def _design_definition(valve: ValveSpec) -> dict:
    d = valve.design
    return {
        "x_max_m": d.x_max_m, "bore_radius_m": d.bore_radius_m, "spool_radius_m": d.spool_radius_m,
        "taper_angle_port1_rad": d.taper_angle_port1_rad, "taper_angle_port2_rad": d.taper_angle_port2_rad,
        "underlap_m": list(d.underlap_m), "contraction_coefficient": d.contraction_coefficient,
        "piston_diameter_m": valve.piston_diameter_m, "rod_diameter_m": valve.rod_diameter_m,
        "v01_m3": valve.v01_m3, "v02_m3": valve.v02_m3, "bulk_modulus_pa": valve.bulk_modulus_pa,
        "density_kg_m3": valve.density_kg_m3, "area_law": d.area_law,
    }  # fmt: skip


BASELINE_METHOD = ("carrier-shaped step 4a, closed-edge leakage identified (λ₁ branch + λ₂ worn-lands branch, block means), "
                   "carrier of the edge law the commissioning window shows")
"""How baselines are built now (part of their definition: a change of method makes new versions)."""


def _method_settings() -> dict:
    """The algorithm's settings (:class:`MonitorParams` defaults without the design data, which
    :func:`monitor_params` takes from the configuration, the sample period, the window length and
    the rows a window evaluates, which a baseline does not depend on: :func:`transforms.monitor.commissioning_baseline`)."""
    design = {"piston_area_m2", "annulus_area_m2", "v01_m3", "v02_m3", "bulk_modulus_pa", "density_kg_m3", "underlap_m", "x_max_m", "sample_period_s",
              "window_s", "window_rows"}  # fmt: skip
    return {f.name: f.default for f in dataclasses.fields(MonitorParams) if f.name not in design}


def baseline_definition(valve: ValveSpec) -> str:
    """What a valve's baseline is built from (design data, commissioning window, the method and
    the algorithm's settings); when it changes, a new baseline version is made."""
    d: dict = {"design": _design_definition(valve), "method": BASELINE_METHOD, "settings": _method_settings()}
    if valve.baseline_window is not None:
        d["window"] = [t.isoformat() for t in valve.baseline_window]
    return json.dumps(d, sort_keys=True)


@dataclass(frozen=True)
class Baseline:
    """The characteristic a valve's edge is fitted against, with its stored version."""

    characteristic: Characteristic
    version: int
    source: str
    plausible: bool
    reasons: str
    leakage: Characteristic | None = None
    """α·A of the edge over the whole stroke at the baseline state (what the other edge of its
    port sees leaking): the nominal characteristic scaled and shifted by the stored
    ``alpha_vs_nominal``, ``x_vs_nominal_mm``, its closed branch that of the identified leakage
    ``leak_branch_scale``, ``leak_gap_scale`` (:meth:`from_row`,
    :func:`transforms.leakage.closed_leakage`)."""
    leak_scale: float = 1.0
    """The identified leakage over Eq. 3's 1 mm inside the edge (``baselines.leak_scale``)."""
    leak_reference: Characteristic | None = None
    """Eq. 3's α·A at the baseline state (the unit of the windows' ``leak_scale``)."""
    edge_law_note: str = ""
    """Why the baseline's edge law is not the configured one (``baselines.edge_law_note``)."""

    @classmethod
    def from_row(cls, valve: ValveSpec, params: MonitorParams, row: dict) -> Baseline:
        """From a row of table ``baselines`` (as a dict); a row without the leakage columns (an
        older version) leaks as Eq. 3."""
        a, x_mm = row.get("alpha_vs_nominal"), row.get("x_vs_nominal_mm")
        if a is None or x_mm is None or not (np.isfinite(a) and np.isfinite(x_mm) and a > 0):
            a, x_mm = 1.0, 0.0  # no state against the nominal: leak as designed
        lam = (row.get("leak_branch_scale"), row.get("leak_gap_scale"))
        if any(v is None or not np.isfinite(v) for v in lam):
            lam = (1.0, 0.0)
        eff = row.get("leak_scale")
        state = scaled_shifted(nominal_characteristic(valve, row["edge"], params.x_hat_bound_m), a, x_mm * 1e-3)
        return cls(
            Characteristic.from_arrays(np.array(row["knots_u_mm"]) * 1e-3, np.array(row["values_mm2"]) * 1e-6),
            row["version"], row["source"], row["plausible"], row["plausibility_reasons"],
            closed_leakage(state, -params.underlap(row["edge"]) - x_mm * 1e-3, lam),
            1.0 if eff is None or not np.isfinite(eff) else float(eff), state, row.get("edge_law_note") or "",
        )  # fmt: skip


def _baseline_rows(valve: ValveSpec, params: MonitorParams, warehouse: Path, versions: dict[str, int]) -> pl.DataFrame:
    """New baseline rows for all edges of a valve (step 4a + 5a, or the nominal characteristic)."""
    nominal = {e: nominal_characteristic(valve, e, params.x_hat_bound_m) for e in EDGES}
    now = datetime.now(timezone.utc)
    definition = baseline_definition(valve)
    rows = []
    if valve.baseline_window is None:
        for e in EDGES:
            c = nominal[e]
            rows.append((e, "nominal", c, 0, True, "", 1.0, 0.0, (1.0, 0.0), 1.0, float("nan"), "eq3", ""))
    else:
        start, end = valve.baseline_window
        lake = read_lake(warehouse, [valve.id], start, end).collect()
        if lake.height == 0:
            raise ValvemonError(
                f"valve {valve.id}: its baseline_window {start.isoformat()} – {end.isoformat()} holds no lake data; "
                "ingest the commissioning exports first or remove baseline_window to use the nominal characteristic"
            )
        laws = {law: {e: nominal_characteristic(valve, e, params.x_hat_bound_m, law) for e in EDGES} for law in OTHER_EDGE_LAWS}
        fitted = commissioning_baseline(lake, params, nominal, law=valve.design.area_law, laws=laws)
        for e in EDGES:
            b = fitted[e]
            if b.characteristic is None:
                raise ValvemonError(
                    f"valve {valve.id}, edge {e}: the baseline_window yields {b.n_points} opening-area points"
                    + (f" over {(b.u_range_m[1] - b.u_range_m[0]) * 1e3:.3f} mm of spool travel" if b.n_points else "")
                    + f", at least {params.min_points} points over {params.min_knot_spacing_m * 1e3:g} mm are needed"
                    " for the initial characteristic (step 4a)"
                )
            check = b.plausibility
            rows.append((e, "commissioning", b.characteristic, b.n_points, check.ok, "; ".join(check.reasons), b.alpha_vs_nominal,
                         b.x_vs_nominal_m, b.leak_coefficients, b.leak_scale, b.leak_scale_se, b.edge_law, b.edge_law_note))  # fmt: skip
    return pl.DataFrame(
        {
            "valve_id": [valve.id] * len(rows),
            "edge": [r[0] for r in rows],
            "version": [versions.get(r[0], 0) + 1 for r in rows],
            "source": [r[1] for r in rows],
            "definition": [definition] * len(rows),
            "knots_u_mm": [(r[2].knots_u_m * 1e3).tolist() for r in rows],
            "values_mm2": [(r[2].values_m2 * 1e6).tolist() for r in rows],
            "n_points": [r[3] for r in rows],
            "plausible": [r[4] for r in rows],
            "plausibility_reasons": [r[5] for r in rows],
            "alpha_vs_nominal": [r[6] for r in rows],
            "x_vs_nominal_mm": [r[7] * 1e3 for r in rows],
            "created_at": [now] * len(rows),
            "leak_branch_scale": [r[8][0] for r in rows],
            "leak_gap_scale": [r[8][1] for r in rows],
            "leak_scale": [r[9] for r in rows],
            "leak_scale_ci_low": [max(r[9] - LEAK_Z95 * r[10], 0.0) if np.isfinite(r[10]) else None for r in rows],
            "leak_scale_ci_high": [r[9] + LEAK_Z95 * r[10] if np.isfinite(r[10]) else None for r in rows],
            "edge_law": [r[11] for r in rows],
            "edge_law_note": [r[12] for r in rows],
        },
        schema=polars_schema(BASELINE_FIELDS),
    )


def _latest_baselines(con, valve_id: str) -> pl.DataFrame:
    return query_frame(
        con,
        "SELECT * FROM baselines WHERE valve_id = ? QUALIFY version = max(version) OVER (PARTITION BY edge)",
        [valve_id],
    )


def ensure_baselines(valve: ValveSpec, params: MonitorParams, warehouse: Path) -> dict[str, Baseline]:
    """The valve's current baseline per edge, made and stored first if missing or outdated."""
    with connect(warehouse) as con:
        ensure_monitor_tables(con)
        latest = _latest_baselines(con, valve.id)
    definition = baseline_definition(valve)
    current = latest.filter(pl.col("definition") == definition)
    if current.height < len(EDGES):
        versions = dict(zip(latest["edge"].to_list(), latest["version"].to_list()))
        current = _baseline_rows(valve, params, warehouse, versions)
        with connect(warehouse) as con:
            ensure_monitor_tables(con)
            insert_frame(con, "baselines", current)
    return {r["edge"]: Baseline.from_row(valve, params, r) for r in current.iter_rows(named=True)}


def monitor_rows(valve: ValveSpec, params: MonitorParams, baselines: dict[str, Baseline], rows: pl.DataFrame) -> MonitorResult:
    """Steps 2–4b on some of the valve's lake rows against its baselines, with the closed-edge
    leakage correction the baselines were built with (what every monitoring path must call).
    The result carries no points frame (the flows store fits and counts only). The process keeps
    freed memory for the next chunk's arrays (:func:`flows.common.allocator.retain_freed_memory`)."""
    retain_freed_memory()
    chars = {valve.id: {e: b.characteristic for e, b in baselines.items()}}
    leaks = {e: b.leakage for e, b in baselines.items()}
    if any(v is None for v in leaks.values()):
        leaks = {e: scaled_shifted(nominal_characteristic(valve, e, params.x_hat_bound_m), 1.0, 0.0) if v is None else v
                 for e, v in leaks.items()}  # fmt: skip
    scales = {valve.id: {e: b.leak_scale for e, b in baselines.items()}}
    refs = {valve.id: {e: b.leak_reference if b.leak_reference is not None else leaks[e] for e, b in baselines.items()}}
    return monitor(rows, params, chars, leakage={valve.id: leaks}, leak_scale=scales, leak_reference=refs, points=False)


def lake_chunks(
    warehouse: Path, valve_id: str, gap_s: float, start: datetime | None, end: datetime | None, days: int | None = None,
    columns: tuple[str, ...] | None = None, window_s: float | None = None,
) -> Iterator[pl.DataFrame]:
    """The valve's lake rows in chunks (:func:`_read_spans`: up to ``days`` days, default
    :data:`CHUNK_DAYS`, and about :data:`CHUNK_ROWS` rows), each chunk ending at a window
    boundary: the window that reaches the end of a chunk is carried into the next, so no window
    is ever split. Windows are those of :func:`transforms.windows.window_starts` with the gap
    limit ``gap_s`` and the length ``window_s`` (None: whole runs).

    With ``start``/``end`` the chunks hold the windows that *start* in [start, end), whole: a
    window that began before ``start`` is left out (it belongs to an earlier span), one that
    starts before ``end`` is read to its end. So the lake is read from two gap limits (and, with
    a length, half a length: enough to tell whether the run at ``start`` is cut by the clock)
    before ``start`` to a time by which the window running at ``end`` has ended (the next gap,
    :func:`_run_end`; with a length, one length and two gap limits after ``end``).

    ``columns``: read only these (``timestamp_utc`` always; ``valve_id`` is then filled in
    rather than decoded from the files)."""
    if start is None and end is None:
        yield from span_chunks(warehouse, valve_id, gap_s, None, None, days, columns, window_s)
        return
    length = timedelta(seconds=window_s) if window_s is not None else None
    back = timedelta(seconds=2 * gap_s) + (length * LONG_RUN_FRACTION if length else timedelta(0))
    read_lo = start - back if start is not None else None
    if end is None:
        read_hi = None
    elif length is not None:
        read_hi = end + length + timedelta(seconds=2 * gap_s)
    else:
        read_hi = _run_end(warehouse, valve_id, gap_s, end)
    lo_us = None if start is None else _epoch_us(start)
    hi_us = None if end is None else _epoch_us(end)
    for rows in span_chunks(warehouse, valve_id, gap_s, read_lo, read_hi, days, columns, window_s):
        # the windows starting in [start, end) are one contiguous slice of the time-sorted rows
        if rows.height == 0:
            continue
        ts = rows["timestamp_utc"].to_physical().to_numpy()
        starts = window_starts(ts, gap_s * 1e6, window_s)
        first = 0 if lo_us is None else int(np.searchsorted(ts[starts], lo_us, side="left"))
        last = len(starts) if hi_us is None else int(np.searchsorted(ts[starts], hi_us, side="left"))
        if first < last:
            a = int(starts[first])
            b = int(starts[last]) if last < len(starts) else rows.height
            yield rows.slice(a, b - a)


_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)

RUN_LOOKAHEAD = timedelta(hours=1)
"""How far beyond a span's end :func:`_run_end` looks for a gap at a time."""


def _run_end(warehouse: Path, valve_id: str, gap_s: float, end: datetime) -> datetime:
    """A time by which the window running at ``end`` (if any) has ended: the end of the first
    :data:`RUN_LOOKAHEAD` after ``end`` that holds a gap or the end of the data (only
    timestamps are read)."""
    gap = timedelta(seconds=gap_s)
    lo = end
    while True:
        hi = lo + RUN_LOOKAHEAD
        t = read_lake(warehouse, [valve_id], lo - gap, hi).select("timestamp_utc").collect()["timestamp_utc"]
        if t.len() == 0:
            return lo
        # (read from ``lo − gap``: a gap found here lies after the last sample before ``lo``)
        if t[-1] < hi - gap or bool((t.diff().dt.total_microseconds() > gap_s * 1e6).any()):
            return hi
        lo = hi


def _last_window(t: pl.Series, gap_s: float, window_s: float | None = None) -> int:
    """Index of the first sample of the last window in ``t`` (0: one window), looked for from
    the end (a tail of 64 k samples, then four times as much, …): a chunk's last window is short.
    (A tail whose run looks short may miss a clock cut of the longer run it belongs to, so it is
    widened until it shows a window start after its first sample.)"""
    n = t.len()
    ts = t.to_physical()
    k = min(n, 1 << 16)
    while True:
        starts = window_starts(ts.slice(n - k, k).to_numpy(), gap_s * 1e6, window_s)
        if starts.size > 1:
            return n - k + int(starts[-1])
        if k == n:
            return 0
        k = min(n, 4 * k)


CHUNK_ROWS = 2_000_000
"""About the most lake rows :func:`lake_chunks` reads at once per valve (besides the window it
carries over): days are read together up to this many rows (a week of hourly 10 s snapshots at
1 kHz is 1.7 M); a day holding more (a continuous recording) in spans of :data:`CHUNK_SPAN_S`."""

CHUNK_SPAN_S = 3600.0
"""Span of one read on a day with more than :data:`CHUNK_ROWS` rows: an hour, 3.6 M rows of a
1 kHz recording (rounded down to whole windows, at least one), the lake's hour file of a
continuous recording, decoded once and without a row filter; half-hour spans decoded the row
groups at their borders twice and filtered every column. [s]"""


@dataclass(frozen=True)
class _LakeFile:
    """A lake file of the valve, with what its footer says (no data decoded)."""

    path: Path
    day: date
    rows: int
    first: datetime | None
    last: datetime | None
    """First and last time stamp from the row groups' statistics (None: not recorded)."""
    grid: list | None = None
    """Its time grid record, checked against the footer (:func:`flows.common.lake.time_grid`;
    None: the time column must be decoded)."""


def _lake_files(warehouse: Path, valve_id: str, start: datetime | None, end: datetime | None) -> list[_LakeFile]:
    """The valve's lake files of the days [start, end) can touch, in time order, with their
    footers' row counts, time ranges and time grid records."""
    out = []
    for _, day, path in list_partitions(warehouse, [valve_id], start, end):
        # the statistics as integers: pyarrow's datetimes of them import pandas (~0.35 CPU-s)
        md = pq.ParquetFile(path).metadata
        groups = row_group_spans(md)
        first, last = min((g[1] for g in groups), default=None), max((g[2] for g in groups), default=None)
        known = first is not None and first != UNKNOWN_SPAN_US[0]  # (a group without statistics spans all time)
        out.append(_LakeFile(path, day, sum(g[0] for g in groups), _EPOCH + timedelta(microseconds=first) if known else None,
                             _EPOCH + timedelta(microseconds=last) if known else None, time_grid(md, path) if known else None))  # fmt: skip
    return out


def _day_extent(warehouse: Path, valve_id: str, day: date, files: list[_LakeFile]) -> tuple[datetime, datetime]:
    """First and last time stamp of a valve's lake day: from the files' footers, else from the
    time column."""
    if all(f.first is not None for f in files):
        return min(f.first for f in files), max(f.last for f in files)
    lo = datetime.combine(day, datetime.min.time(), timezone.utc)
    t = pl.col("timestamp_utc")
    return read_lake(warehouse, [valve_id], lo, lo + timedelta(days=1)).select(t.min().alias("a"), t.max().alias("b")).collect().row(0)


def _read_span(files: list[_LakeFile], lo: datetime, hi: datetime, columns: list[str]) -> pl.DataFrame | None:
    """The ``columns`` of the rows of ``files`` in [lo, hi), file by file: only the files whose
    footers overlap the span are read. A file with a time grid record (:class:`_LakeFile`
    ``grid``) gets its time column from the record and its rows in the span as one slice
    (:func:`_grid_rows`); any other is decoded, with a time filter only where it reaches beyond
    the span (a row filter copies every column). None: no file overlaps."""
    chosen = [f for f in files if f.first is None or (f.first < hi and f.last >= lo)]
    if not chosen:
        return None
    frames = []
    for f in chosen:
        if f.grid is not None:
            frames.append(_grid_rows(f, lo, hi, columns))
            continue
        lf = pl.scan_parquet(f.path, hive_partitioning=False, schema=SENSOR_POLARS_SCHEMA)
        if f.first is None or f.first < lo:
            lf = lf.filter(pl.col("timestamp_utc") >= lo)
        if f.first is None or f.last >= hi:
            lf = lf.filter(pl.col("timestamp_utc") < hi)
        frames.append(lf.select(columns).collect())
    return frames[0] if len(frames) == 1 else pl.concat(frames, rechunk=False)


def _grid_rows(f: _LakeFile, lo: datetime, hi: datetime, columns: list[str]) -> pl.DataFrame:
    """The ``columns`` of a lake file with a time grid record, its rows in [lo, hi): the rows
    in the span found on the record and read as one slice (polars decodes only the pages it
    covers), the time stamps built from the record in the other columns' chunks (never decoded)."""
    a, b = grid_rows_before(f.grid, _epoch_us(lo)), grid_rows_before(f.grid, _epoch_us(hi))
    read = [c for c in columns if c != "timestamp_utc"]
    if not read:
        return grid_series(f.grid, a, b).to_frame()
    lf = pl.scan_parquet(f.path, hive_partitioning=False, schema=SENSOR_POLARS_SCHEMA).select(read)
    frame = (lf if (a, b) == (0, f.rows) else lf.slice(a, b - a)).collect()
    lengths = [c.len() for c in frame.get_column(read[0]).get_chunks()]
    return frame.with_columns(grid_series(f.grid, a, b, lengths)).select(columns)


def _epoch_us(t: datetime) -> int:
    return (t - _EPOCH) // timedelta(microseconds=1)


def _read_spans(
    warehouse: Path, valve_id: str, files: list[_LakeFile], start: datetime | None, end: datetime | None, days: int, window_s: float | None,
) -> Iterator[tuple[datetime, datetime]]:
    """The [lo, hi) spans :func:`span_chunks` reads one at a time: whole days, up to ``days`` of
    them holding at most :data:`CHUNK_ROWS` rows together (counted from the files' metadata); a
    day holding more in spans of :data:`CHUNK_SPAN_S` (whole windows of ``window_s``) over its
    first to its last sample."""
    step = timedelta(seconds=CHUNK_SPAN_S)
    if window_s is not None:
        step = timedelta(seconds=window_s) * max(1, int(CHUNK_SPAN_S // window_s))
    group: list[date] = []
    rows = 0

    def flush() -> Iterator[tuple[datetime, datetime]]:
        if group:
            lo = datetime.combine(group[0], datetime.min.time(), timezone.utc)
            yield lo, datetime.combine(group[-1] + timedelta(days=1), datetime.min.time(), timezone.utc)

    for day in sorted({f.day for f in files}):
        day_files = [f for f in files if f.day == day]
        n = sum(f.rows for f in day_files)
        if n > CHUNK_ROWS:
            first, last = _day_extent(warehouse, valve_id, day, day_files)
            yield from flush()
            group, rows = [], 0
            midnight = datetime.combine(day, datetime.min.time(), timezone.utc)
            lo = midnight + step * ((first - midnight) // step)
            while lo <= last:
                hi = min(lo + step, midnight + timedelta(days=1))
                if (start is None or hi > start) and (end is None or lo < end):
                    yield lo, hi
                lo += step
            continue
        if len(group) >= days or (group and rows + n > CHUNK_ROWS):
            yield from flush()
            group, rows = [], 0
        group.append(day)
        rows += n
    yield from flush()


def span_chunks(
    warehouse: Path, valve_id: str, gap_s: float, start: datetime | None, end: datetime | None, days: int | None,
    columns: tuple[str, ...] | None, window_s: float | None = None,
) -> Iterator[pl.DataFrame]:
    """:func:`lake_chunks` for rows in [start, end) (windows cut at the bounds): the rows
    ``read_lake(warehouse, [valve_id], start, end)`` holds, in chunks of whole windows."""
    select = None
    read = SENSOR_POLARS_SCHEMA.names()
    if columns is not None:
        names = list(dict.fromkeys(["timestamp_utc", *columns]))
        read = [c for c in names if c != "valve_id"]
        select = [pl.lit(valve_id, dtype=pl.Utf8).alias("valve_id") if c == "valve_id" else pl.col(c) for c in names]
    days = CHUNK_DAYS if days is None else int(days)
    if days < 1:
        raise ValueError(f"chunk days must be >= 1, got {days}")
    files = _lake_files(warehouse, valve_id, start, end)
    spans = list(_read_spans(warehouse, valve_id, files, start, end, days, window_s))
    carry = None
    for i, (lo, hi) in enumerate(spans):
        rows = _read_span(files, max(lo, start) if start else lo, min(hi, end) if end else hi, read)
        if rows is None:
            rows = pl.DataFrame(schema={c: SENSOR_POLARS_SCHEMA[c] for c in read})
        # valve_id filled in after the decode: in the query polars cuts the columns into ~100 k-row
        # chunks, after it they stay the row groups' (fewer chunks for the monitor to read across)
        if select is not None:
            rows = rows.select(select)
        if carry is not None:
            rows = pl.concat([carry, rows])
        if rows.height == 0:
            carry = None
            continue
        if i == len(spans) - 1:
            yield rows
            return
        cut = _last_window(rows["timestamp_utc"], gap_s, window_s)
        if cut == 0:
            carry = rows  # one window reaching over the whole chunk: keep collecting
            continue
        carry = rows.slice(cut)
        yield rows.slice(0, cut)
    if carry is not None and carry.height:
        yield carry


def _fits_table(fits: pl.DataFrame, valve: ValveSpec, baselines: dict[str, Baseline], now: datetime) -> pl.DataFrame:
    x_max_mm = valve.design.x_max_m * 1e3
    commissioned = valve.commissioned
    version = {e: b.version for e, b in baselines.items()}
    return fits.select(
        "valve_id",
        "edge",
        "window_start",
        "window_end",
        ((pl.col("window_start") - pl.lit(commissioned)).dt.total_microseconds() / 3.6e9).alias("operating_hours"),
        pl.col("n_points").cast(pl.Int32),
        "alpha_hat",
        (pl.col("x_hat_m") * 1e3).alias("x_hat_mm"),
        (pl.col("x_hat_m") * 1e3 / x_max_mm * 100).alias("x_hat_pct"),
        (pl.col("e_m2") * 1e6).alias("e_mm2"),
        "status",
        "alpha_ci_low",
        "alpha_ci_high",
        (pl.col("x_hat_ci_low_m") * 1e3).alias("x_hat_ci_low_mm"),
        (pl.col("x_hat_ci_high_m") * 1e3).alias("x_hat_ci_high_mm"),
        (pl.col("u_min_m") * 1e3).alias("u_min_mm"),
        (pl.col("u_max_m") * 1e3).alias("u_max_mm"),
        pl.col("edge").replace_strict(version, return_dtype=pl.Int32).alias("baseline_version"),
        pl.lit(now, dtype=pl.Datetime("us", "UTC")).alias("monitored_at"),
        "leak_scale",
        "leak_scale_ci_low",
        "leak_scale_ci_high",
        (pl.col("u_spread_m") * 1e3).alias("u_spread_mm"),
        "x_hat_determined",
        "leak_scale_held",
        pl.col("row_stride").cast(pl.Int32),
    ).cast(dict(polars_schema(EDGE_FIT_FIELDS))).with_columns(pl.col(pl.Float64).fill_nan(None))  # no estimate: NULL


Span = tuple[str, datetime, datetime, pl.DataFrame, pl.DataFrame]
"""(valve_id, start, end, fits, selection): the rows of one valve's windows starting in [start, end)."""


def store_spans(warehouse: Path, spans: list[Span], also: Callable[[duckdb.DuckDBPyConnection], None] | None = None) -> None:
    """For each span replace the valve's ``edge_fits`` and ``selection_stats`` rows whose
    ``window_start`` lies in ``[start, end)`` by the span's rows, then run ``also(con)`` (e.g. a
    progress record), all in one transaction: a rerun replaces, never duplicates, and a crash
    leaves every span as before or complete."""
    if not spans:
        return
    with connect(warehouse) as con:
        ensure_monitor_tables(con)
        with transaction(con):
            for valve_id, start, end, _, _ in spans:
                for table in ("edge_fits", "selection_stats"):
                    con.execute(f"DELETE FROM {table} WHERE valve_id = ? AND window_start >= ? AND window_start < ?", [valve_id, start, end])
            insert_frame(con, "edge_fits", pl.concat([s[3] for s in spans], how="vertical_relaxed"))
            insert_frame(con, "selection_stats", pl.concat([s[4] for s in spans], how="vertical_relaxed"))
            if also is not None:
                also(con)


@dataclass
class ValveReport:
    """What monitoring one valve gave."""

    valve_id: str
    windows: int = 0
    fits_ok: int = 0
    rows_read: int = 0
    baseline_source: str = ""
    baseline_plausible: bool = True
    edge_law_note: str = ""
    """The baselines' note when the commissioning window shows another edge law than the configured one."""
    status_counts: dict[str, int] = field(default_factory=dict)


def monitor_valve(
    config: PlantConfig, valve_id: str, warehouse: Path, start: datetime | None = None, end: datetime | None = None,
    *, chunk_days: int | None = None,
) -> ValveReport:
    """Steps 2–6 for one valve over [start, end) of its lake; see the module docstring."""
    valve = config.valve(valve_id)
    params = plant_monitor_params(config, valve)
    baselines = ensure_baselines(valve, params, warehouse)
    report = ValveReport(valve_id, baseline_source=baselines["s1"].source, baseline_plausible=all(b.plausible for b in baselines.values()),
                         edge_law_note=baselines["s1"].edge_law_note)  # fmt: skip
    gap_s = params.gap_limit_periods * params.sample_period_s
    spans: WriteBatch[Span] = WriteBatch(lambda batch: store_spans(warehouse, batch))
    for rows in lake_chunks(warehouse, valve.id, gap_s, start, end, chunk_days, LAKE_COLUMNS, params.window_s):
        res = monitor_rows(valve, params, baselines, rows)
        now = datetime.now(timezone.utc)
        fits = _fits_table(res.fits, valve, baselines, now)
        selection = res.selection.select([f.name for f in SELECTION_FIELDS]).cast(dict(polars_schema(SELECTION_FIELDS)))
        t = rows["timestamp_utc"]
        spans.add((valve.id, t[0], t[-1] + timedelta(microseconds=1), fits, selection))
        report.rows_read += rows.height
        report.windows += res.windows.height
        report.fits_ok += int((fits["status"] == "ok").sum())
        for s, n in fits["status"].value_counts().iter_rows():
            report.status_counts[s] = report.status_counts.get(s, 0) + n
    spans.flush()
    return report


def run_monitor(
    config_path: str | Path,
    warehouse: str | Path,
    valve_ids: list[str] | None = None,
    start: str | date | datetime | None = None,
    end: str | date | datetime | None = None,
    *,
    valve_runner: Callable[..., ValveReport] = monitor_valve,
    chunk_days: int | None = None,
) -> list[ValveReport]:
    """Monitor the plant's valves (or ``valve_ids``); ``valve_runner`` lets the flow pass its task.
    ``chunk_days``: lake days read at once per valve (default :data:`CHUNK_DAYS`; the fits do not
    depend on it)."""
    config = load_plant_config(config_path)
    warehouse = Path(warehouse)
    valves = plant_valves(config, valve_ids, config_path)
    t0, t1 = utc_instant(start, "--from"), utc_instant(end, "--to")
    if t0 and t1 and t1 <= t0:
        raise ValvemonError("--to must be later than --from")
    if chunk_days is None:
        return [valve_runner(config, v, warehouse, t0, t1) for v in valves]
    return [valve_runner(config, v, warehouse, t0, t1, chunk_days=chunk_days) for v in valves]


@task(name="monitor-valve", persist_result=False)
def monitor_valve_task(config: PlantConfig, valve_id: str, warehouse: Path, start: datetime | None, end: datetime | None) -> ValveReport:
    """One valve's steps 2–6 as a Prefect task."""
    return monitor_valve(config, valve_id, warehouse, start, end)


@flow(name="valvemon-monitor", persist_result=False, validate_parameters=False)
def monitor_flow(config_path: str, warehouse: str, valve_ids: list[str] | None = None, start: str | None = None, end: str | None = None) -> list[ValveReport]:
    """The Prefect flow behind ``valvemon monitor``."""
    return run_monitor(config_path, warehouse, valve_ids, start, end, valve_runner=monitor_valve_task)

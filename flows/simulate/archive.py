"""Synthetic historian archives: ``valvemon simulate`` (docs/simulate.md).

An archive is a folder::

    DIR/plant.toml                                  the plant configuration that reads the exports
    DIR/truth.parquet                               the true condition per valve, edge and window
    DIR/exports/<PLANT>_<YYYY-MM-DD>.<csv|csv.gz|parquet>   one file per UTC day, all valves' tags
    DIR/exports/<PLANT>_<YYYYMMDDTHHMMSS>.<…>              or files of N minutes (``file_s``), named by their first sample

The plant's valves are recorded in snapshot windows or continuously (:class:`ArchivePlan`),
simulated segment by segment with :mod:`model.simulate` (a batch of segments per call; a
recording longer than a segment continues from one segment's end state to the next) and
measured with :mod:`model.sensors`; their condition in each segment follows the valve's
scenario (:mod:`model.condition`: healthy, wear, broken edge, each with the valve's own
manufacturing scatter) at the segment's operating hours. The samples are converted from SI to
the units of the plant's tags and written the way the plant's historian exports them
(:mod:`flows.simulate.writers`), streamed: only one batch of segments is ever in memory.

Randomness: every window (segment) draws its operating inputs (trajectory, load, supply) and its sensor
noise from its own generator, seeded with (seed, valve id, segment start), and every valve its
manufacturing scatter from (seed, valve id). An archive is therefore the same, byte for byte,
for the same options, and a valve's data do not depend on which other valves are simulated
with it or how windows are batched.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import re
import shutil
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow.parquet as pq
import tomli_w

from flows.common.config import load_plant_config
from flows.common.errors import ValvemonError
from flows.common.instants import utc_instant
from flows.simulate.simulator import default_workers, iso_us, run_ordered, simulate_measured, valve_key, window_rng  # noqa: F401 (window_rng: API)
from flows.simulate.writers import FILE_SUFFIXES, ExportColumns, decimals_for_step, export_suffix, open_day_writer
from model import condition as mcond
from model.params import (
    EDGES,
    TABLE1,
    FluidParams,
    PlantParams,
    SensorChannel,
    SensorParams,
    ValveCondition,
    ValveGeometry,
)
from schemas.fields import SIGNAL_KIND, SIGNALS
from schemas.plant_config import ConfigError, ExportSpec, PlantConfig, ValveSpec, parse_plant_config, plant_config_to_dict

SCENARIOS: tuple[str, ...] = ("healthy", "wear", "broken_edge")
"""Scenario names ``--scenario`` accepts (``broken_edge`` also as ``broken_edge:EDGE@HOURS``)."""

TAG_SUFFIX: dict[str, str] = {"ps": "PS", "pr": "PR", "p1": "P1", "p2": "P2", "x_spool": "XS", "x_cyl": "XC", "x_ref": "XREF"}
"""Tag suffix of each signal in a generated plant: ``<PLANT>.<VALVE>.<SUFFIX>``."""

DEFAULT_COMMISSIONED = datetime(2025, 1, 1, tzinfo=timezone.utc)
"""Commissioning instant of the valves of a generated plant."""

BATCH_SAMPLES = 500_000
"""Samples per simulator call (windows x samples per window), which bounds the memory."""

CHUNK_ROWS = 4_000_000
"""Largest number of long-layout rows formatted at once."""

US = 1_000_000
DAY_US = 86_400 * US


# --- scenarios -------------------------------------------------------------------------------

_SCENARIO_RE = re.compile(r"^(?P<name>[a-z_]+)(?::(?P<edge>[a-z0-9]+))?(?:@(?P<hours>[0-9.eE+]+)h?)?$")


def parse_scenario(spec: str, *, scatter_seed: int | None = None, x_max_m: float = TABLE1.geometry.x_max_m) -> mcond.Scenario:
    """A scenario from its name as written on the command line and in ``plant.toml``.

    ``healthy``, ``wear`` (Table 3 calibrated, all edges), ``broken_edge`` (Table 2: edge 1r,
    broken from 0 h), ``broken_edge:s2`` (another edge), ``broken_edge:1r@4000`` (the edge breaks
    at 4000 operating hours). The broken edge's underlap grows by 11.8 % of the valve's x_max.

    Raises
    ------
    ValueError
        For anything else, with a message naming the accepted forms.
    """
    m = _SCENARIO_RE.match(spec.strip())
    forms = "healthy, wear, broken_edge[:EDGE][@HOURS]"
    if m is None or m["name"] not in SCENARIOS:
        raise ValueError(f"unknown scenario {spec!r} (expected {forms})")
    name, edge, hours = m["name"], m["edge"], m["hours"]
    if name != "broken_edge" and (edge or hours):
        raise ValueError(f"scenario {spec!r}: only broken_edge takes an edge and an hour (expected {forms})")
    if name == "healthy":
        return mcond.healthy(scatter_seed=scatter_seed)
    if name == "wear":
        return mcond.wear(scatter_seed=scatter_seed)
    edge = edge or "1r"
    if edge not in EDGES:
        raise ValueError(f"scenario {spec!r}: unknown edge {edge!r} (expected one of {', '.join(EDGES)})")
    try:
        from_h = float(hours) if hours else 0.0
    except ValueError:
        raise ValueError(f"scenario {spec!r}: {hours!r} is not a number of hours") from None
    return mcond.broken_edge(edge, from_hours=from_h, underlap_increase_m=0.118 * x_max_m, scatter_seed=scatter_seed)


def scatter_seed(seed: int, valve_id: str) -> int:
    """Seed of a valve's manufacturing scatter (from the seed and the valve id)."""
    return int(np.random.SeedSequence([int(seed), valve_key(valve_id), 1]).generate_state(1, np.uint64)[0])


def resolve_scenarios(config: PlantConfig, default: str | None, per_valve: dict[str, str]) -> dict[str, str]:
    """Each valve's scenario: ``--scenario VALVE=…``, else the valve's ``scenario`` key, else the
    default (``--scenario NAME``, or ``healthy``). Names are checked here."""
    ids = {v.id for v in config.valves}
    for vid in per_valve:
        if vid not in ids:
            raise ValvemonError(f"--scenario {vid}=…: no valve {vid!r} in plant {config.name!r} (valves: {', '.join(sorted(ids))})")
    out = {}
    for v in config.valves:
        spec = per_valve.get(v.id) or v.scenario or default or "healthy"
        try:
            parse_scenario(spec)
        except ValueError as exc:
            raise ValvemonError(f"valve {v.id}: {exc}") from None
        out[v.id] = spec
    return out


def parse_scenario_options(options: Sequence[str]) -> tuple[str | None, dict[str, str]]:
    """``--scenario`` values: ``NAME`` (the default) or ``VALVE=NAME``; returns (default, per valve)."""
    default = None
    per_valve: dict[str, str] = {}
    for opt in options:
        if "=" in opt:
            vid, _, spec = opt.partition("=")
            vid, spec = vid.strip(), spec.strip()
            if not vid or not spec:
                raise ValvemonError(f"--scenario {opt!r}: expected NAME or VALVE=NAME")
            if vid in per_valve:
                raise ValvemonError(f"--scenario: valve {vid!r} is given twice")
            per_valve[vid] = spec
        else:
            if default is not None:
                raise ValvemonError(f"--scenario: two defaults ({default!r} and {opt!r}); give the others as VALVE=NAME")
            default = opt.strip()
        try:
            parse_scenario(spec if "=" in opt else default)  # type: ignore[arg-type]
        except ValueError as exc:
            raise ValvemonError(f"--scenario: {exc}") from None
    return default, per_valve


# --- the plant -------------------------------------------------------------------------------


def generate_plant_config(
    name: str = "SIM1",
    n_valves: int = 3,
    layout: str = "long",
    commissioned: datetime = DEFAULT_COMMISSIONED,
    scenarios: dict[str, str] | None = None,
) -> PlantConfig:
    """A plant of ``n_valves`` valves V001… of the Table 1 type ``servo_4w`` (plant-config.md's
    example: underlap 0.04 mm on every edge, α 0.675, piston 140/100 mm, stroke 610 mm), tags
    ``<PLANT>.<VALVE>.<PS|PR|P1|P2|XS|XC|XREF>`` in bar and mm, exported in ``layout``
    (``long`` with a quality column, or ``wide``), ISO-8601 UTC timestamps."""
    if n_valves < 1 or n_valves > 999:
        raise ValvemonError(f"--valves: {n_valves} is not between 1 and 999")
    export: dict = {"layout": layout, "timestamp_column": "timestamp", "timestamp_format": "iso8601"}
    if layout == "long":
        export |= {"tag_column": "tag", "value_column": "value", "quality_column": "quality", "good_quality": ["Good", "192"]}
    export |= {"separator": ",", "decimal": "."}
    valves = []
    for i in range(1, n_valves + 1):
        vid = f"V{i:03d}"
        unit = {"pressure": "bar", "position": "mm", "spool_position": "mm"}
        v = {
            "id": vid,
            "type": "servo_4w",
            "commissioned": commissioned.astimezone(timezone.utc).isoformat().replace("+00:00", "Z"),
            "piston_diameter_mm": 140.0,
            "rod_diameter_mm": 100.0,
            "stroke_mm": 610.0,
            "v01_l": 3.0,
            "v02_l": 7.1,
            "bulk_modulus_gpa": 1.5,
            "density_kg_m3": 870.0,
            "tags": {s: {"tag": f"{name}.{vid}.{TAG_SUFFIX[s]}", "unit": unit[SIGNAL_KIND[s]]} for s in SIGNALS},
        }
        if scenarios and vid in scenarios:
            v["scenario"] = scenarios[vid]
        valves.append(v)
    raw = {
        "plant": {"name": name, "timezone": "UTC"},
        "export": export,
        "valve_types": {
            "servo_4w": {
                "x_max_mm": 3.5,
                "bore_radius_mm": 10.0,
                "spool_radius_mm": 9.99,
                "taper_angle_port1_deg": 10.48,
                "taper_angle_port2_deg": 5.24,
                "underlap_mm": {e: 0.04 for e in EDGES},
                "contraction_coefficient": 0.675,
            }
        },
        "valves": valves,
    }
    try:
        return parse_plant_config(raw)
    except ConfigError as exc:
        raise ValvemonError(f"generated plant: {exc}") from None


def with_scenarios(config: PlantConfig, scenarios: dict[str, str]) -> PlantConfig:
    """The configuration with each valve's ``scenario`` key set (for ``plant.toml``)."""
    valves = tuple(dataclasses.replace(v, scenario=scenarios[v.id]) for v in config.valves)
    return dataclasses.replace(config, valves=valves)


def _scaled_channel(ch: SensorChannel, factor: float) -> SensorChannel:
    return SensorChannel(ch.noise_std, ch.step * factor, ch.lo * factor, ch.hi * factor)


def plant_params_for_valve(valve: ValveSpec, export: ExportSpec, base: PlantParams = TABLE1) -> PlantParams:
    """The simulator's parameters for a configured valve: its design data (with its valve
    family, ``area_law`` and ``leakage_factor``) and positioning unit from the configuration,
    sampled at the export's ``sample_rate_hz``; everything the
    configuration does not name (spool dynamics, mass, friction, supply, controller, load,
    sensor noise) from ``base`` (Table 1). For a stroke or x_max other than Table 1's, the
    reference targets and the position sensors' ranges are scaled with them."""
    d = valve.design
    geometry = ValveGeometry(d.x_max_m, d.bore_radius_m, d.spool_radius_m, d.taper_angle_port1_rad, d.taper_angle_port2_rad,
                             d.area_law, d.leakage_factor)
    nominal = ValveCondition(underlap_m=d.underlap_m, alpha=(d.contraction_coefficient,) * 4, x_l_fraction=base.nominal_condition.x_l_fraction)
    cylinder = dataclasses.replace(
        base.cylinder,
        piston_diameter_m=valve.piston_diameter_m,
        rod_diameter_m=valve.rod_diameter_m,
        stroke_m=valve.stroke_m,
        v01_m3=valve.v01_m3,
        v02_m3=valve.v02_m3,
    )
    fluid = FluidParams(bulk_modulus_pa=valve.bulk_modulus_pa, density_kg_m3=valve.density_kg_m3)
    fs = export.sample_rate_hz
    sensors = dataclasses.replace(base.sensors, sample_rate_hz=fs)
    trajectory = base.trajectory
    if valve.stroke_m != base.cylinder.stroke_m:
        k = valve.stroke_m / base.cylinder.stroke_m
        trajectory = dataclasses.replace(
            trajectory, X_low_m=trajectory.X_low_m * k, X_high_m=trajectory.X_high_m * k, min_travel_m=trajectory.min_travel_m * k
        )
        xc = sensors.x_cyl
        sensors = dataclasses.replace(sensors, x_cyl=SensorChannel(xc.noise_std, xc.step, xc.lo, valve.stroke_m + (xc.hi - base.cylinder.stroke_m)))
    if d.x_max_m != base.geometry.x_max_m:
        k = d.x_max_m / base.geometry.x_max_m
        sensors = dataclasses.replace(sensors, x_spool=_scaled_channel(sensors.x_spool, k), x_ref=_scaled_channel(sensors.x_ref, k))
    controller = dataclasses.replace(base.controller, sample_time_s=1.0 / fs) if fs != base.sensors.sample_rate_hz else base.controller
    return dataclasses.replace(
        base, geometry=geometry, nominal_condition=nominal, cylinder=cylinder, fluid=fluid, sensors=sensors, controller=controller
    )


def _tag_decimals(valve: ValveSpec, signal: str, sensors: SensorParams) -> int | None:
    ch: SensorChannel = getattr(sensors, signal)
    f = valve.si_factor(signal)
    return decimals_for_step(ch.step / f, ch.noise_std / f)


# --- the time grid ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ArchivePlan:
    """When the recordings are.

    Snapshots (the default): ``windows_per_day`` windows a UTC day, each ``window_s`` long, the
    k-th starting at 00:00 + k·24 h / windows_per_day (floored to the sample grid), every window
    in [start, end) recorded for every valve. ``continuous``: one recording of every valve over
    the whole span, back to back (from the first sample instant at or after ``start``).

    A recording longer than ``segment_s`` is simulated as consecutive segments cut at the
    multiples of ``segment_s`` (UTC, since 1970), each continuing the last (states, reference,
    load and supply carry over) with its own operating inputs and the condition at its start;
    a shorter one is one segment. The exports are split into files of ``file_s`` (cut at its
    multiples since 00:00 UTC, named by their first sample), or one file a UTC day (``None``)."""

    start: datetime
    end: datetime
    windows_per_day: int = 24
    window_s: float = 10.0
    sample_rate_hz: float = 1000.0
    continuous: bool = False
    segment_s: float = 60.0
    file_s: float | None = None

    def __post_init__(self):
        if self.end <= self.start:
            raise ValvemonError(f"the span is empty: --to {_iso(self.end)} is not after --from {_iso(self.start)}")
        p = US / self.sample_rate_hz
        if abs(p - round(p)) > 1e-9:
            raise ValvemonError(f"export.sample_rate_hz: {self.sample_rate_hz:g} Hz is not a whole number of microseconds per sample")
        n = self.segment_s * self.sample_rate_hz
        if not (self.segment_s >= 1 and abs(n - round(n)) < 1e-6 and 86_400 % self.segment_s == 0):
            raise ValvemonError(f"--segment-s: {self.segment_s:g} s is not a whole number of seconds (>= 1) that divides a day")
        if self.file_s is not None and not (self.file_s >= 60 and self.file_s % 60 == 0 and 86_400 % self.file_s == 0):
            raise ValvemonError(f"--file-minutes: {self.file_s / 60:g} is not a whole number of minutes that divides a day (1440)")
        if self.continuous:
            return
        if not 1 <= self.windows_per_day <= 86_400:
            raise ValvemonError(f"--windows-per-day: {self.windows_per_day} is not between 1 and 86400")
        if not self.window_s > 0:
            raise ValvemonError(f"--window-s: {self.window_s:g} must be > 0")
        if self.window_s > 86_400 / self.windows_per_day:
            raise ValvemonError(
                f"--window-s: {self.window_s:g} s windows overlap at {self.windows_per_day} windows per day "
                f"(at most {86_400 / self.windows_per_day:g} s)"
            )
        n = self.window_s * self.sample_rate_hz
        if abs(n - round(n)) > 1e-6 or round(n) < 2:
            raise ValvemonError(f"--window-s: {self.window_s:g} s is not a whole number (>= 2) of samples at {self.sample_rate_hz:g} Hz")

    @property
    def n_samples(self) -> int:
        """Samples per window."""
        return round(self.window_s * self.sample_rate_hz)

    @property
    def period_us(self) -> int:
        """Sample period. [µs]"""
        return round(US / self.sample_rate_hz)

    def days(self) -> Iterator[tuple[date, np.ndarray]]:
        """Each UTC day of the span that has windows, with their start times (int64 µs UTC)."""
        start_us, end_us = _us(self.start), _us(self.end)
        day = self.start.astimezone(timezone.utc).date()
        k = np.arange(self.windows_per_day, dtype=np.int64)
        offsets = (k * DAY_US) // self.windows_per_day
        offsets -= offsets % self.period_us
        while True:
            day_us = _us(datetime(day.year, day.month, day.day, tzinfo=timezone.utc))
            if day_us >= end_us:
                return
            starts = day_us + offsets
            starts = starts[(starts >= start_us) & (starts < end_us)]
            if starts.size:
                yield day, starts
            day += timedelta(days=1)

    def n_slots(self) -> int:
        """Number of window slots in the span (continuous: 1)."""
        if self.continuous:
            return 1
        return sum(s.size for _, s in self.days())

    def recordings(self) -> Iterator[tuple[int, int]]:
        """Every recording as (first sample [µs UTC], samples), in time order."""
        if self.continuous:
            p = self.period_us
            first = -(-_us(self.start) // p) * p
            n = -(-(_us(self.end) - first) // p)
            if n > 0:
                yield first, n
            return
        for _, starts in self.days():
            for s0 in starts:
                yield int(s0), self.n_samples

    def segments(self, first_us: int, n: int) -> Iterator[tuple[int, int]]:
        """The segments of the recording of ``n`` samples from ``first_us``: (first sample
        [µs UTC], samples) each; one segment if it is no longer than ``segment_s``."""
        p, seg = self.period_us, round(self.segment_s * US)
        end = first_us + n * p
        if n * p <= seg:
            yield first_us, n
            return
        a = first_us
        while a < end:
            b = min(end, (a // seg + 1) * seg)
            m = -(-(b - a) // p)
            yield a, m
            a += m * p

    def n_segments(self) -> int:
        """Number of segments a valve is simulated in."""
        if not self.continuous and self.n_samples * self.period_us <= round(self.segment_s * US):
            return self.n_slots()
        return sum(1 for r in self.recordings() for _ in self.segments(*r))

    def valve_seconds(self) -> float:
        """Recorded seconds per valve. [s]"""
        return sum(n for _, n in self.recordings()) / self.sample_rate_hz

    def file_key(self, t_us: np.ndarray) -> np.ndarray:
        """Which export file each sample instant goes to (the file's first instant [µs UTC])."""
        size = DAY_US if self.file_s is None else round(self.file_s * US)
        return t_us - t_us % size


def _us(t: datetime) -> int:
    t = t.astimezone(timezone.utc)
    return (t.toordinal() - 719_163) * DAY_US + ((t.hour * 60 + t.minute) * 60 + t.second) * US + t.microsecond


def _iso(t: datetime) -> str:
    return t.astimezone(timezone.utc).isoformat().replace("+00:00", "Z")


def parse_hours(text: str) -> tuple[float, float]:
    """``--hours``: ``END`` (from 0 h) or ``START:END`` operating hours."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            h0, h1 = 0.0, float(parts[0])
        elif len(parts) == 2:
            h0, h1 = float(parts[0]), float(parts[1])
        else:
            raise ValueError
    except ValueError:
        raise ValvemonError(f"--hours: {text!r} is not END or START:END in operating hours") from None
    if not (math.isfinite(h0) and math.isfinite(h1)) or h0 < 0 or h1 <= h0:
        raise ValvemonError(f"--hours: {text!r} needs 0 <= START < END")
    return h0, h1


# --- the truth -------------------------------------------------------------------------------


@dataclass(frozen=True)
class ValveRun:
    """One valve of an archive run: its configuration, simulator parameters and scenario."""

    spec: ValveSpec
    params: PlantParams
    scenario_name: str
    scenario: mcond.Scenario
    commissioning: ValveCondition
    """As manufactured: the design condition with the valve's scatter, no wear, not broken."""
    seed: int
    """The archive's seed (windows are seeded with it, the valve id and their start)."""

    def hours(self, starts_us: np.ndarray) -> np.ndarray:
        """Operating hours (calendar time since commissioning) at ``starts_us``. [h]"""
        return (starts_us - _us(self.spec.commissioned)) / (3600.0 * US)

    def conditions(self, starts_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(underlap [m], alpha [-]), each (n, 4), at the windows starting at ``starts_us``."""
        return mcond.condition_arrays(self.scenario, self.hours(starts_us), self.params.nominal_condition)


def make_valve_runs(config: PlantConfig, scenarios: dict[str, str], seed: int) -> list[ValveRun]:
    """Simulator parameters, scenario and commissioning state of every valve."""
    runs = []
    for v in config.valves:
        params = plant_params_for_valve(v, config.export)
        ss = scatter_seed(seed, v.id)
        scen = parse_scenario(scenarios[v.id], scatter_seed=ss, x_max_m=v.design.x_max_m)
        commissioning = mcond.manufactured(params.nominal_condition, ss, scen.underlap_scatter_m, scen.alpha_scatter_rel)
        runs.append(ValveRun(v, params, scenarios[v.id], scen, commissioning, seed))
    return runs


TRUTH_SCHEMA = pl.Schema(
    {
        "valve_id": pl.String,
        "edge": pl.String,
        "window_start": pl.Datetime("us", "UTC"),
        "window_end": pl.Datetime("us", "UTC"),
        "operating_hours": pl.Float64,
        "scenario": pl.String,
        "alpha": pl.Float64,
        "alpha_rel": pl.Float64,
        "underlap_m": pl.Float64,
        "underlap_change_m": pl.Float64,
        "x_hat_mm": pl.Float64,
        "x_hat_pct": pl.Float64,
        "broken": pl.Boolean,
        "alpha_commissioned": pl.Float64,
        "underlap_commissioned_m": pl.Float64,
        "alpha_design": pl.Float64,
        "underlap_design_m": pl.Float64,
    }
)
"""``truth.parquet``: one row per valve, edge and window (docs/simulate.md explains each column)."""


def truth_frame(runs: Sequence[ValveRun], starts_us: np.ndarray, ends_us: np.ndarray) -> pl.DataFrame:
    """The truth rows of the windows (segments) [``starts_us``, ``ends_us``), ordered by window,
    valve, edge."""
    n, k = starts_us.size, len(EDGES)
    parts = []
    for vi, r in enumerate(runs):
        xu, al = r.conditions(starts_us)
        xu0 = np.asarray(r.commissioning.underlap_m)[None, :]
        al0 = np.asarray(r.commissioning.alpha)[None, :]
        dx = xu - xu0
        hours = r.hours(starts_us)
        broken = np.zeros((n, k), bool)
        if r.scenario.broken_edge is not None:
            broken[:, EDGES.index(r.scenario.broken_edge)] = hours >= r.scenario.broken_from_h
        parts.append(
            pl.DataFrame(
                {
                    "_w": np.repeat(np.arange(n), k),
                    "_v": np.full(n * k, vi),
                    "valve_id": [r.spec.id] * (n * k),
                    "edge": list(EDGES) * n,
                    "window_start": np.repeat(starts_us, k),
                    "window_end": np.repeat(ends_us, k),
                    "operating_hours": np.repeat(hours, k),
                    "scenario": [r.scenario_name] * (n * k),
                    "alpha": al.ravel(),
                    "alpha_rel": (al / al0).ravel(),
                    "underlap_m": xu.ravel(),
                    "underlap_change_m": dx.ravel(),
                    "x_hat_mm": (dx * 1e3).ravel(),
                    "x_hat_pct": (dx / r.params.geometry.x_max_m * 100.0).ravel(),
                    "broken": broken.ravel(),
                    "alpha_commissioned": np.tile(al0[0], n),
                    "underlap_commissioned_m": np.tile(xu0[0], n),
                    "alpha_design": np.tile(np.asarray(r.params.nominal_condition.alpha), n),
                    "underlap_design_m": np.tile(np.asarray(r.params.nominal_condition.underlap_m), n),
                }
            )
        )
    df = pl.concat(parts).sort(["_w", "_v"], maintain_order=True).drop("_w", "_v")
    return df.with_columns(pl.col("window_start", "window_end").cast(pl.Datetime("us", "UTC"))).cast(TRUTH_SCHEMA)  # type: ignore[arg-type]


# --- the archive -----------------------------------------------------------------------------


@dataclass
class ArchiveSummary:
    """What a run wrote and how long it took."""

    out: Path
    files: list[Path] = field(default_factory=list)
    windows: int = 0
    """Valve windows simulated."""
    rows: int = 0
    """Export rows written (long: sample x tag; wide: samples)."""
    values: int = 0
    """Values written (samples x tags)."""
    bytes: int = 0
    valve_seconds: float = 0.0
    simulate_s: float = 0.0
    """Time spent simulating, or (with workers) waiting for the simulation. [s]"""
    write_s: float = 0.0
    """Time spent converting, formatting and writing. [s]"""
    wall_s: float = 0.0


ProgressCallback = Callable[[int, float], None]
"""Called after every simulator call with (windows just simulated, valve-seconds just simulated)."""


def archive_paths(out: Path) -> tuple[Path, Path, Path]:
    """(plant.toml, truth.parquet, exports/) of an archive folder."""
    return out / "plant.toml", out / "truth.parquet", out / "exports"


def check_archive(config: PlantConfig, plan: ArchivePlan, file_format: str) -> None:
    """Whether ``plan`` can be written for ``config`` (a :class:`ValvemonError` if not)."""
    if file_format not in FILE_SUFFIXES:
        raise ValvemonError(f"unknown export file format {file_format!r}")
    if file_format == "tdms" and config.export.layout != "wide":
        raise ValvemonError(f"--format tdms: TDMS files hold a channel per tag (wide); the plant has export.layout = {config.export.layout!r}")
    unitless = [(v.id, s) for v in config.valves for s, t in v.tags.items() if t.unit is None]
    if unitless:
        raise ValvemonError(f"valve {unitless[0][0]}, signal {unitless[0][1]}: the simulator writes values in the configured units; give [valves.tags] unit")
    if abs(plan.sample_rate_hz - config.export.sample_rate_hz) > 1e-9:
        raise ValvemonError("the plan's sample rate must be the export's sample_rate_hz")
    if config.export.timestamp_format == "epoch_ms" and plan.period_us % 1000:
        raise ValvemonError(
            f"export.timestamp_format: epoch_ms cannot hold samples {plan.period_us} µs apart ({config.export.sample_rate_hz:g} Hz)"
        )
    late = [v for v in config.valves if v.commissioned > plan.start]
    if late:
        v = max(late, key=lambda v: v.commissioned)
        raise ValvemonError(f"--from {_iso(plan.start)} is before valve {v.id}'s commissioning ({_iso(v.commissioned)})")
    if next(plan.recordings(), None) is None:
        raise ValvemonError(f"no window falls into {_iso(plan.start)} … {_iso(plan.end)} at {plan.windows_per_day} windows per day")


def check_out_dir(out: Path, overwrite: bool) -> None:
    """An archive already in ``out`` is an error unless ``overwrite``."""
    toml_path, truth_path, exports = archive_paths(out)
    existing = [p for p in (toml_path, truth_path, exports) if p.exists()]
    if existing and not overwrite:
        raise ValvemonError(f"{out}: already holds an archive ({existing[0].name}); give --overwrite to replace it")
    if out.exists() and not out.is_dir():
        raise ValvemonError(f"--out: {out} is a file, not a folder")


def prepare_out_dir(out: Path, overwrite: bool) -> None:
    """Create the archive folder; an existing archive in it is an error unless ``overwrite``,
    which removes it (plant.toml, truth.parquet, exports/) and nothing else."""
    toml_path, truth_path, exports = archive_paths(out)
    existing = [p for p in (toml_path, truth_path, exports) if p.exists()]
    if existing and not overwrite:
        raise ValvemonError(f"{out}: already holds an archive ({existing[0].name}); give --overwrite to replace it")
    for p in existing:
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    exports.mkdir(parents=True, exist_ok=True)


@dataclass(frozen=True)
class _Step:
    """Segments that start at the same instants for every valve and are simulated together:
    several single-segment windows, or one segment of a longer recording."""

    starts: np.ndarray
    """First sample of each segment. [µs UTC]"""
    n_samples: int
    chain: int | None
    """The recording a segment of a longer recording belongs to (its index), else None."""
    first: bool
    """The recording's first segment."""
    last: bool
    """The recording's last segment."""


def _steps(plan: ArchivePlan, n_valves: int, batch_samples: int) -> Iterator[_Step]:
    """The steps of an archive in time order: windows that are one segment in groups (as many
    as fit ``batch_samples`` with every valve, at least one, within a UTC day), the segments of
    longer recordings one at a time (each continues the last)."""
    group: list[int] = []
    n_group = 0

    def flush():
        starts = np.array(group, dtype=np.int64)
        group.clear()
        return _Step(starts, n_group, None, True, True)

    for r, (first_us, n) in enumerate(plan.recordings()):
        segments = list(itertools.islice(plan.segments(first_us, n), 2))
        if len(segments) == 1:
            if group and (n != n_group or first_us // DAY_US != group[0] // DAY_US or (len(group) + 1) * n * n_valves > batch_samples):
                yield flush()
            group.append(first_us)
            n_group = n
            continue
        if group:
            yield flush()
        prev = None
        for seg in plan.segments(first_us, n):
            if prev is not None:
                yield _Step(np.array([prev[0]], dtype=np.int64), prev[1], r, prev[0] == first_us, False)
            prev = seg
        yield _Step(np.array([prev[0]], dtype=np.int64), prev[1], r, prev[0] == first_us, True)
    if group:
        yield flush()


@dataclass(frozen=True)
class _Call:
    """One simulator call of the pipeline and where its segments go."""

    step: _Step
    items: tuple[tuple[int, int], ...]
    """(valve run index, segment index within ``step.starts``) of each segment."""
    first_of_step: bool
    last_of_step: bool


def _calls(plan: ArchivePlan, runs: Sequence[ValveRun], batch_samples: int) -> Iterator[tuple[_Call, tuple]]:
    """The simulator calls of an archive in file order, each with its task
    (:data:`flows.simulate.simulator.Task`).

    Step by step (:func:`_steps`); within a step the valves that share simulator parameters
    together, split into calls of at most ``batch_samples`` samples (a recording's segments
    are split the same way throughout, so each call continues the one before it)."""
    groups: dict[PlantParams, list[int]] = {}
    for i, r in enumerate(runs):
        groups.setdefault(r.params, []).append(i)
    seg_samples = round(plan.segment_s * plan.sample_rate_hz)
    for step in _steps(plan, len(runs), batch_samples):
        conds = {i: runs[i].conditions(step.starts) for i in range(len(runs))}
        calls = []
        per_call = max(1, batch_samples // (step.n_samples if step.chain is None else seg_samples))
        for g, (params, members) in enumerate(groups.items()):
            x_l = params.nominal_condition.x_l_fraction
            items = [(i, k) for i in members for k in range(step.starts.size)]
            for c in range(0, len(items), per_call):
                chunk = tuple(items[c : c + per_call])
                conditions = [ValveCondition(tuple(conds[i][0][k]), tuple(conds[i][1][k]), x_l) for i, k in chunk]
                windows = [(runs[i].spec.id, int(step.starts[k])) for i, k in chunk]
                key = None if step.chain is None else (step.chain, g, c)
                args = (params, conditions, windows, step.n_samples, runs[chunk[0][0]].seed)
                calls.append((chunk, (simulate_measured, args, None if step.first else key, None if step.last else key)))
        for n, (chunk, task) in enumerate(calls):
            yield _Call(step, chunk, n == 0, n == len(calls) - 1), task


def export_name(config: PlantConfig, plan: ArchivePlan, first_us: int, suffix: str) -> str:
    """An export file's name: ``<PLANT>_<YYYY-MM-DD>`` (a day's file) or, with ``file_s``,
    ``<PLANT>_<YYYYMMDDTHHMMSS>`` of its first sample (UTC), as a recorder names its files."""
    t = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=int(first_us))
    stamp = t.date().isoformat() if plan.file_s is None else t.strftime("%Y%m%dT%H%M%S")
    return f"{config.name}_{stamp}{suffix}"


TRUTH_FLUSH_ROWS = 100_000
"""Truth rows buffered before they are written (a row group); they are also written when the
segments move on to the next export file."""


def write_archive(
    config: PlantConfig,
    out: Path,
    plan: ArchivePlan,
    scenarios: dict[str, str],
    *,
    seed: int = 0,
    file_format: str = "csv",
    gzip: bool = False,
    overwrite: bool = False,
    workers: int = 0,
    progress: ProgressCallback | None = None,
    batch_samples: int = BATCH_SAMPLES,
) -> ArchiveSummary:
    """Simulate ``config``'s valves over ``plan`` and write the archive into ``out``.

    Parameters
    ----------
    config : PlantConfig
        The plant; its export layout, tags and units decide how the files look.
    out : Path
        Archive folder (module docstring).
    plan : ArchivePlan
        The span, the recordings and the files.
    scenarios : dict
        Valve id → scenario name (:func:`parse_scenario`); recorded in ``plant.toml``.
    seed : int
        Seed of everything random.
    file_format : str
        ``"csv"`` or ``"parquet"``.
    gzip : bool
        Compress CSV files (``.csv.gz``).
    overwrite : bool
        Replace an archive already in ``out``.
    workers : int
        Simulator worker processes; 0 simulates in this process. The archive is the same
        either way.
    progress : callable, optional
        Called after every simulator call (:data:`ProgressCallback`).
    batch_samples : int
        Samples per simulator call (bounds the memory).

    Raises
    ------
    ValvemonError
        A simulation failed (the valve, the segment and the instant are named). Files are
        written under a ``.partial`` name and renamed when whole; on any failure, an
        interrupt included, the file being written and ``truth.parquet`` are removed, the
        whole export files already written stay.
    """
    t_wall = time.perf_counter()
    check_archive(config, plan, file_format)
    check_out_dir(out, overwrite)
    config = with_scenarios(config, scenarios)
    runs = make_valve_runs(config, scenarios, seed)
    prepare_out_dir(out, overwrite)
    toml_path, truth_path, exports = archive_paths(out)
    toml_path.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())

    # Columns: every configured tag, valve by valve, signal by signal.
    tags, decimals, units, names = [], [], [], []
    cols_of: dict[int, list[tuple[int, str, float]]] = {}  # run → (column, signal, si_factor of the unit)
    for i, r in enumerate(runs):
        for s in SIGNALS:
            if s in r.spec.tags:
                cols_of.setdefault(i, []).append((len(tags), s, r.spec.si_factor(s)))
                tags.append(r.spec.tags[s].tag)
                decimals.append(_tag_decimals(r.spec, s, r.params.sensors))
                units.append(r.spec.tags[s].unit)
                names.append(f"{r.spec.id} {s}")
    columns = ExportColumns(tuple(tags), tuple(decimals), tuple(units), tuple(names))

    period = plan.period_us
    long_layout = config.export.layout == "long"
    summary = ArchiveSummary(out=out)
    suffix = export_suffix(file_format, gzip)
    truth_partial = truth_path.with_name(truth_path.name + ".partial")
    truth_writer: pq.ParquetWriter | None = None
    truth_rows: list[pl.DataFrame] = []
    writer = None
    file_key = partial = path = None
    values = np.empty(0)
    metas: deque[_Call] = deque()

    def tasks():
        for meta, task in _calls(plan, runs, batch_samples):
            metas.append(meta)
            yield task

    def flush_truth():
        nonlocal truth_writer
        if not truth_rows:
            return
        table = pl.concat(truth_rows).rechunk().to_arrow()
        truth_rows.clear()
        if truth_writer is None:
            truth_writer = pq.ParquetWriter(truth_partial, table.schema, compression="zstd")
        truth_writer.write_table(table)

    def finish_file():
        nonlocal writer
        writer.close()
        writer = None
        os.replace(partial, path)
        summary.files.append(path)
        summary.bytes += path.stat().st_size

    def emit(t_us: np.ndarray, block: np.ndarray):
        """Write consecutive samples, opening the next file where a file ends."""
        nonlocal writer, file_key, partial, path
        keys = plan.file_key(t_us)
        cuts = [0, *np.flatnonzero(np.diff(keys)) + 1, t_us.size]
        for a, b in zip(cuts[:-1], cuts[1:]):
            if keys[a] != file_key:
                if writer is not None:
                    finish_file()
                file_key = keys[a]
                path = exports / export_name(config, plan, int(t_us[a]), suffix)
                partial = path.with_name(path.name + ".partial")
                writer = open_day_writer(partial, config.export, columns, config.timezone, file_format, gzip, continuous=plan.continuous)
            summary.rows += writer.write(t_us[a:b], block[a:b])
            summary.values += block[a:b].size

    try:
        t0 = time.perf_counter()
        for m in run_ordered(tasks(), workers):
            call = metas.popleft()
            step, n_samp = call.step, call.step.n_samples
            t1 = time.perf_counter()
            summary.simulate_s += t1 - t0
            if call.first_of_step:
                truth = truth_frame(runs, step.starts, step.starts + n_samp * period)
                if truth_rows and (plan.file_key(step.starts[:1])[0] != file_key or sum(f.height for f in truth_rows) >= TRUTH_FLUSH_ROWS):
                    flush_truth()
                truth_rows.append(truth)
                values = np.empty((step.starts.size, n_samp, len(tags)))
            for w, (i, k) in enumerate(call.items):
                for j, s, factor in cols_of[i]:
                    np.divide(m[s][w], factor, out=values[k, :, j])
            del m
            if call.last_of_step:
                rows_per_chunk = max(1, CHUNK_ROWS // len(tags)) if long_layout else n_samp
                rel_us = np.arange(n_samp, dtype=np.int64) * period
                for k, s0 in enumerate(step.starts):
                    for a in range(0, n_samp, rows_per_chunk):
                        emit(s0 + rel_us[a : a + rows_per_chunk], values[k, a : a + rows_per_chunk])
            summary.windows += len(call.items)
            summary.valve_seconds += len(call.items) * n_samp / plan.sample_rate_hz
            t0 = time.perf_counter()
            summary.write_s += t0 - t1
            if progress is not None:
                progress(len(call.items), len(call.items) * n_samp / plan.sample_rate_hz)
        if writer is not None:
            finish_file()
        flush_truth()
        if truth_writer is not None:
            truth_writer.close()
            truth_writer = None
            os.replace(truth_partial, truth_path)
    except BaseException as exc:
        if writer is not None:
            writer.close()
            partial.unlink(missing_ok=True)
        if truth_writer is not None:
            truth_writer.close()
        truth_partial.unlink(missing_ok=True)
        if isinstance(exc, BrokenProcessPool):
            call = metas[0] if metas else None
            where = "" if call is None else f" simulating {', '.join(dict.fromkeys(runs[i].spec.id for i, _ in call.items))} from {iso_us(int(call.step.starts[0]))}"
            raise ValvemonError(f"a simulator worker process died{where} (out of memory? try fewer --workers)") from None
        raise
    summary.wall_s = time.perf_counter() - t_wall
    return summary


# --- the command -----------------------------------------------------------------------------

FORMATS: tuple[str, ...] = ("long", "wide", "parquet", "ascii", "tdms")
"""``--format``: CSV long or wide, Parquet in the plant's layout, wide text with the plant's header
rows (``ascii``; a generated plant gets iba's tag/name/unit lines, tab-separated), TDMS (wide)."""
ASCII_HEADER_ROWS = ("tag", "name", "unit")
"""The header rows of a generated plant's ``--format ascii`` files (iba's ASCII export)."""
RECORDINGS: tuple[str, ...] = ("snapshot", "continuous")
CONTINUOUS_FILE_MINUTES = 60.0
"""Length of the export files of a continuous recording unless ``--file-minutes`` says."""


@dataclass(frozen=True)
class SimulateRequest:
    """``valvemon simulate``'s options, as given (validated by :func:`plan_request`)."""

    out: Path
    config_path: Path | None = None
    n_valves: int | None = None
    plant: str | None = None
    commissioned: str | None = None
    start: str | None = None
    end: str | None = None
    days: float | None = None
    hours: str | None = None
    windows_per_day: int | None = None
    window_s: float | None = None
    recording: str = "snapshot"
    segment_s: float = 60.0
    file_minutes: float | None = None
    scenarios: tuple[str, ...] = ()
    seed: int = 0
    format: str = "long"
    layout: str | None = None
    gzip: bool = False
    overwrite: bool = False
    workers: int | None = None


AUTO_WORKERS_VALVE_SECONDS = 2_000.0
"""Archives of at least this many valve-seconds use worker processes by default."""


def plan_request(req: SimulateRequest) -> tuple[PlantConfig, ArchivePlan, dict[str, str], str]:
    """Check the options and turn them into (plant, plan, scenarios, file format).

    Raises
    ------
    ValvemonError, ConfigError
        With a one-line message naming the option.
    """
    fmt = req.format.strip().lower()
    if fmt not in FORMATS:
        raise ValvemonError(f"--format: {req.format!r} is not one of {', '.join(FORMATS)}")
    if req.layout is not None and req.layout not in ("long", "wide"):
        raise ValvemonError(f"--layout: {req.layout!r} is not one of long, wide")
    if req.layout is not None and fmt != "parquet":
        raise ValvemonError("--layout: only with --format parquet (for CSV the format names the layout; ascii and tdms are wide)")
    if req.gzip and fmt in ("parquet", "tdms"):
        raise ValvemonError(f"--gzip: only for text formats ({'Parquet files are zstd-compressed' if fmt == 'parquet' else 'TDMS is binary'})")
    if req.seed < 0:
        raise ValvemonError(f"--seed: {req.seed} must be >= 0")
    if req.workers is not None and not 0 <= req.workers <= 256:
        raise ValvemonError(f"--workers: {req.workers} is not between 0 and 256")
    default, per_valve = parse_scenario_options(req.scenarios)
    if req.config_path is not None:
        for opt, val in (("--n-valves", req.n_valves), ("--plant", req.plant), ("--commissioned", req.commissioned)):
            if val is not None:
                raise ValvemonError(f"{opt}: only for a generated plant (without --config)")
        config = load_plant_config(req.config_path)
        layout = config.export.layout
        want = {"parquet": req.layout, "ascii": "wide", "tdms": "wide"}.get(fmt, fmt)
        if want is not None and want != layout:
            raise ValvemonError(f"--format/--layout: {want} contradicts export.layout = {layout!r} in {req.config_path}")
    else:
        layout = {"parquet": req.layout or "long", "ascii": "wide", "tdms": "wide"}.get(fmt, fmt)
        name = req.plant if req.plant is not None else "SIM1"
        if not re.match(r"^[A-Za-z0-9_-]+$", name):
            raise ValvemonError(f"--plant: {name!r} may hold only letters, digits, '-' and '_' (it names files and tags)")
        commissioned = utc_instant(req.commissioned, "--commissioned") if req.commissioned else DEFAULT_COMMISSIONED
        config = generate_plant_config(name, req.n_valves if req.n_valves is not None else 3, layout, commissioned)
        if fmt == "ascii":
            config = dataclasses.replace(config, export=dataclasses.replace(config.export, header_rows=ASCII_HEADER_ROWS, separator="\t"))
    scenarios = resolve_scenarios(config, default, per_valve)

    reference = max(v.commissioned for v in config.valves)
    if req.hours is not None:
        for opt, val in (("--from", req.start), ("--to", req.end), ("--days", req.days)):
            if val is not None:
                raise ValvemonError(f"--hours: give either --hours or {opt}, not both")
        h0, h1 = parse_hours(req.hours)
        start, end = reference + timedelta(hours=h0), reference + timedelta(hours=h1)
    else:
        start = utc_instant(req.start, "--from") if req.start is not None else reference
        if req.end is not None and req.days is not None:
            raise ValvemonError("--to: give either --to or --days, not both")
        if req.days is not None and not (math.isfinite(req.days) and req.days > 0):
            raise ValvemonError(f"--days: {req.days:g} must be > 0")
        end = utc_instant(req.end, "--to") if req.end is not None else start + timedelta(days=req.days if req.days is not None else 1.0)
    if req.recording not in RECORDINGS:
        raise ValvemonError(f"--recording: {req.recording!r} is not one of {', '.join(RECORDINGS)}")
    continuous = req.recording == "continuous"
    if continuous:
        for opt, val in (("--windows-per-day", req.windows_per_day), ("--window-s", req.window_s)):
            if val is not None:
                raise ValvemonError(f"{opt}: only for --recording snapshot (a continuous recording has no windows)")
    file_minutes = req.file_minutes if req.file_minutes is not None else (CONTINUOUS_FILE_MINUTES if continuous else None)
    plan = ArchivePlan(
        start,
        end,
        req.windows_per_day if req.windows_per_day is not None else 24,
        req.window_s if req.window_s is not None else 10.0,
        config.export.sample_rate_hz,
        continuous=continuous,
        segment_s=req.segment_s,
        file_s=None if file_minutes is None else file_minutes * 60.0,
    )
    return config, plan, scenarios, fmt if fmt in ("parquet", "ascii", "tdms") else "csv"


def run_simulate(req: SimulateRequest, *, show_progress: bool = True) -> ArchiveSummary:
    """``valvemon simulate``: check the options, write the archive with a progress bar."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    config, plan, scenarios, file_format = plan_request(req)
    check_archive(config, plan, file_format)
    check_out_dir(req.out, req.overwrite)
    total = plan.n_segments() * len(config.valves)
    workers = req.workers
    if workers is None:
        workers = default_workers() if plan.valve_seconds() * len(config.valves) >= AUTO_WORKERS_VALVE_SECONDS else 0
    progress = Progress(
        TextColumn("[bold]simulate[/] {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("segments · {task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        disable=not show_progress,
    )
    with progress:
        task = progress.add_task(f"{config.name} → {req.out}", total=total, rate="")
        t0 = time.perf_counter()
        done = [0.0]

        def on_batch(n_windows: int, valve_seconds: float) -> None:
            done[0] += valve_seconds
            rate = done[0] / max(time.perf_counter() - t0, 1e-9)
            progress.update(task, advance=n_windows, rate=f"{rate:,.0f} valve-s/s")

        return write_archive(
            config,
            req.out,
            plan,
            scenarios,
            seed=req.seed,
            file_format=file_format,
            gzip=req.gzip,
            overwrite=req.overwrite,
            workers=workers,
            progress=on_batch,
        )

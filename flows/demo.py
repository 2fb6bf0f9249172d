"""``valvemon demo``: a small synthetic plant through the whole pipeline.

The demo plant (``DEMO``, Table 1 valves) has twelve valves of different ages: new healthy ones,
worn ones commissioned up to three years earlier (the paper's wear scenario; one past its wear
bound), and one whose edge
1r breaks during the demo span (Table 2's fault). Three are of other valve families
(:data:`OTHER_FAMILIES`: two sharp-edged, one with worn lands leaking 3× Eq. 3). Every valve's commissioning day is simulated
too and named as its ``baseline_window``, so each edge's baseline is the step-4a fit of its own
commissioning data (checked against the nominal characteristic, step 5a), as at a real plant.

The plant delivers both shapes of data: the snapshot valves a 10 s window every 6 hours (one
historian export a day), the valves of :data:`CONTINUOUS_VALVES` a continuous recording for
part of every day (:data:`CONTINUOUS_MINUTES` back to back from 00:00 UTC, in recorder-style
files named by their start).

Steps: write ``plant.toml``; simulate the commissioning days, the snapshot span and the daily
recordings into exports (Parquet, long layout); ingest them into the lake; monitor (baselines, fits); refresh the
views and write the report (pictures, HTML, BI export). Everything lives under ``WAREHOUSE/demo/`` and the warehouse itself; a second run
replaces the archive and leaves the lake and the fits as they were (idempotent).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime, timedelta, timezone
from pathlib import Path

import tomli_w

from flows.common.prefect_run import flow
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.report.flow import run_report
from flows.simulate.archive import SimulateRequest, generate_plant_config, run_simulate
from schemas.plant_config import plant_config_to_dict

DEMO_END = datetime(2026, 10, 1, tzinfo=timezone.utc)
"""End of the demo span (fixed, so the demo is the same every time)."""
DEMO_DAYS = 60
"""Length of the demo span. [d]"""
WINDOWS_PER_DAY = 4
"""Monitoring windows per day in the demo span (every 6 h)."""
COMMISSIONING_WINDOWS = 12
"""Windows simulated on each valve's commissioning day (the baseline window)."""
CONTINUOUS_VALVES: tuple[str, ...] = ("V005",)
"""Valves recorded continuously for part of each day instead of in snapshots."""
CONTINUOUS_MINUTES = 5
"""Length of each day's continuous recording (from 00:00 UTC). [min]"""
DEMO_SEED = 1
"""One seed for both archives: it also draws each valve's manufacturing scatter, which must be
the same valve at commissioning and later."""

OTHER_FAMILIES: dict[str, tuple[str, dict]] = {
    "V003": ("servo_4w_sharp", {"area_law": "sharp"}),
    "V006": ("servo_4w_worn_lands", {"leakage_factor": 3.0}),
    "V008": ("servo_4w_sharp", {"area_law": "sharp"}),
}
"""Valves of other families than Eq. 3's (valve type, its design changes): sharp-edged spools
without closed-edge leakage, and Eq. 3 lands that leak three times as much (docs/simulate.md);
the monitor is not told, it identifies each edge's leakage at commissioning."""

# valve → (age at the start of the span [d], scenario)
DEMO_FLEET: dict[str, tuple[float, str]] = {
    "V001": (30, "healthy"),
    "V002": (60, "healthy"),
    "V003": (120, "healthy"),
    "V004": (200, "healthy"),
    "V005": (300, "wear"),
    "V006": (400, "healthy"),
    "V007": (450, "wear"),
    "V008": (500, "healthy"),
    "V009": (550, "wear"),
    "V010": (1150, "wear"),  # past the x̂ wear bound (6 % of x_max): state worn
    "V011": (650, "healthy"),
    "V012": (100, "broken_edge:1r@{h}"),
}


def demo_config(out: Path):
    """The demo plant: ages, scenarios and baseline windows of :data:`DEMO_FLEET`."""
    start = DEMO_END - timedelta(days=DEMO_DAYS)
    base = generate_plant_config("DEMO", len(DEMO_FLEET), "long")
    types = dict(base.valve_types)
    valves = []
    for v in base.valves:
        if v.id in OTHER_FAMILIES:
            type_name, changes = OTHER_FAMILIES[v.id]
            types[type_name] = dataclasses.replace(types[v.type], **changes)
            v = dataclasses.replace(v, type=type_name, design=types[type_name])
        age_d, scenario = DEMO_FLEET[v.id]
        commissioned = start - timedelta(days=age_d)
        # the broken edge breaks halfway through the demo span
        scenario = scenario.format(h=f"{(age_d + DEMO_DAYS / 2) * 24:g}")
        valves.append(
            dataclasses.replace(
                v,
                commissioned=commissioned,
                scenario=scenario,
                baseline_window=(commissioned, commissioned + timedelta(days=1)),
            )
        )
    config = dataclasses.replace(base, valve_types=types, valves=tuple(valves))
    out.mkdir(parents=True, exist_ok=True)
    path = out / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    return config, path


def _part_config(config, valves, path: Path) -> Path:
    """A plant.toml of some of ``config``'s valves (the archive of just those)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, valves=tuple(valves)))).encode())
    return path


def _simulate_all(requests: list[SimulateRequest]) -> None:
    """Write the archives of ``requests`` one after the other (in the demo's side process)."""
    for req in requests:
        run_simulate(req, show_progress=False)


def run_demo(warehouse: Path, *, show_progress: bool = True, valves: tuple[str, ...] | None = None) -> dict:
    """Simulate, ingest, monitor and report the demo plant into ``warehouse``.

    The snapshot span is written here (with the simulator's default workers) while one spawned
    side process writes the commissioning days and the recordings: the archives are
    independent and each is the same, byte for byte, however it is run. ``valves``: only these of
    the demo plant (the same valves, data and outcome as in the whole demo; for tests)."""
    out = warehouse / "demo"
    config, config_path = demo_config(out)
    if valves is not None:
        config = dataclasses.replace(config, valves=tuple(v for v in config.valves if v.id in valves))
        _part_config(config, config.valves, config_path)
    start = DEMO_END - timedelta(days=DEMO_DAYS)
    side = []  # each valve's commissioning day, simulated for that valve alone, then the recordings
    archives = []
    for v in config.valves:
        day = out / "commissioning" / v.id
        one = _part_config(config, [v], day / "plant.toml")
        side.append(SimulateRequest(
            out=day / "archive", config_path=one, start=v.commissioned.isoformat(), days=1.0,
            windows_per_day=COMMISSIONING_WINDOWS, format="parquet", overwrite=True, seed=DEMO_SEED, workers=0,
        ))  # fmt: skip
        archives.append(day / "archive" / "exports")
    recorded = out / "recordings"
    recording = [v for v in config.valves if v.id in CONTINUOUS_VALVES]
    if recording:
        continuous = _part_config(config, recording, out / "parts" / "recordings.toml")
        side.append(SimulateRequest(
            out=recorded, config_path=continuous, start=start.isoformat(), days=float(DEMO_DAYS), windows_per_day=1,
            window_s=CONTINUOUS_MINUTES * 60.0, file_minutes=float(CONTINUOUS_MINUTES), format="parquet", overwrite=True,
            seed=DEMO_SEED, workers=0,
        ))  # fmt: skip
    span = out / "archive"
    snapshot = _part_config(config, [v for v in config.valves if v.id not in CONTINUOUS_VALVES], out / "parts" / "snapshots.toml")
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        side_done = pool.submit(_simulate_all, side)
        run_simulate(
            SimulateRequest(
                out=span, config_path=snapshot, start=start.isoformat(), days=float(DEMO_DAYS),
                windows_per_day=WINDOWS_PER_DAY, format="parquet", overwrite=True, seed=DEMO_SEED,
            ),
            show_progress=show_progress,
        )  # fmt: skip
        side_done.result()
    exports = [*archives, span / "exports"] + ([recorded / "exports"] if recording else [])
    ingest = run_ingest(config_path, exports, warehouse, show_progress=show_progress)
    monitored = run_monitor(config_path, warehouse)
    report = run_report(config_path, warehouse)
    return {"config": config_path, "ingest": ingest, "monitor": monitored, "report": report}


@flow(name="valvemon-demo", persist_result=False, validate_parameters=False)
def demo_flow(warehouse: str, show_progress: bool = True) -> dict:
    """The Prefect flow behind ``valvemon demo``."""
    return run_demo(Path(warehouse), show_progress=show_progress)

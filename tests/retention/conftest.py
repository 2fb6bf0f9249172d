"""A small simulated warehouse for the retention tests: two valves, four UTC days, a 10 s window
every 4 h (6 a day), V001 commissioned on its first day's 01:00–07:00 windows; ingested, monitored
and read by the report's standstill check (the plain functions the flows run)."""

from __future__ import annotations

import dataclasses
import shutil
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import pytest
import tomli_w

from flows.common.config import load_plant_config
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.report.flow import update_standstill
from flows.simulate.archive import DEFAULT_COMMISSIONED, SimulateRequest, run_simulate
from schemas.plant_config import PlantConfig, RetentionSpec, plant_config_to_dict

DAY0 = DEFAULT_COMMISSIONED  # 2025-01-01T00:00Z
DAYS = [date(2025, 1, d) for d in (1, 2, 3, 4)]
AS_OF = date(2025, 1, 7)  # ages 6, 5, 4, 3 days
COMMISSIONING = (DAY0 + timedelta(hours=1), DAY0 + timedelta(hours=7))  # inside V001's first day


def write_config(src: Path, out: Path, retention: RetentionSpec | None) -> Path:
    config = load_plant_config(src)
    valves = tuple(dataclasses.replace(v, baseline_window=COMMISSIONING) if v.id == "V001" else v for v in config.valves)
    out.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, valves=valves, retention=retention))).encode())
    return out


@pytest.fixture(scope="session")
def base(tmp_path_factory) -> tuple[Path, Path]:
    """Two valves, four UTC days, a 10 s window every 4 h, V001 commissioned on its first day's
    01:00–07:00 windows: ingested, monitored and checked for standstill. (warehouse, archive)."""
    root = tmp_path_factory.mktemp("retention")
    archive = root / "sim"
    run_simulate(SimulateRequest(out=archive, n_valves=2, days=4.0, windows_per_day=6, format="parquet", seed=5, workers=0), show_progress=False)
    cfg = write_config(archive / "plant.toml", root / "plant.toml", None)
    wh = root / "wh"
    run_ingest(cfg, [archive / "exports"], wh)
    run_monitor(cfg, wh)
    update_standstill(load_plant_config(cfg), wh, datetime.now(timezone.utc))
    return wh, archive


@pytest.fixture
def wh(base, tmp_path) -> Path:
    """A copy of the base warehouse for one test."""
    dst = tmp_path / "wh"
    shutil.copytree(base[0], dst)
    return dst


def plant_with(base, tmp_path, **kw) -> PlantConfig:
    """The plant with ``[retention]`` set from ``kw`` (also written to ``tmp_path/plant.toml``)."""
    return load_plant_config(write_config(base[1] / "plant.toml", tmp_path / "plant.toml", RetentionSpec(**kw) if kw else None))

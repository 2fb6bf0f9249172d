"""Shared helpers of the ingest tests: plant configurations, the reference lake, warehouse reads.

The hand-written exports in ``data/`` all hold (apart from their quirk) the same five seconds of
valve V017 on 2025-03-01 from 12:00:00 to 12:00:04 UTC: :data:`BASE` in export units (bar, mm).
The test plant is the specification's example on a 1 Hz grid with gaps longer than 2.5 s.
"""

from __future__ import annotations

import sys
import tomllib
from datetime import datetime, timedelta, timezone
from pathlib import Path

import polars as pl
import pytest
import tomli_w

from flows.common.config import load_plant_config
from flows.common.lake import read_lake
from flows.common.warehouse_db import connect, query_frame
from flows.ingest.flow import run_ingest
from schemas.fields import SENSOR_FIELDS, polars_schema

T0_US = 1_735_689_600 * 10**6  # 2025-01-01T00:00Z
"""The lake tests' first time stamp. [µs]"""
FLOATS = [f.name for f in SENSOR_FIELDS if f.name.endswith(("_pa", "_m"))]
"""The lake's float signal columns."""
DATA = Path(__file__).parent / "data"
EXAMPLE = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"
T0 = datetime(2025, 3, 1, 12, 0, 0, tzinfo=timezone.utc)

BASE = {
    "ps": [210.0, 210.5, 211.0, 210.25, 209.75],
    "pr": [2.0, 2.5, 2.0, 2.25, 1.75],
    "p1": [100.0, 101.5, 102.0, 103.5, 104.0],
    "p2": [90.0, 89.5, 89.0, 88.5, 88.0],
    "x_spool": [0.1, 0.2, -0.3, 0.4, 0.5],
    "x_cyl": [300.0, 300.5, 301.0, 301.5, 302.0],
}
"""The reference data of the fixtures, in export units (bar, mm), one value per second."""

FACTOR = {"ps": 1e5, "pr": 1e5, "p1": 1e5, "p2": 1e5, "x_spool": 1e-3, "x_cyl": 1e-3, "x_ref": 1e-3}
COLUMN = {"ps": "ps_pa", "pr": "pr_pa", "p1": "p1_pa", "p2": "p2_pa", "x_spool": "x_spool_m", "x_cyl": "x_cyl_m", "x_ref": "x_ref_m"}


def write_plant(folder: Path, name: str = "plant.toml", units: dict[str, str] | None = None, **export) -> Path:
    """The example plant with ``[export]`` keys replaced (a value None removes the key) and,
    optionally, other units for some signals (``units={"x_spool": "%"}``)."""
    raw = tomllib.loads(EXAMPLE.read_text())
    raw["export"].update({"sample_rate_hz": 1.0, "max_gap_s": 2.5})
    for signal, unit in (units or {}).items():
        raw["valves"][0]["tags"][signal]["unit"] = unit
    for k, v in export.items():
        if v is None:
            raw["export"].pop(k, None)
        else:
            raw["export"][k] = v
    path = folder / name
    path.write_bytes(tomli_w.dumps(raw).encode())
    return path


def expected_lake(times: list[datetime], values: dict[str, list[float | None]], valve_id: str = "V017") -> pl.DataFrame:
    """The lake frame of ``values`` (export units) at ``times``, converted as the ingest does."""
    data: dict[str, object] = {
        "valve_id": [valve_id] * len(times),
        "date": [t.date() for t in times],
        "timestamp_utc": times,
    }
    for signal, col in COLUMN.items():
        vals = values.get(signal)
        data[col] = [None] * len(times) if vals is None else [None if v is None else v * FACTOR[signal] for v in vals]
    return pl.DataFrame(data, schema=polars_schema(SENSOR_FIELDS))


def base_lake(n: int = 5) -> pl.DataFrame:
    """The lake of the reference data (its first ``n`` seconds)."""
    return expected_lake([T0 + timedelta(seconds=i) for i in range(n)], {s: v[:n] for s, v in BASE.items()})


def lake(warehouse: Path) -> pl.DataFrame:
    """The whole lake, collected."""
    return read_lake(warehouse).collect()


def table(warehouse: Path, name: str) -> pl.DataFrame:
    with connect(warehouse, read_only=True) as con:
        return query_frame(con, f"SELECT * FROM {name}")


def ingest(config: Path, paths, warehouse: Path, **kw):
    """The plain (Prefect-free) ingest run."""
    return run_ingest(config, [str(p) for p in (paths if isinstance(paths, (list, tuple)) else [paths])], warehouse, **kw)


def run_cli(args: list[str], monkeypatch, capsys) -> tuple[int, str, str]:
    """Run ``valvemon`` as the console script does; (exit code, stdout, stderr)."""
    from flows.cli import main

    monkeypatch.setattr(sys, "argv", ["valvemon", *args])
    monkeypatch.delenv("PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL", raising=False)  # restored after the test
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def plant(tmp_path):
    """``plant(**export_overrides) -> (config path, PlantConfig)``."""

    def make(name: str = "plant.toml", units: dict[str, str] | None = None, **export):
        path = write_plant(tmp_path, name, units, **export)
        return path, load_plant_config(path)

    return make

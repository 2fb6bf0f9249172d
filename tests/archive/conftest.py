"""Small synthetic archives shared by the archive tests (each a few valve-seconds)."""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

import pytest

from flows.simulate.archive import DEFAULT_COMMISSIONED, ArchivePlan, generate_plant_config, resolve_scenarios, write_archive

SEED = 11
SCENARIOS = {"V001": "wear", "V002": "broken_edge:1r@30"}
# 2 windows a UTC day (00:00 and 12:00) of 1.5 s from 06:00 on the commissioning day to 01:00 two
# days later: windows at 12, 24, 36 and 48 operating hours, on three days (three export files),
# x 2 valves. V002's edge 1r breaks at 30 h, between the 2nd and the 3rd window.
START = DEFAULT_COMMISSIONED + timedelta(hours=6)
END = DEFAULT_COMMISSIONED + timedelta(days=2, hours=1)
PLAN = ArchivePlan(START, END, windows_per_day=2, window_s=1.5)


def make_archive(out: Path, *, layout: str = "long", file_format: str = "csv", gzip: bool = False, seed: int = SEED, **kw):
    """Write the small test archive; returns (config with scenarios, summary)."""
    config = generate_plant_config("T1", 2, layout)
    scenarios = resolve_scenarios(config, None, SCENARIOS)
    summary = write_archive(config, out, PLAN, scenarios, seed=seed, file_format=file_format, gzip=gzip, **kw)
    return config, summary


@pytest.fixture(scope="session")
def long_gz(tmp_path_factory):
    out = tmp_path_factory.mktemp("long_gz")
    return out, *make_archive(out, gzip=True)


@pytest.fixture(scope="session")
def wide_csv(tmp_path_factory):
    out = tmp_path_factory.mktemp("wide_csv")
    return out, *make_archive(out, layout="wide")


@pytest.fixture(scope="session")
def long_parquet(tmp_path_factory):
    out = tmp_path_factory.mktemp("long_parquet")
    return out, *make_archive(out, file_format="parquet")


@pytest.fixture(scope="session")
def wide_parquet(tmp_path_factory):
    out = tmp_path_factory.mktemp("wide_parquet")
    return out, *make_archive(out, layout="wide", file_format="parquet")

"""A small simulated archive and a clean backfill of it, shared by the orchestration tests.

2 valves × 3 UTC days (2025-01-01 … 2025-01-03), 4 windows of 10 s a day at 1 kHz, Parquet
(one file per day): 24 valve windows, 96 fits. Backfilled with one-day monitor units: 3 ingest
units and 6 monitor units.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import duckdb
import polars as pl
import pytest

from flows.simulate.archive import SimulateRequest, run_simulate

START, END = "2025-01-01", "2025-01-04"

VOLATILE = {
    "edge_fits": ("monitored_at",),
    "baselines": ("created_at",),
    "ingest_manifest": ("ingested_at", "run_id"),
    "quarantine": ("ingested_at", "run_id"),
    "backfill_progress": ("run_id", "finished_at", "fingerprint"),  # the fingerprint holds partition mtimes
}
"""Columns that record when or by which run a row was written (differ between two clean runs)."""

TABLES = ("edge_fits", "selection_stats", "baselines", "ingest_manifest", "quarantine", "ingest_gaps", "backfill_progress")


def table(warehouse: Path, name: str, *, volatile: bool = True) -> pl.DataFrame:
    """A warehouse table sorted by all its columns, optionally without the volatile ones."""
    con = duckdb.connect(str(Path(warehouse) / "valvemon.duckdb"), read_only=True)
    try:
        drop = () if volatile else VOLATILE.get(name, ())
        cols = [c for c in con.sql(f"SELECT * FROM {name} LIMIT 0").columns if c not in drop]
        return pl.from_arrow(con.sql(f"SELECT {', '.join(cols)} FROM {name} ORDER BY ALL").to_arrow_table())
    finally:
        con.close()


def lake_files(warehouse: Path, *, mtimes: bool = False) -> dict[str, tuple]:
    """Lake file → sha256 of its bytes (and its mtime)."""
    root = Path(warehouse) / "lake"
    out = {}
    for p in sorted(root.rglob("*.parquet")):
        digest = hashlib.sha256(p.read_bytes()).hexdigest()
        out[str(p.relative_to(root))] = (digest, p.stat().st_mtime_ns) if mtimes else (digest,)
    return out


def snapshot(warehouse: Path, *, volatile: bool = True, tables=TABLES) -> dict:
    """Every backfilled table and the lake's bytes (``volatile=False``: without run-specific columns)."""
    snap = {name: table(warehouse, name, volatile=volatile) for name in tables}
    snap["lake"] = lake_files(warehouse, mtimes=volatile)
    return snap


def assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], pl.DataFrame):
            assert a[k].shape == b[k].shape, k
            assert a[k].equals(b[k]), f"table {k} differs"
        else:
            assert a[k] == b[k], k


@pytest.fixture(scope="session")
def archive(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("orch_archive") / "archive"
    run_simulate(
        SimulateRequest(out=out, n_valves=2, start=START, end=END, windows_per_day=4, format="parquet", seed=3, workers=0),
        show_progress=False,
    )
    return out


@pytest.fixture(scope="session")
def clean(archive, tmp_path_factory):
    """One clean backfill of the archive (one-day units, two threads, as a command runs it without
    a Prefect API: the flow's function); returns (warehouse, summary)."""
    from flows.orchestration.backfill import backfill_flow

    wh = tmp_path_factory.mktemp("orch_clean") / "wh"
    summary = backfill_flow.fn(
        config_path=str(archive / "plant.toml"), warehouse=str(wh), start=START, end=END,
        exports=str(archive / "exports"), concurrency=2, unit_days=1,
    )  # fmt: skip
    return wh, summary


def copy_warehouse(src: Path, dst: Path) -> Path:
    """A copy with the same file times (so partitions look unchanged to the fingerprints)."""
    shutil.copytree(src, dst, copy_function=shutil.copy2)
    return dst

"""End to end through the real command line: simulate → ingest → monitor → `valvemon report`
→ `valvemon query`. The simulated broken edge 1r (Table 2) must come out faulty, the Eq. 9
standstill check must fail for it alone, and the healthy valve must not raise an alarm."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import polars as pl
import pytest

pytestmark = pytest.mark.slow


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).parent / "valvemon"
    env = os.environ | {"PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
    r = subprocess.run([str(exe), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"valvemon {' '.join(args)}: {r.stderr[-2000:]}"
    return r


def test_simulated_plant_through_report_and_query(tmp_path):
    from flows.ingest.flow import run_ingest
    from flows.monitor.flow import run_monitor

    _cli("simulate", "--out", "sim", "--n-valves", "2", "--days", "1", "--windows-per-day", "12", "--format", "parquet",
         "--scenario", "V001=healthy", "--scenario", "V002=broken_edge", "--quiet", cwd=tmp_path)  # fmt: skip
    config, warehouse = tmp_path / "sim" / "plant.toml", tmp_path / "wh"
    run_ingest(config, [tmp_path / "sim" / "exports"], warehouse)  # the flows' bodies, without a Prefect API
    run_monitor(config, warehouse)
    r = _cli("report", "--config", str(config), "--warehouse", str(warehouse), cwd=tmp_path)
    html = Path(r.stdout.strip().splitlines()[-1])
    assert html == (warehouse / "reports" / "report.html").resolve() and html.stat().st_size > 100_000
    q = _cli("query", "SELECT valve_id, edge, state, eq9_ok FROM valve_condition ORDER BY valve_id, edge_order",
             "--format", "json", "--warehouse", str(warehouse), cwd=tmp_path)  # fmt: skip
    cond = pl.read_json(q.stdout.encode())
    states = {(r["valve_id"], r["edge"]): r["state"] for r in cond.iter_rows(named=True)}
    assert states[("V002", "1r")] == "faulty"
    assert all(states[("V001", e)] != "faulty" for e in ("s1", "1r", "s2", "2r"))
    eq9 = dict(zip(cond["valve_id"], cond["eq9_ok"]))
    assert eq9 == {"V001": True, "V002": False}
    alarms = _cli("query", "SELECT DISTINCT valve_id, edge FROM fault_alarms ORDER BY ALL", "--format", "csv",
                  "--warehouse", str(warehouse), cwd=tmp_path)  # fmt: skip
    assert alarms.stdout.split() == ["valve_id,edge", "V002,1r"]
    exported = warehouse / "export" / "edge_fits"
    assert sorted(p.name for p in exported.iterdir()) == ["_exported_through", "valve_id=V001", "valve_id=V002"]
    assert {p.parent.parent.name for p in exported.glob("valve_id=*/date=*/part-0.parquet")} == {"valve_id=V001", "valve_id=V002"}

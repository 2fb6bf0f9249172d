"""`valvemon query` right after `ingest` and `monitor`, without `report` (issue 15, item 3): every
writing command publishes the snapshot, so the manifest, the fits and the condition views are
there at once; and a query during a running `monitor` (the writer mid-transaction) answers from
the previous snapshot instead of waiting. All through the real command line, in subprocesses."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from flows.simulate.archive import DEFAULT_COMMISSIONED, SimulateRequest, run_simulate
from tests.report.commands import run_each

ROOT = Path(__file__).resolve().parents[2]
DAY2 = "2025-01-02T00:00:00Z"

# `valvemon monitor` whose first write transaction stops, inside the write connection, until told to go on
_HELD_MONITOR = textwrap.dedent("""
    import sys, time
    from contextlib import contextmanager
    from pathlib import Path
    import flows.monitor.flow as fm
    from flows.cli import main
    ready, go = Path(sys.argv[1]), Path(sys.argv[2])
    real = fm.transaction

    @contextmanager
    def held(con):
        with real(con):
            if not ready.exists():
                ready.touch()
                while not go.exists():
                    time.sleep(0.05)
            yield

    fm.transaction = held
    sys.argv = ["valvemon", *sys.argv[3:]]
    main()
""")


def _env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")}  # no Prefect API: plain runs
    return env | {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp_path / "prefect-home")}


def _cli(args: list[str], env: dict[str, str]) -> str:
    proc = subprocess.run([sys.executable, "-c", "from flows.cli import main; main()", *args], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _query(*sqls: str, wh: Path, env: dict[str, str]) -> list[list[str]]:
    """The rows (CSV, without the header) of each query, the queries run one after the other in one process."""
    done = run_each([["query", sql, "--format", "csv", "--warehouse", str(wh)] for sql in sqls], env)
    assert all(code == 0 for code, _, _ in done), done
    return [out.splitlines()[1:] for _, out, _ in done]


@pytest.mark.slow
def test_query_sees_each_step_at_once_and_never_waits_for_a_running_monitor(tmp_path):
    archive = tmp_path / "sim"
    run_simulate(SimulateRequest(out=archive, n_valves=1, start=DEFAULT_COMMISSIONED.isoformat(), days=2.0, windows_per_day=2,
                                 format="parquet", seed=5, workers=0), show_progress=False)  # fmt: skip
    env, wh, config = _env(tmp_path), tmp_path / "wh", str(archive / "plant.toml")

    _cli(["ingest", "--config", config, "--warehouse", str(wh), str(archive / "exports")], env)
    manifest, quarantine, fits = _query("SELECT count(*) FROM ingest_manifest", "SELECT count(*) FROM quarantine", "SELECT count(*) FROM edge_fits", wh=wh, env=env)
    assert manifest == ["2"]  # one file per day
    assert quarantine == ["0"]
    assert fits == ["0"]  # the views' tables exist before any fit

    _cli(["monitor", "--config", config, "--warehouse", str(wh), "--to", DAY2], env)  # day 1: 2 windows × 4 edges
    fits, condition = _query("SELECT count(*) FROM edge_fits WHERE status = 'ok'", "SELECT valve_id, edge, state, n_windows FROM valve_condition ORDER BY edge_order",
                             wh=wh, env=env)  # fmt: skip
    assert fits == ["8"]
    assert condition == [f"V001,{e},unknown,2" for e in ("s1", "1r", "s2", "2r")]  # too few fits for a trend: unknown

    ready, go = tmp_path / "ready", tmp_path / "go"
    monitor = subprocess.Popen([sys.executable, "-c", _HELD_MONITOR, str(ready), str(go), "monitor", "--config", config, "--warehouse", str(wh)],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        while not ready.exists():
            assert monitor.poll() is None, monitor.communicate()
            time.sleep(0.05)
        # the monitor holds the live database mid-transaction: the reader answers from the snapshot
        fits, condition = _query("SELECT count(*) FROM edge_fits", "SELECT * FROM valve_condition", wh=wh, env=env)
        assert fits == ["8"] and len(condition) == 4
        assert monitor.poll() is None  # the answers came while the writer was still holding the database
    finally:
        go.touch()
        out, err = monitor.communicate(timeout=600)
    assert monitor.returncode == 0, err
    fits, most = _query("SELECT count(*) FROM edge_fits WHERE status = 'ok'", "SELECT max(n_windows) FROM valve_condition", wh=wh, env=env)
    assert fits == ["16"]  # day 2 published at once
    assert most == ["4"]

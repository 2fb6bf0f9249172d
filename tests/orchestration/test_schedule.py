"""`valvemon serve` on a real `prefect server start`: the cron schedule fires and the run makes fits.

A Prefect server (SQLite in a temporary PREFECT_HOME, a free port on 127.0.0.1) and `valvemon
serve --cron "* * * * *"` run as subprocesses in their own sessions; the inbox holds yesterday's
export. The test waits (at most 150 s after serve starts) for ``edge_fits`` rows, then checks
that they came from a scheduled (not a manual) flow run, and for the report. The schedule fires
once a minute at the second that comes ``FIRST_FIRE_S`` after serve starts (croniter's sixth field
is the second), not on the minute: the test waits for serve and the run, not for the clock. Both process groups
are terminated in any case.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import duckdb
import httpx
import pytest

from flows.simulate.archive import SimulateRequest, run_simulate

FIRE_WITHIN_S = 240  # a deadline, not a wait: generous for a loaded machine
FIRST_FIRE_S = 6  # serve registers the deployment 2.5-2.8 s after it starts, idle or with both cores busy (a fire it misses comes again a minute later)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen | None, grace_s: float = 10) -> None:
    """SIGTERM the process group, SIGKILL it if it is still there after the grace period."""
    if proc is None:
        return
    for sig, wait in ((signal.SIGTERM, grace_s), (signal.SIGKILL, 10)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            continue
        # the group may outlive its leader (flow-run subprocesses)
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        return


def fits_count(wh: Path) -> int:
    try:
        con = duckdb.connect(str(wh / "valvemon.duckdb"), read_only=True)
    except (duckdb.IOException, duckdb.InvalidInputException):  # missing, or locked by the writer
        return 0
    try:
        return con.execute("SELECT count(*) FROM edge_fits").fetchone()[0]
    except duckdb.CatalogException:
        return 0
    finally:
        con.close()


@pytest.mark.slow
def test_scheduled_nightly_run_fires_and_makes_fits(tmp_path):
    yesterday = (datetime.now(timezone.utc) - timedelta(days=1)).date()
    archive = tmp_path / "archive"
    wh = tmp_path / "wh"
    port = free_port()
    api = f"http://127.0.0.1:{port}/api"
    env = dict(os.environ)
    env.update(
        PREFECT_HOME=str(tmp_path / "prefect-home"),
        PREFECT_API_URL=api,
        PREFECT_SERVER_ANALYTICS_ENABLED="false",
        PREFECT_UI_ENABLED="false",
        PREFECT_RUNNER_POLL_FREQUENCY="2",
        PREFECT_LOGGING_TO_API_ENABLED="false",
    )
    env.pop("PREFECT_API_DATABASE_CONNECTION_URL", None)
    env.pop("PREFECT_SERVER_DATABASE_CONNECTION_URL", None)
    bindir = Path(sys.executable).parent
    server = serve = None
    logs = {name: open(tmp_path / f"{name}.log", "wb") for name in ("server", "serve")}
    try:
        server = subprocess.Popen(
            [str(bindir / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)],
            env=env, stdout=logs["server"], stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
        run_simulate(  # while the server starts
            SimulateRequest(out=archive, n_valves=2, start=yesterday.isoformat(), days=1, windows_per_day=4, format="parquet", seed=5, workers=0),
            show_progress=False,
        )
        deadline = time.monotonic() + 120
        while True:
            try:
                if httpx.get(f"{api}/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert server.poll() is None, (tmp_path / "server.log").read_text()[-2000:]
            assert time.monotonic() < deadline, "the Prefect server did not start within 120 s"
            time.sleep(1)

        cron = f"* * * * * {(datetime.now(timezone.utc).second + FIRST_FIRE_S) % 60}"
        serve = subprocess.Popen(
            [str(bindir / "valvemon"), "serve", "--config", str(archive / "plant.toml"), "--exports", str(archive / "exports"),
             "--warehouse", str(wh), "--cron", cron, "--timezone", "UTC", "--name", "test-nightly"],
            env=env, stdout=logs["serve"], stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
        deadline = time.monotonic() + FIRE_WITHIN_S
        n = 0
        while time.monotonic() < deadline:
            assert serve.poll() is None, (tmp_path / "serve.log").read_text()[-3000:]
            n = fits_count(wh)
            if n:
                break
            time.sleep(2)
        assert n == 2 * 4 * 4, f"edge_fits has {n} rows after {FIRE_WITHIN_S} s\n" + (tmp_path / "serve.log").read_text()[-3000:]

        # the fits came from a run the schedule created, of our deployment
        runs = httpx.post(f"{api}/flow_runs/filter", json={"limit": 50}, timeout=10).json()
        deployments = httpx.post(f"{api}/deployments/filter", json={"limit": 10}, timeout=10).json()
        ours = [d for d in deployments if d["name"] == "test-nightly"]
        assert ours and ours[0]["schedules"][0]["schedule"]["cron"] == cron
        scheduled = [r for r in runs if r["deployment_id"] == ours[0]["id"] and r["auto_scheduled"]]
        assert scheduled, runs

        # and the run goes on to refresh the report
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (wh / "reports" / "report.html").exists():
            time.sleep(2)
        assert (wh / "reports" / "report.html").exists(), (tmp_path / "serve.log").read_text()[-3000:]
    finally:
        stop(serve)
        stop(server)
        for fh in logs.values():
            fh.close()

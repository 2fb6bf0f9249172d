"""Ctrl-C stops `valvemon query` (the snapshot and `--live`): a cross join that would run for hours
gets SIGINT once it is running, the command exits with 130 without a result or a message, and a
writer gets the warehouse right after (an ingest runs).

Before: the query ran on after SIGINT (20 s in the issue, until kill -9) or ended as "unexpected
RuntimeError: Query interrupted" with status 1, and a `--live` reader keeps writers out. No timing
is asserted: the child's CPU time says the query is running, then only the outcome is checked.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.ingest.conftest import DATA, ingest, table, write_plant

ROOT = Path(__file__).resolve().parents[2]
CROSS_JOIN = "SELECT count(*) FROM ingest_manifest, range(100000000) a, range(100000000) b WHERE (7 * a.range + b.range) % 1000003 = 1"
"""10^16 pairs, no join condition to plan around: never ends by itself."""


def _cpu_s(pid: int) -> float:
    """CPU time of a process so far (user + system, all threads). [s]"""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _interrupted_query(wh: Path, live: bool) -> tuple[int, str, str]:
    """Run the cross join in a child `valvemon query`, SIGINT it once it runs: (status, stdout, stderr)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")} | {"PYTHONPATH": str(ROOT)}
    args = ["query", CROSS_JOIN, "--warehouse", str(wh), *(["--live"] if live else [])]
    child = subprocess.Popen([sys.executable, "-c", "from flows.cli import main; main()", *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while child.poll() is None and _cpu_s(child.pid) < 2.0 and time.monotonic() < deadline:  # started in ~1 s, then the join's threads
            time.sleep(0.05)
        assert child.poll() is None, child.stderr.read()  # the join is running
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=60)  # a generous bound: the property is that it ends at all
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    return child.returncode, out, err


def test_ctrl_c_stops_a_running_query_with_130_and_frees_the_warehouse(tmp_path):
    from flows.report.publish import publish

    cfg, wh = write_plant(tmp_path), tmp_path / "wh"
    ingest(cfg, DATA / "base_long.csv", wh)
    publish(cfg, wh)  # the snapshot the query reads
    for live in (False, True):
        assert _interrupted_query(wh, live) == (130, "", ""), live  # no result, no message
    wide = write_plant(tmp_path, "wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    ingest(wide, DATA / "base_wide.csv", wh)  # a writer gets the warehouse at once
    assert table(wh, "ingest_manifest").height == 2

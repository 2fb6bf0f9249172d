"""A closed pipe on standard output after the work is done (`valvemon ... | head -1`) exits 0
silently, and the work stands (issue 46, item 7): `ingest`, `monitor`, `query` and
`retention --dry-run --list` run as the installed command with their standard output a pipe
whose reading end is already closed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import tomli_w
import tomllib

from tests.ingest.conftest import DATA, lake, table, write_plant

ROOT = Path(__file__).resolve().parents[1]


def _closed_pipe(args: list[str], tmp_path: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API") and k != "PYTHONUNBUFFERED"}
    env |= {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp_path / "prefect-home")}
    read, write = os.pipe()
    os.close(read)  # `head -1` has read its line and gone
    try:
        cmd = [sys.executable, "-c", "from flows.cli import console; console()", *args]
        return subprocess.run(cmd, env=env, stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)


def test_a_closed_pipe_after_the_work_exits_0_silently(tmp_path):
    cfg = write_plant(tmp_path)
    raw = tomllib.loads(cfg.read_text()) | {"retention": {"keep_days": 1, "mode": "drop"}}
    cfg.write_text(tomli_w.dumps(raw))
    wh = str(tmp_path / "wh")
    ingest = _closed_pipe(["ingest", "--config", str(cfg), "--warehouse", wh, str(DATA / "base_long.csv")], tmp_path)
    assert (ingest.returncode, ingest.stderr) == (0, "")
    assert lake(Path(wh)).height == 5  # the work stands
    for args in (
        ["monitor", "--config", str(cfg)],
        ["query", "SELECT * FROM range(100000)"],
        ["query", "SELECT 1 AS a", "--format", "csv"],
        ["retention", "--config", str(cfg), "--dry-run", "--list", "--as-of", "2025-03-02"],
    ):
        r = _closed_pipe([*args, "--warehouse", wh], tmp_path)
        assert (r.returncode, r.stderr) == (0, ""), args
    assert table(Path(wh), "ingest_manifest").height == 1  # marked ingested: a rerun skips it

"""`valvemon --help` and `valvemon query` load only what they need: no Prefect, no numba kernels,
no matplotlib, no pandera, no scipy (issue 15: each costs a command seconds of start-up)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import duckdb
import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("prefect", "numba", "matplotlib", "pandera", "pandas", "scipy", "transforms", "model")

_RUN = textwrap.dedent("""
    import json, sys
    from flows.cli import main
    sys.argv = ["valvemon", *sys.argv[1:]]
    try:
        main()
    except SystemExit as exc:
        code = exc.code
    else:
        code = 0
    print(json.dumps({"code": code, "modules": sorted({m.split(".")[0] for m in sys.modules})}), file=sys.stderr)
""")


def _loaded(args: list[str], tmp_path: Path) -> tuple[int, set[str], str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")}
    env |= {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp_path / "prefect-home")}
    proc = subprocess.run([sys.executable, "-c", _RUN, *args], env=env, capture_output=True, text=True, timeout=120)
    import json

    report = json.loads(proc.stderr.strip().splitlines()[-1])
    return report["code"], set(report["modules"]), proc.stdout


@pytest.mark.parametrize("args", [["--help"], ["query", "--help"], ["monitor", "--help"]])
def test_help_loads_nothing_heavy(args, tmp_path):
    code, modules, out = _loaded(args, tmp_path)
    assert code == 0 and "Usage: valvemon" in out
    assert modules.isdisjoint(HEAVY), sorted(modules & set(HEAVY))
    assert "polars" not in modules and "duckdb" not in modules


def test_query_loads_nothing_heavy(tmp_path):
    snapshot = tmp_path / "wh" / "snapshot"
    snapshot.mkdir(parents=True)
    con = duckdb.connect(str(snapshot / "valvemon.duckdb"))
    con.execute("CREATE TABLE edge_fits AS SELECT 1 AS n")
    con.close()
    code, modules, out = _loaded(["query", "SELECT n FROM edge_fits", "--format", "csv", "--warehouse", str(tmp_path / "wh")], tmp_path)
    assert code == 0 and out.split() == ["n", "1"]
    assert modules.isdisjoint(HEAVY), sorted(modules & set(HEAVY))

"""`valvemon query` never writes (issue 18, item 1): on a warehouse holding one ingested day,
every statement that reaches the file system or the session's safety is refused with one line
on stderr and exit 1, and every file of the warehouse is byte-identical afterwards; reading the
lake's Parquet and the views still works. Through the real command line, in subprocesses (the
refused statements one after the other in one)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import duckdb
import pytest

from flows.common.errors import ValvemonError
from flows.report.query import check_read_only
from flows.simulate.archive import DEFAULT_COMMISSIONED, SimulateRequest, run_simulate
from tests.report.commands import run_each

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def warehouse(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    tmp = tmp_path_factory.mktemp("query_safety")
    archive, wh = tmp / "sim", tmp / "wh"
    run_simulate(SimulateRequest(out=archive, n_valves=1, start=DEFAULT_COMMISSIONED.isoformat(), days=1.0, windows_per_day=1,
                                 window_s=5.0, format="parquet", seed=3, workers=0), show_progress=False)  # fmt: skip
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")}
    env |= {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp / "prefect-home")}
    _run(["ingest", "--config", str(archive / "plant.toml"), "--warehouse", str(wh), str(archive / "exports")], env, ok=True)
    return wh, env


def _run(args: list[str], env: dict[str, str], *, ok: bool) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-c", "from flows.cli import main; main()", *args], env=env, capture_output=True, text=True, timeout=300)
    assert (proc.returncode == 0) == ok, proc.stderr
    return proc



def _files(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*")) if p.is_file()}


def _partition(wh: Path) -> Path:
    (part,) = sorted((wh / "lake").rglob("*.parquet"))
    return part


REFUSED = [
    "copy (select 1 as x) to '{part}' (format parquet)",
    "COPY sensors_dummy FROM '{part}'",
    "explain analyze copy (select 1 as x) to '{part}' (format parquet)",
    "select 1; copy (select 1 as x) to '{part}' (format parquet)",
    "export database '{wh}/dump'",
    "attach '{wh}/other.duckdb' as other",
    "install httpfs",
    "load httpfs",
    "set enable_external_access = true",
    "drop table edge_fits",
    "delete from ingest_manifest",
    "create table t as select 1",
    "select * from read_csv('/etc/passwd')",
    "select * from read_text('{wh}/valvemon.duckdb')",
]


@pytest.mark.slow
@pytest.mark.xdist_group("query_safety_warehouse")  # one worker builds the shared `warehouse` once
@pytest.mark.parametrize("live", [False, True], ids=["snapshot", "live"])
def test_a_query_refuses_every_write_and_leaves_every_file_unchanged(warehouse, live):
    wh, env = warehouse
    part = _partition(wh)
    before = _files(wh)
    sqls = [template.format(part=part, wh=wh) for template in REFUSED]
    done = run_each([["query", sql, "--warehouse", str(wh), *(["--live"] if live else [])] for sql in sqls], env)
    for sql, (code, stdout, stderr) in zip(sqls, done, strict=True):
        assert code == 1, (sql, stderr)
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("valvemon: error: query "), (sql, stderr)
        assert stdout == ""
    assert _files(wh) == before  # the partition still holds its rows, no file appeared or changed


@pytest.mark.slow
@pytest.mark.xdist_group("query_safety_warehouse")
def test_the_lake_and_the_views_stay_readable(warehouse):
    wh, env = warehouse
    rows = duckdb.sql(f"select count(*) from read_parquet('{_partition(wh)}')").fetchall()[0][0]
    assert rows > 1000
    lake_sql = f"select count(*) from read_parquet('{wh}/lake/sensors/**/*.parquet', hive_partitioning = true)"
    assert _run(["query", lake_sql, "--format", "csv", "--warehouse", str(wh)], env, ok=True).stdout.split() == ["count_star()", str(rows)]
    out = _run(["query", "explain select * from ingest_manifest", "--format", "json", "--warehouse", str(wh), "--live"], env, ok=True)
    assert "ingest_manifest" in json.loads(out.stdout)[0]["explain_value"]
    assert _run(["query", "select count(*) from ingest_manifest", "--format", "csv", "--warehouse", str(wh)], env, ok=True).stdout.split()[1] == "1"


@pytest.mark.parametrize(
    "sql",
    ["select 1", "with a as (select 1 x) select * from a", "from range(3)", "describe select 1", "summarize select 1",
     "show tables", "EXPLAIN select 1", "explain (format json) select 1", "explain analyze select 1"],
)  # fmt: skip
def test_selects_and_their_explains_pass_the_check(sql):
    check_read_only(sql)


@pytest.mark.parametrize("template", REFUSED[:10] + ["explain (format json) copy (select 1) to 'x.csv'", "pragma threads = 1", "call pragma_version()", ""])
def test_everything_else_is_refused_before_it_runs(template):
    with pytest.raises(ValvemonError, match="query refused"):
        check_read_only(template.format(part="p.parquet", wh="w"))

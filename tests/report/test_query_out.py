"""``valvemon query --out`` never writes into the warehouse (issue 46, item 1): a path inside the
warehouse folder (the live database, the snapshot, a lake file; through a symlink too) is refused
with one line and exit 1 whatever ``--force`` says, an existing file elsewhere only with ``--force``,
and afterwards every file of the warehouse is byte-identical and still answers queries."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pytest

from tests.ingest.conftest import DATA, run_cli, write_plant


def _files(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def lake_wh(tmp_path, monkeypatch, capsys) -> Path:
    cfg = write_plant(tmp_path)
    wh = tmp_path / "wh"
    code, _, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(wh), str(DATA / "base_long.csv")], monkeypatch, capsys)
    assert code == 0, err
    return wh


def _targets(wh: Path, tmp_path: Path) -> list[Path]:
    (part,) = sorted((wh / "lake").rglob("*.parquet"))
    link = tmp_path / "innocent.parquet"
    link.symlink_to(wh / "valvemon.duckdb")
    folder_link = tmp_path / "whlink"
    folder_link.symlink_to(wh)
    return [wh / "valvemon.duckdb", wh / "snapshot" / "valvemon.duckdb", part, link, folder_link / "new.parquet", wh / "new.csv"]


@pytest.mark.parametrize("fmt", ["parquet", "csv", "table"])
def test_out_inside_the_warehouse_is_refused_even_with_force(lake_wh, tmp_path, monkeypatch, capsys, fmt):
    wh = lake_wh
    before = _files(wh)
    for target in _targets(wh, tmp_path):
        for force in ([], ["--force"]):
            args = ["query", "SELECT 1 AS a", "--warehouse", str(wh), "--format", fmt, "--out", str(target), *force]
            code, out, err = run_cli(args, monkeypatch, capsys)
            assert code == 1, (target, err)
            assert err.count("\n") == 1 and err.startswith(f"valvemon: error: --out {target}: ") and "inside the warehouse" in err, err
    assert _files(wh) == before
    code, out, err = run_cli(["query", "SELECT count(*) AS n FROM read_parquet('" + str(wh) + "/lake/sensors/**/*.parquet')",
                              "--warehouse", str(wh), "--format", "csv"], monkeypatch, capsys)  # fmt: skip
    assert code == 0 and out.splitlines() == ["n", "5"], err


def test_an_existing_file_needs_force(lake_wh, tmp_path, monkeypatch, capsys):
    wh = lake_wh
    target = tmp_path / "result.csv"
    target.write_text("precious\n")
    args = ["query", "SELECT 1 AS a", "--warehouse", str(wh), "--format", "csv", "--out", str(target)]
    code, _, err = run_cli(args, monkeypatch, capsys)
    assert code == 1 and "exists" in err and "--force" in err and err.count("\n") == 1, err
    assert target.read_text() == "precious\n"
    code, _, err = run_cli([*args, "--force"], monkeypatch, capsys)
    assert code == 0, err
    assert target.read_text() == "a\n1\n"


def test_force_replaces_a_hard_link_without_writing_through_it(lake_wh, tmp_path, monkeypatch, capsys):
    """An existing file outside the warehouse that is a hard link of the live database: ``--force``
    replaces the name, never the database's bytes."""
    wh = lake_wh
    db = wh / "valvemon.duckdb"
    before = _files(wh)
    target = tmp_path / "alias.duckdb"
    os.link(db, target)
    code, _, err = run_cli(["query", "SELECT 1 AS a", "--warehouse", str(wh), "--format", "csv", "--out", str(target), "--force"],
                           monkeypatch, capsys)  # fmt: skip
    assert code == 0, err
    assert target.read_text() == "a\n1\n" and _files(wh) == before

"""``valvemon ingest``: exit status, the summary on stdout, one line on stderr; the Prefect flow.

Without a Prefect API the command runs the flow's function directly (no server); two tests run
the real flow on the session's Prefect test server.
"""

from __future__ import annotations

import gzip

import pytest
from polars.testing import assert_frame_equal

from tests.ingest.conftest import DATA, base_lake, lake, run_cli, table


def test_success_prints_the_counts(plant, tmp_path, monkeypatch, capsys):
    cfg, _ = plant()
    wh = tmp_path / "wh"
    code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(wh), str(DATA / "duplicates.csv")], monkeypatch, capsys)
    assert code == 0 and err == ""
    assert out.strip() == (
        "ingested 1 of 1 files: 21 rows read, 3 lake rows written (3 new) in 1 partitions, "
        "0 quarantined, 2 duplicates, 1 conflicts, 0 gaps"
    )
    code, out, _ = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(wh), str(DATA / "duplicates.csv")], monkeypatch, capsys)
    assert code == 0 and "(1 already ingested, skipped)" in out


def test_warehouse_from_the_environment(plant, tmp_path, monkeypatch, capsys):
    cfg, _ = plant()
    monkeypatch.setenv("VALVEMON_WAREHOUSE", str(tmp_path / "envwh"))
    code, _, _ = run_cli(["ingest", "--config", str(cfg), str(DATA / "base_long.csv")], monkeypatch, capsys)
    assert code == 0
    assert_frame_equal(lake(tmp_path / "envwh"), base_lake())


@pytest.mark.parametrize(
    "make, expected",
    [
        (lambda d: DATA / "unknown_tag.csv", "line 4: unknown tag 'MILL1.V099.P1'"),
        (lambda d: DATA / "missing_signal.csv", "required signal x_cyl (tag MILL1.V017.XC) is missing"),
        (lambda d: _write(d / "empty.csv", b""), "empty file"),
        (lambda d: _write(d / "cut.csv.gz", gzip.compress((DATA / "base_long.csv").read_bytes())[:200]), "truncated or corrupt gzip file"),
        (lambda d: DATA / "not_really.parquet", "not a readable Parquet export"),
        (lambda d: d / "missing.csv", "no such file or folder"),
        (lambda d: DATA / "dst_spring.csv", "line 8: tag MILL1.V017.PS: local time 2025-03-30 02:30:00 does not exist"),
    ],
)
def test_errors_are_one_line_with_exit_status_1(plant, tmp_path, monkeypatch, capsys, make, expected):
    cfg, _ = plant(other_tags="error")
    path = make(tmp_path)
    code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(tmp_path / "wh"), str(path)], monkeypatch, capsys)
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"valvemon: error: {path}: ")
    assert expected in err


def test_configuration_error_is_one_line(tmp_path, monkeypatch, capsys):
    bad = tmp_path / "plant.toml"
    bad.write_text("[plant]\nname = 'X'\n")
    code, _, err = run_cli(["ingest", "--config", str(bad), str(DATA / "base_long.csv")], monkeypatch, capsys)
    assert code == 1 and err.count("\n") == 1 and err.startswith(f"valvemon: error: {bad}: ")


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


# --- the real Prefect flow (session test server) --------------------------------------------


def test_cli_runs_the_prefect_flow(prefect_server, plant, tmp_path, monkeypatch, capsys):
    cfg, _ = plant()
    wh = tmp_path / "wh"
    code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(wh), str(DATA / "base_long.csv"), str(DATA / "out_of_order.csv")], monkeypatch, capsys)
    assert code == 0, err
    assert out.startswith("ingested 2 of 2 files: 60 rows read, 10 lake rows written (5 new)")
    assert_frame_equal(lake(wh), base_lake())
    assert table(wh, "ingest_runs")["status"].to_list() == ["ok"]


def test_a_failing_flow_still_gives_one_line(prefect_server, plant, tmp_path, monkeypatch, capsys):
    cfg, _ = plant(other_tags="error")
    code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(tmp_path / "wh"), str(DATA / "unknown_tag.csv")], monkeypatch, capsys)
    assert code == 1
    assert err == f"valvemon: error: {DATA / 'unknown_tag.csv'}: line 4: unknown tag 'MILL1.V099.P1': no valve of the plant configuration has it\n"

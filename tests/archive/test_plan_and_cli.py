"""The window grid, the option checks and the command line."""

from __future__ import annotations

import os
import subprocess
import sys
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from flows.common.errors import ValvemonError
from flows.simulate.archive import ArchivePlan, SimulateRequest, parse_hours, plan_request

UTC = timezone.utc
VALVEMON = str(Path(sys.executable).parent / "valvemon")


def test_window_grid_per_utc_day():
    plan = ArchivePlan(datetime(2025, 1, 1, 5, tzinfo=UTC), datetime(2025, 1, 3, 5, tzinfo=UTC), windows_per_day=3, window_s=10)
    days = list(plan.days())
    assert [d.isoformat() for d, _ in days] == ["2025-01-01", "2025-01-02", "2025-01-03"]
    first = days[0][1]
    as_dt = [datetime.fromtimestamp(s / 1e6, UTC) for s in first]
    assert as_dt == [datetime(2025, 1, 1, 8, tzinfo=UTC), datetime(2025, 1, 1, 16, tzinfo=UTC)]
    assert days[2][1].size == 1 and plan.n_slots() == 2 + 3 + 1
    # slots fall on the sample grid even when 24 h / windows_per_day does not
    odd = ArchivePlan(datetime(2025, 1, 1, tzinfo=UTC), datetime(2025, 1, 2, tzinfo=UTC), windows_per_day=7, window_s=1)
    (_, starts), = odd.days()
    assert np.all(starts % 1000 == 0) and starts.size == 7


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"windows_per_day": 0}, "--windows-per-day"),
        ({"window_s": 7200.0, "windows_per_day": 24}, "overlap"),
        ({"window_s": 0.0005}, "whole number"),
        ({"sample_rate_hz": 3000.0}, "microseconds"),
    ],
)
def test_bad_plans(kw, match):
    with pytest.raises(ValvemonError, match=match):
        ArchivePlan(datetime(2025, 1, 1, tzinfo=UTC), datetime(2025, 1, 2, tzinfo=UTC), **kw)


def test_hours_and_dates(tmp_path):
    cfg, plan, scen, fmt = plan_request(SimulateRequest(out=tmp_path, hours="700:724", n_valves=2, scenarios=("wear", "V002=healthy")))
    assert plan.start == datetime(2025, 1, 1, tzinfo=UTC) + timedelta(hours=700)
    assert plan.end - plan.start == timedelta(hours=24)
    assert scen == {"V001": "wear", "V002": "healthy"} and fmt == "csv"
    _, plan, _, fmt = plan_request(SimulateRequest(out=tmp_path, start="2025-02-01", days=2.5, format="parquet"))
    assert plan.end == datetime(2025, 2, 3, 12, tzinfo=UTC) and fmt == "parquet"
    assert parse_hours("100") == (0.0, 100.0)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"format": "xml"}, "--format"),
        ({"gzip": True, "format": "parquet"}, "--gzip"),
        ({"hours": "5:1"}, "--hours"),
        ({"hours": "10", "start": "2025-01-01"}, "--hours"),
        ({"scenarios": ("V007=wear",)}, "V007"),
        ({"scenarios": ("rust",)}, "unknown scenario"),
        ({"config_path": Path("tests/fixtures/plant_example.toml"), "n_valves": 3}, "--n-valves"),
        ({"config_path": Path("tests/fixtures/plant_example.toml"), "format": "wide"}, "export.layout"),
        ({"start": "yesterday"}, "--from"),
        ({"n_valves": 0}, "--valves"),
        ({"recording": "always"}, "--recording"),
        ({"recording": "continuous", "window_s": 5.0}, "--window-s"),
        ({"recording": "continuous", "windows_per_day": 2}, "--windows-per-day"),
        ({"segment_s": 7.0}, "--segment-s"),
        ({"segment_s": 0.5}, "--segment-s"),
        ({"file_minutes": 7.0}, "--file-minutes"),
        ({"file_minutes": 0.5}, "--file-minutes"),
    ],
)
def test_bad_options(tmp_path, kw, match):
    with pytest.raises(ValvemonError, match=match):
        plan_request(SimulateRequest(out=tmp_path, **kw))


def _run(*args, cwd):
    env = dict(os.environ, COLUMNS="200")
    return subprocess.run([VALVEMON, "simulate", *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=120)


def test_cli_writes_an_archive(tmp_path):
    r = _run(
        "--out", str(tmp_path / "arch"), "--n-valves", "2", "--hours", "0:30", "--windows-per-day", "2", "--window-s", "0.5",
        "--scenario", "wear", "--scenario", "V002=broken_edge@10", "--format", "wide", "--gzip", "--seed", "4", "--quiet",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "wrote 2 export files" in r.stdout
    names = sorted(p.name for p in (tmp_path / "arch" / "exports").iterdir())
    assert names == ["SIM1_2025-01-01.csv.gz", "SIM1_2025-01-02.csv.gz"]
    assert (tmp_path / "arch" / "plant.toml").is_file() and (tmp_path / "arch" / "truth.parquet").is_file()
    assert 'scenario = "broken_edge@10"' in (tmp_path / "arch" / "plant.toml").read_text()


def test_cli_continuous_recording(tmp_path, monkeypatch, capsys):
    """``--recording continuous`` through the entry point: 90 s back to back from 00:59:00 in
    1-minute files named by their first sample, the truth per 60 s segment."""
    import polars as pl

    from flows.cli import main

    out = tmp_path / "rec"
    argv = ["valvemon", "simulate", "--out", str(out), "--n-valves", "1", "--recording", "continuous", "--from", "2025-01-01T00:59:00Z",
            "--to", "2025-01-01T01:00:30Z", "--file-minutes", "1", "--format", "parquet", "--quiet", "--workers", "0"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 0
    assert "2 valve segments (90 valve-s)" in capsys.readouterr().out
    names = sorted(p.name for p in (out / "exports").iterdir())
    assert names == ["SIM1_20250101T005900.parquet", "SIM1_20250101T010000.parquet"]
    truth = pl.read_parquet(out / "truth.parquet")
    assert truth.height == 2 * 4 and sorted(set((truth["window_end"] - truth["window_start"]).dt.total_seconds())) == [30, 60]


@pytest.mark.parametrize(
    "args, match",
    [
        (["--format", "xml"], "--format"),
        (["--scenario", "V009=wear"], "V009"),
        (["--window-s", "-1"], "--window-s"),
        (["--config", "nope.toml"], "nope.toml"),
        (["--from", "2024-12-31"], "commissioning"),
        (["--existing"], "--overwrite"),
    ],
)
def test_cli_bad_option_one_line(tmp_path, monkeypatch, capsys, args, match):
    """In-process through the entry point ``flows.cli:main`` (the subprocess test above covers
    the installed script)."""
    from flows.cli import main

    out = tmp_path / "x"
    if args == ["--existing"]:  # an archive already in --out, no --overwrite
        (out / "exports").mkdir(parents=True)
        args = []
    monkeypatch.setattr(sys, "argv", ["valvemon", "simulate", "--out", str(out), "--quiet", *args])
    with pytest.raises(SystemExit) as exc:
        main()
    err = capsys.readouterr().err
    assert exc.value.code != 0
    assert err.startswith("valvemon: error: ") and err.count("\n") == 1 and match in err, err
    assert not (out / "plant.toml").exists()

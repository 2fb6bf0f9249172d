"""``valvemon retention``: the summary, --dry-run, --list, retention off, one-line errors.

Without a Prefect API the command runs the flow's function (flows.common.prefect_run), no server."""

from __future__ import annotations

from datetime import date, datetime, timezone

import pytest

from flows.common.lake import partition_folders
from flows.common.warehouse_db import connect
from flows.retention.flow import latest_today
from schemas.plant_config import RetentionSpec
from tests.ingest.conftest import run_cli
from tests.retention.conftest import write_config

pytestmark = pytest.mark.xdist_group("retention_base")  # one worker builds the shared `base` once


def _cli(args, wh, cfg, monkeypatch, capsys):
    return run_cli(["retention", "--config", str(cfg), "--warehouse", str(wh), *args], monkeypatch, capsys)


def test_dry_run_prints_the_summary_and_changes_nothing(base, wh, tmp_path, monkeypatch, capsys):
    cfg = write_config(base[1] / "plant.toml", tmp_path / "plant.toml", RetentionSpec(keep_days=3, mode="drop"))
    parts = partition_folders(wh)
    code, out, err = _cli(["--dry-run", "--as-of", "2025-01-07", "--list"], wh, cfg, monkeypatch, capsys)
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert "V001 2025-01-01  keep  kept: commissioning window" in lines
    assert any(line.startswith("V002 2025-01-03  drop  drop: fitted, checked and older than 3 days  rows 60,000 -> 0") for line in lines)
    assert "retention as of 2025-01-07 (keep_days 3, mode drop): DRY RUN, nothing changed" in lines
    assert any(line.split()[:2] == ["drop", "5"] for line in lines)
    assert any(line.split()[:2] == ["keep", "2"] and "kept: within 3 days" in line for line in lines)
    assert lines[-1].startswith("would free ")
    today = datetime.now(timezone.utc).date()
    age = (today - date(2025, 1, 1)).days
    assert f"  oldest data it would touch: V002 2025-01-01, {age:,} days old today ({today}); newest V001 2025-01-03, {age - 2:,} days old" in lines
    assert partition_folders(wh) == parts
    code, out, _ = _cli(["--as-of", "2025-01-07"], wh, cfg, monkeypatch, capsys)
    assert code == 0 and out.splitlines()[-1].startswith("freed ") and len(partition_folders(wh)) == 3


def test_retention_off_deletes_nothing(base, wh, tmp_path, monkeypatch, capsys):
    cfg = write_config(base[1] / "plant.toml", tmp_path / "plant.toml", None)
    code, out, _ = _cli(["--as-of", "2030-01-01"], wh, cfg, monkeypatch, capsys)
    assert code == 0 and "no [retention] table: retention is off, nothing is deleted" in out
    assert len(partition_folders(wh)) == 8


@pytest.mark.parametrize(
    "args, message",
    [
        (["--as-of", "7.1.2025"], "valvemon: error: --as-of: '7.1.2025' is not an ISO date (YYYY-MM-DD)"),
        (["--valves", "V009"], "valvemon: error: --valves: no valve 'V009' in plant"),
    ],
)
def test_errors_are_one_line(base, wh, tmp_path, monkeypatch, capsys, args, message):
    cfg = write_config(base[1] / "plant.toml", tmp_path / "plant.toml", RetentionSpec(keep_days=3))
    code, out, err = _cli(args, wh, cfg, monkeypatch, capsys)
    assert code == 1 and err.startswith(message) and len(err.strip().splitlines()) == 1


def test_an_as_of_in_the_future_is_refused_unless_forced(base, wh, tmp_path, monkeypatch, capsys):
    """The issue's typo: --as-of 2099-01-01 with keep_days 1000 dropped data 694 days old."""
    cfg = write_config(base[1] / "plant.toml", tmp_path / "plant.toml", RetentionSpec(keep_days=1000, mode="drop"))
    parts = partition_folders(wh)
    code, out, err = _cli(["--as-of", "2099-01-01"], wh, cfg, monkeypatch, capsys)
    today = latest_today(datetime.now(timezone.utc))  # today in the zone furthest ahead (the nightly run's as-of is the plant's local today)
    assert code == 1 and out == "" and err == f"valvemon: error: --as-of 2099-01-01 is later than today ({today}): data would count as older than it is; give --force if that is meant\n"
    assert partition_folders(wh) == parts
    code, out, _ = _cli(["--as-of", "2099-01-01", "--dry-run"], wh, cfg, monkeypatch, capsys)  # a dry run only reports
    assert code == 0 and "DRY RUN" in out and partition_folders(wh) == parts
    code, out, _ = _cli(["--as-of", "2099-01-01", "--force"], wh, cfg, monkeypatch, capsys)
    assert code == 0 and [(v, d) for v, d, _ in partition_folders(wh)] == [("V001", date(2025, 1, 1))]  # all but the commissioning day


def test_an_as_of_long_after_the_latest_ingest_is_refused(base, wh, tmp_path, monkeypatch, capsys):
    """A machine whose clock runs ahead: the latest ingest, not only today, bounds --as-of."""
    cfg = write_config(base[1] / "plant.toml", tmp_path / "plant.toml", RetentionSpec(keep_days=3, mode="drop"))
    with connect(wh) as con:
        con.execute("UPDATE ingest_manifest SET ingested_at = '2025-01-05T12:00:00Z'")
    parts = partition_folders(wh)
    code, _, err = _cli(["--as-of", "2025-01-07"], wh, cfg, monkeypatch, capsys)
    assert code == 1 and "--as-of 2025-01-07 is more than a day after the latest ingest (2025-01-05 12:00 UTC)" in err
    assert partition_folders(wh) == parts
    code, _, _ = _cli(["--as-of", "2025-01-06"], wh, cfg, monkeypatch, capsys)
    assert code == 0 and len(partition_folders(wh)) < len(parts)

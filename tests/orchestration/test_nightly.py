"""The nightly flow without a schedule: which day, late exports, the report step, serve's checks."""

from __future__ import annotations

import shutil
from datetime import date, datetime, timezone

import pytest
from typer.testing import CliRunner

import flows.orchestration.nightly as nightly
from flows.cli import app
from flows.common.errors import ValvemonError
from tests.orchestration.conftest import table

UTC = timezone.utc


def test_previous_day_in_the_schedules_time_zone():
    # 02:30 in Vienna (CEST, UTC+2) on 2025-07-10 → 2025-07-09 00:00–24:00 local
    day, start, end = nightly.previous_day(datetime(2025, 7, 10, 0, 30, tzinfo=UTC), "Europe/Vienna")
    assert day == date(2025, 7, 9)
    assert (start, end) == (datetime(2025, 7, 8, 22, tzinfo=UTC), datetime(2025, 7, 9, 22, tzinfo=UTC))
    # the night after the switch to winter time: a 25-hour day
    day, start, end = nightly.previous_day(datetime(2025, 10, 27, 1, 30, tzinfo=UTC), "Europe/Vienna")
    assert day == date(2025, 10, 26) and (end - start).total_seconds() == 25 * 3600
    # in UTC the previous day is the UTC date before
    assert nightly.previous_day(datetime(2025, 1, 2, 0, 0, 1, tzinfo=UTC), "UTC")[0] == date(2025, 1, 1)
    with pytest.raises(ValvemonError, match="not an IANA time zone"):
        nightly.previous_day(datetime(2025, 1, 1, tzinfo=UTC), "Mars/Olympus")


def test_nightly_ingests_the_inbox_and_monitors_the_day_and_late_files(prefect_server, archive, tmp_path, monkeypatch):
    """Night of 2025-01-03: the inbox holds the 2nd day; the 1st day's file arrives a night late."""
    inbox, wh = tmp_path / "inbox", tmp_path / "wh"
    inbox.mkdir()
    shutil.copy2(archive / "exports" / "SIM1_2025-01-02.parquet", inbox)
    reports = []
    monkeypatch.setattr(nightly, "refresh_report", lambda config_path, warehouse: reports.append(warehouse) or "report.html")
    kw = dict(config_path=str(archive / "plant.toml"), exports=str(inbox), warehouse=str(wh), timezone_name="UTC")
    out = nightly.nightly_flow(**kw, day="2025-01-02")
    assert out["day"] == "2025-01-02" and reports == [str(wh)]
    fits = table(wh, "edge_fits")
    assert fits.height == 2 * 4 * 4 and fits["window_start"].dt.date().unique().to_list() == [date(2025, 1, 2)]
    # next night (2025-01-03 has no file yet); the late file of 2025-01-01 is monitored too
    shutil.copy2(archive / "exports" / "SIM1_2025-01-01.parquet", inbox)
    out = nightly.nightly_flow(**kw, day="2025-01-03")
    assert "files: 1 ingested, 1 already in the manifest" in out["summary"]
    fits = table(wh, "edge_fits")
    assert sorted(fits["window_start"].dt.date().unique().to_list()) == [date(2025, 1, 1), date(2025, 1, 2)]
    assert fits.height == 2 * 2 * 4 * 4
    runs = table(wh, "backfill_runs")
    assert runs["kind"].to_list() == ["nightly", "nightly"] and runs["status"].to_list() == ["ok", "ok"]


def test_serve_needs_a_prefect_server(archive, tmp_path):
    from prefect.settings import PREFECT_API_URL, temporary_settings

    runner = CliRunner()
    args = ["serve", "--config", str(archive / "plant.toml"), "--exports", str(archive / "exports"), "--warehouse", str(tmp_path)]
    with temporary_settings(updates={PREFECT_API_URL: None}):
        res = runner.invoke(app, args)
    assert res.exit_code != 0 and "needs a Prefect server" in str(res.exception)
    with temporary_settings(updates={PREFECT_API_URL: "http://127.0.0.1:9/api"}):  # nothing listens on port 9
        res = runner.invoke(app, args)
    assert "does not answer" in str(res.exception)
    with temporary_settings(updates={PREFECT_API_URL: "http://127.0.0.1:9/api"}):
        res = runner.invoke(app, [*args, "--timezone", "Nowhere/City"])
    assert "not an IANA time zone" in str(res.exception)
    res = runner.invoke(app, [*args[:3], "--exports", str(tmp_path / "missing"), "--warehouse", str(tmp_path)])
    assert "no such folder" in str(res.exception)


def test_backfill_command_checks_its_options(archive, tmp_path, monkeypatch):
    import functools

    import flows.orchestration.dask_runner as dask_runner

    # nothing listens on port 9: the client retries until its timeout (10 s by default, 1 s here)
    monkeypatch.setattr(dask_runner, "cluster_threads", functools.partial(dask_runner.cluster_threads, timeout_s=1.0))
    runner = CliRunner()
    base = ["backfill", "--config", str(archive / "plant.toml"), "--warehouse", str(tmp_path)]
    res = runner.invoke(app, [*base, "--from", "2025-01-01", "--to", "2025-01-02", "--dask-address", "tcp://x:1", "--dask-workers", "2"])
    assert "exclude each other" in str(res.exception)
    res = runner.invoke(app, [*base, "--from", "2025-01-01", "--to", "2025-01-02", "--dask-address", "tcp://127.0.0.1:9"])
    assert "cannot reach the Dask scheduler" in str(res.exception)


@pytest.mark.slow
def test_nightly_applies_retention_after_monitoring_and_the_report(prefect_server, archive, tmp_path, monkeypatch):
    """keep_days 1, drop: the night after 2025-01-03 drops the two older days, which are fitted and
    were read by the standstill check of the report step (here only that part of the report)."""
    import dataclasses

    import tomli_w

    from flows.common.config import load_plant_config
    from flows.common.lake import partition_folders
    from flows.report.flow import update_standstill
    from schemas.plant_config import RetentionSpec, plant_config_to_dict

    config = dataclasses.replace(load_plant_config(archive / "plant.toml"), retention=RetentionSpec(keep_days=1, mode="drop"))
    cfg = tmp_path / "plant.toml"
    cfg.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    wh = tmp_path / "wh"
    steps = []

    def report_step(config_path, warehouse):
        steps.append("report")
        update_standstill(load_plant_config(config_path), wh, datetime.now(UTC))
        return "report.html"

    monkeypatch.setattr(nightly, "refresh_report", report_step)
    out = nightly.nightly_flow(config_path=str(cfg), exports=str(archive / "exports"), warehouse=str(wh), timezone_name="UTC", day="2025-01-03")
    assert steps == ["report"] and out["retention"].startswith("freed ")
    assert sorted({d for _, d, _ in partition_folders(wh)}) == [date(2025, 1, 3)]
    log = table(wh, "retention_log")
    assert sorted(zip(log["valve_id"], log["date"])) == [(v, date(2025, 1, d)) for v in ("V001", "V002") for d in (1, 2)]
    assert set(log["as_of"]) == {date(2025, 1, 4)} and set(log["action"]) == {"drop"}
    assert table(wh, "edge_fits").height == 2 * 3 * 4 * 4  # the fits of the dropped days stay

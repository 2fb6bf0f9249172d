"""Recording a run and sending its message against loopback receivers, on a warehouse whose
conditions are written by hand (no simulation): a night without change, the mail login with the
password from the environment, a receiver that refuses, and what the table keeps."""

from __future__ import annotations

import dataclasses
import tomllib
from datetime import datetime, timedelta, timezone
from pathlib import Path

import polars as pl
import pytest

import flows.notify.channels as channels
from flows.common.warehouse_db import connect, query_frame
from flows.notify.night import deliver_pending, record_run
from flows.report.views import create_views, ensure_report_tables
from schemas.fields import EDGES
from schemas.plant_config import MailSpec, NotifySpec, parse_plant_config
from tests.notify.receivers import http_receiver, smtp_receiver

EXAMPLE = Path(__file__).resolve().parents[1] / "fixtures" / "plant_example.toml"
T0 = datetime(2026, 9, 1, 2, 30, tzinfo=timezone.utc)


@pytest.fixture
def warehouse(tmp_path, monkeypatch) -> Path:
    monkeypatch.setattr(channels, "RETRY_WAITS_S", (0.0,))
    with connect(tmp_path) as con:
        ensure_report_tables(con)
        create_views(con)
    return tmp_path


def _config(**notify):
    return dataclasses.replace(parse_plant_config(tomllib.loads(EXAMPLE.read_text())), notify=NotifySpec(**notify))


def _conditions(states: dict[str, str] | None = None) -> pl.DataFrame:
    """valve_condition rows of valve V1: every edge healthy unless ``states`` says otherwise."""
    states = states or {}
    return pl.DataFrame([{
        "valve_id": "V1", "edge": e, "edge_order": i + 1, "state": states.get(e, "healthy"), "reason": f"{states.get(e, 'healthy')}: why",
        "remaining_hours": None, "first_alarm_start": T0 if states.get(e) == "faulty" else None,
        "last_alarm_start": T0 if states.get(e) == "faulty" else None, "last_ok_window_start": T0,
    } for i, e in enumerate(EDGES)])  # fmt: skip


def _night(config, warehouse, night: int, states=None):
    now = T0 + timedelta(days=night)
    record_run(config, warehouse, _conditions(states), now=now, kind="report", report="/wh/reports/report.html")
    return deliver_pending(config, warehouse, now)


def _table(warehouse) -> pl.DataFrame:
    with connect(warehouse, read_only=True) as con:
        return query_frame(con, "SELECT * FROM notifications ORDER BY created_at, channel")


def test_a_night_without_change_sends_nothing_or_one_line(warehouse):
    with http_receiver() as (url, posts):
        for night in range(2):
            assert _night(_config(webhook_url=url), warehouse, night).sent == 0
        assert posts == [] and _table(warehouse).height == 0
        done = _night(_config(webhook_url=url, no_change=True), warehouse, 2)
    assert done.sent == 1 and len(posts) == 1 and posts[0]["changes"] == []
    assert posts[0]["text"] == "valvemon, plant MILL1: no change at the run of 2026-09-03 02:30 UTC. Report: /wh/reports/report.html"
    assert posts[0]["_content_type"] == "application/json"


def test_mail_logs_in_with_the_password_from_the_environment(warehouse, monkeypatch):
    logins = []
    with smtp_receiver(logins=logins) as (port, mails):
        mail = MailSpec(host="127.0.0.1", port=port, starttls=False, sender="valvemon@plant.test", to=("a@plant.test", "b@plant.test"),
                        password_env="VALVEMON_TEST_SMTP_PASSWORD")  # fmt: skip
        config = _config(mail=mail)
        _night(config, warehouse, 0)
        missing = _night(config, warehouse, 1, {"1r": "faulty"})  # the variable is not set: kept unsent
        assert (missing.sent, missing.unsent) == (0, 1) and "VALVEMON_TEST_SMTP_PASSWORD" in missing.line()
        monkeypatch.setenv("VALVEMON_TEST_SMTP_PASSWORD", "s3cret-from-env")
        done = _night(config, warehouse, 2, {"1r": "faulty"})  # no new change; last night's message goes out
    assert done.sent == 1 and logins == [("valvemon@plant.test", "s3cret-from-env")]
    assert len(mails) == 1 and mails[0]["To"] == "a@plant.test, b@plant.test" and mails[0]["Subject"] == "valvemon MILL1: 1 change: V1 1r faulty"
    table = _table(warehouse)
    assert table["status"].to_list() == ["sent"] and table["target"].to_list() == ["a@plant.test, b@plant.test"]
    assert not any("s3cret" in str(v) for row in table.iter_rows() for v in row)  # never recorded


def test_a_refusing_webhook_is_retried_then_kept(warehouse):
    with http_receiver(status=503) as (url, posts):
        config = _config(webhook_url=url, retries=3)
        _night(config, warehouse, 0)
        done = _night(config, warehouse, 1, {"s2": "faulty"})
    assert (done.sent, done.unsent) == (0, 1) and len(posts) == 3  # three attempts reached it
    row = _table(warehouse).row(0, named=True)
    assert (row["status"], row["attempts"], row["sent_at"]) == ("unsent", 3, None) and "503" in row["error"]


def test_a_backfill_without_notify_sends_nothing(warehouse):
    with http_receiver() as (url, posts):
        config = _config(webhook_url=url)
        _night(config, warehouse, 0)
        record_run(config, warehouse, _conditions({"1r": "worn"}), now=T0 + timedelta(days=1), kind="backfill", send=False)
        _night(config, warehouse, 2, {"1r": "worn"})  # the next night: the backfill's change is not news
    assert posts == [] and _table(warehouse)["status"].to_list() == ["suppressed"]


def test_runs_within_one_second_compare_each_with_the_run_before(warehouse):
    """``run_at`` holds whole seconds: five runs recorded in the same second still compare tonight
    with the run just before (a random run id ordered them by chance: a night without change
    reported the fault again, about one run in two)."""
    config = _config(webhook_url="http://127.0.0.1:9/hook")
    states = [None, {"1r": "faulty"}, {"1r": "faulty"}, None, None]
    seen = [record_run(config, warehouse, _conditions(s), now=T0, kind="report", send=False).changes["change"].to_list() for s in states]
    assert seen == [[], ["faulty"], [], ["recovered"], []]

"""`valvemon notify --test`: a test message on every channel against loopback receivers, a
channel that is down named with exit status 1, and a start-up that loads neither Prefect nor
DuckDB."""

from __future__ import annotations

import tomllib
from pathlib import Path

import tomli_w
from typer.testing import CliRunner

import flows.notify.channels as channels
from flows.cli import app
from tests.notify.receivers import free_port, http_receiver, smtp_receiver
from tests.test_cli_imports import HEAVY, _loaded

EXAMPLE = Path(__file__).resolve().parents[1] / "fixtures" / "plant_example.toml"


def _config(tmp_path: Path, notify: dict | None) -> Path:
    raw = tomllib.loads(EXAMPLE.read_text()) | ({"notify": notify} if notify else {})
    path = tmp_path / "plant.toml"
    path.write_text(tomli_w.dumps(raw))
    return path


def test_a_test_message_on_every_channel(tmp_path, monkeypatch):
    monkeypatch.setattr(channels, "RETRY_WAITS_S", (0.0,))
    runner = CliRunner()
    with http_receiver() as (url, posts), smtp_receiver() as (port, mails):
        mail = {"host": "127.0.0.1", "port": port, "starttls": False, "from": "v@plant.test", "to": "r@plant.test"}
        res = runner.invoke(app, ["notify", "--config", str(_config(tmp_path, {"webhook_url": url, "mail": mail})), "--test"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines() == ["webhook to " + url.split("/")[2] + ": sent", "mail to r@plant.test: sent"]
    assert len(posts) == 1 and posts[0]["test"] is True and posts[0]["plant"] == "MILL1"
    assert len(mails) == 1 and mails[0]["Subject"] == "valvemon MILL1: test message"
    down = {"webhook_url": f"http://127.0.0.1:{free_port()}/hook", "retries": 2}
    res = runner.invoke(app, ["notify", "--config", str(_config(tmp_path, down)), "--test"])
    assert res.exit_code != 0 and "NOT sent after 2 attempt(s): ConnectError" in res.output
    res = runner.invoke(app, ["notify", "--config", str(_config(tmp_path, None)), "--test"])
    assert res.exit_code != 0 and "no [notify] section" in str(res.exception)


def test_notify_test_loads_neither_prefect_nor_duckdb(tmp_path):
    with http_receiver() as (url, posts):
        code, modules, out = _loaded(["notify", "--config", str(_config(tmp_path, {"webhook_url": url})), "--test"], tmp_path)
    assert code == 0 and out.strip().endswith(": sent") and len(posts) == 1
    assert modules.isdisjoint(HEAVY) and "duckdb" not in modules, sorted(modules & {*HEAVY, "duckdb"})


def test_notify_sends_what_is_unsent_now(tmp_path):
    from datetime import datetime, timezone

    import polars as pl

    from flows.common.warehouse_db import connect, insert_frame
    from flows.report.views import create_views, ensure_report_tables
    from schemas.fields import NOTIFICATION_FIELDS, polars_schema

    runner = CliRunner()
    res = runner.invoke(app, ["notify", "--config", str(_config(tmp_path, {"webhook_url": "http://127.0.0.1:9/x"})), "--warehouse", str(tmp_path / "none")])
    assert res.exit_code != 0 and "no warehouse database" in str(res.exception) and not (tmp_path / "none").exists()
    wh = tmp_path / "wh"
    row = {f.name: None for f in NOTIFICATION_FIELDS} | {
        "notification_id": "n1", "run_id": "r1", "created_at": datetime(2026, 9, 2, tzinfo=timezone.utc), "channel": "webhook",
        "target": "old", "status": "unsent", "n_changes": 1, "subject": "s", "body": "b", "payload": '{"text": "held over"}',
        "attempts": 3, "error": "ConnectError"}  # fmt: skip
    with connect(wh) as con:
        ensure_report_tables(con)
        create_views(con)
        insert_frame(con, "notifications", pl.DataFrame([row], schema=polars_schema(NOTIFICATION_FIELDS)))
    with http_receiver() as (url, posts):
        res = runner.invoke(app, ["notify", "--config", str(_config(tmp_path, {"webhook_url": url})), "--warehouse", str(wh)])
    assert res.exit_code == 0 and "notify: 1 message(s) sent" in res.output and posts[0]["text"] == "held over"

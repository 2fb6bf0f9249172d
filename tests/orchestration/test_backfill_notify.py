"""`valvemon backfill` records the condition it leaves and sends nothing unless `--notify`
(a copy of the shared clean backfill: every unit is done, so the command only publishes,
records and, when asked, sends)."""

from __future__ import annotations

import tomllib

import tomli_w
from typer.testing import CliRunner

from flows.cli import app
from tests.notify.receivers import http_receiver
from tests.orchestration.conftest import END, START, copy_warehouse, table


def test_a_backfill_sends_only_with_notify(clean, archive, tmp_path):
    wh = copy_warehouse(clean[0], tmp_path / "wh")
    runner = CliRunner()
    with http_receiver() as (url, posts):
        plant = tomllib.loads((archive / "plant.toml").read_text()) | {"notify": {"webhook_url": url, "no_change": True}}
        config = tmp_path / "plant.toml"
        config.write_text(tomli_w.dumps(plant))
        args = ["backfill", "--config", str(config), "--warehouse", str(wh), "--from", START, "--to", END, "--quiet"]
        quiet = runner.invoke(app, args)
        assert quiet.exit_code == 0, quiet.output
        assert "(recorded, not sent: --notify sends them)" in quiet.output and posts == []
        loud = runner.invoke(app, [*args, "--notify"])
        assert loud.exit_code == 0, loud.output
    assert "notify: 1 message(s) sent" in loud.output and len(posts) == 1 and posts[0]["report"] == ""
    assert table(wh, "notifications")["status"].sort().to_list() == ["sent", "suppressed"]
    runs = table(wh, "condition_history")
    assert set(runs["run_kind"]) == {"backfill"} and runs["run_id"].n_unique() == 2 and runs.height == 2 * 2 * 4  # 2 valves × 4 edges a run

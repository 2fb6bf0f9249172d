"""The demo's night in which V012's edge 1r breaks (Table 2's fault, halfway through the demo
span: 2026-09-01 00:00 UTC), through the real ingest, monitor and `report`, with both receivers
listening on loopback: the night before sends nothing, that night one message per channel
naming V012, 1r and the reason. Only V012 of the demo plant, its commissioning day and the two
days around the break (the demo's own data: same configuration, seed and scenario)."""

from __future__ import annotations

import dataclasses
import functools

import pytest
import tomli_w

from flows.demo import COMMISSIONING_WINDOWS, DEMO_SEED, demo_config
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.report.flow import run_report
from flows.simulate.archive import SimulateRequest, run_simulate
from schemas.plant_config import MailSpec, NotifySpec, plant_config_to_dict
from tests.notify.receivers import http_receiver, smtp_receiver

BREAK = "2026-09-01"


@pytest.fixture(scope="module")
def v012(tmp_path_factory):
    """V012's archives: its commissioning day and 2026-08-31 … 2026-09-01 (4 windows a day)."""
    root = tmp_path_factory.mktemp("demo_night")
    config, _ = demo_config(root / "demo")
    v = config.valve("V012")
    config = dataclasses.replace(config, valves=(v,))
    plain = root / "plain.toml"
    plain.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    run_simulate(SimulateRequest(out=root / "commissioning", config_path=plain, start=v.commissioned.isoformat(), days=1.0,
                                 windows_per_day=COMMISSIONING_WINDOWS, format="parquet", seed=DEMO_SEED, workers=0), show_progress=False)
    run_simulate(SimulateRequest(out=root / "span", config_path=plain, start="2026-08-31", days=2.0, windows_per_day=4,
                                 format="parquet", seed=DEMO_SEED, workers=0), show_progress=False)  # fmt: skip
    return root, config


def test_the_night_v012_breaks_sends_one_message_naming_it(v012, tmp_path):
    root, config = v012
    report = functools.partial(run_report, detail=0)
    with http_receiver() as (url, posts), smtp_receiver() as (port, mails):
        notify = NotifySpec(webhook_url=url, mail=MailSpec(host="127.0.0.1", port=port, starttls=False, sender="valvemon@plant.test",
                                                            to=("reliability@plant.test",)))  # fmt: skip
        path = tmp_path / "plant.toml"
        path.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, notify=notify))).encode())
        wh = tmp_path / "wh"
        run_ingest(path, [root / "commissioning" / "exports", root / "span" / "exports"], wh)
        run_monitor(path, wh, end=BREAK)  # the night before the break
        first = report(path, wh)
        assert first.changes.height == 0 and (posts, mails) == ([], [])  # nothing changed: nothing sent
        run_monitor(path, wh, start=BREAK)  # the night of the break
        second = report(path, wh)
    assert second.delivery.sent == 2 and second.delivery.unsent == 0
    assert len(posts) == 1 and len(mails) == 1  # one message per channel, not one per window
    assert [(c["valve_id"], c["edge"], c["change"]) for c in posts[0]["changes"]] == [("V012", "1r", "faulty")]
    reason = posts[0]["changes"][0]["reason"]
    assert reason.startswith("fault: ") and posts[0]["changes"][0]["window_start"].startswith(BREAK)
    assert "V012 edge 1r" in posts[0]["text"] and reason in posts[0]["text"] and str(second.html.resolve()) in posts[0]["text"]
    assert mails[0]["To"] == "reliability@plant.test" and "V012 1r" in mails[0]["Subject"]
    body = mails[0].get_payload(decode=True).decode().replace("\r\n", "\n")
    assert "V012 edge 1r" in body and reason in body and posts[0]["text"] == body.rstrip("\n")  # the same text on both channels
    html = second.html.read_text()
    assert html.index("id='changes'") < html.index("Fleet, most urgent first") and "V012" in html[html.index("id='changes'"):html.index("Fleet")]


def test_receivers_down_the_night_completes_and_the_next_night_sends(v012, tmp_path, monkeypatch):
    import flows.notify.channels as channels
    from flows.common.warehouse_db import connect, query_frame
    from tests.notify.receivers import free_port

    monkeypatch.setattr(channels, "RETRY_WAITS_S", (0.0,))
    root, config = v012
    http_port, smtp_port = free_port(), free_port()  # nothing listens there yet
    notify = NotifySpec(webhook_url=f"http://127.0.0.1:{http_port}/hook", retries=2,
                        mail=MailSpec(host="127.0.0.1", port=smtp_port, starttls=False, sender="v@plant.test", to=("r@plant.test",)))  # fmt: skip
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, notify=notify))).encode())
    wh = tmp_path / "wh"
    run_ingest(path, [root / "commissioning" / "exports", root / "span" / "exports"], wh)
    run_monitor(path, wh, end=BREAK)
    run_report(path, wh, detail=0)
    run_monitor(path, wh, start=BREAK)
    down = run_report(path, wh, detail=0)  # the night completes
    assert down.html.is_file() and down.changes["valve_id"].to_list() == ["V012"]
    assert (down.delivery.sent, down.delivery.unsent) == (0, 2) and "ConnectError" in down.delivery.line()
    with connect(wh, read_only=True) as con:
        kept = query_frame(con, "SELECT channel, status, attempts, error FROM notifications ORDER BY channel")
    assert kept["status"].to_list() == ["unsent", "unsent"] and kept["attempts"].to_list() == [2, 2]
    assert all(kept["error"].str.len_chars() > 0)
    with http_receiver(http_port) as (_, posts), smtp_receiver(smtp_port) as (_, mails):
        after = run_report(path, wh, detail=0)  # the next night: nothing new, last night's message goes out
    assert after.changes.height == 0 and (after.delivery.sent, after.delivery.unsent) == (2, 0)
    assert len(posts) == 1 and len(mails) == 1 and posts[0]["changes"][0]["edge"] == "1r" and "V012" in mails[0]["Subject"]
    with connect(wh, read_only=True) as con:
        sent = query_frame(con, "SELECT status, attempts, sent_at FROM notifications")
    assert sent["status"].to_list() == ["sent", "sent"] and sent["attempts"].to_list() == [3, 3] and sent["sent_at"].is_not_null().all()

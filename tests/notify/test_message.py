"""The run's message: what [notify] asks for, one message for all changes, the one-line no-change."""

from __future__ import annotations

from datetime import datetime, timezone

from flows.notify.message import compose
from schemas.plant_config import NotifySpec

AT = datetime(2026, 9, 2, 2, 30, tzinfo=timezone.utc)
SPEC = NotifySpec(webhook_url="http://x/hook")


def _change(valve: str, edge: str, change: str, before: str | None, after: str, reason: str = "why") -> dict:
    return {"valve_id": valve, "edge": edge, "change": change, "state_before": before, "state_after": after, "reason": reason,
            "window_start": datetime(2026, 9, 1, tzinfo=timezone.utc), "remaining_below_h": 500.0, "run_id": "r"}  # fmt: skip


CHANGES = [_change("V012", "1r", "faulty", "healthy", "faulty", "fault: alpha_hat 0.31 beyond fault bound"),
           _change("V010", "s1", "worn", "healthy", "worn"), _change("V002", "s2", "remaining_below", "healthy", "healthy"),
           _change("V007", "2r", "recovered", "faulty", "healthy"), _change("V012", "s1", "new_alarm", "faulty", "faulty")]  # fmt: skip


def test_one_message_names_every_change_asked_for():
    m = compose("DEMO", SPEC, CHANGES, run_at=AT, report="/wh/reports/report.html")
    assert m.n_changes == 4  # remaining_below only with remaining_below_h
    assert m.subject == "valvemon DEMO: 4 changes: V012 1r faulty, V010 s1 worn, V007 2r recovered, +1 more"
    lines = m.body.splitlines()
    assert lines[0] == "valvemon, plant DEMO: 4 changes at the run of 2026-09-02 02:30 UTC" and lines[-1] == "Report: /wh/reports/report.html"
    assert ("- V012 edge 1r: healthy -> faulty, became faulty (window 2026-09-01 00:00 UTC): "
            "fault: alpha_hat 0.31 beyond fault bound") in lines  # fmt: skip
    assert [(c["valve_id"], c["edge"], c["change"]) for c in m.payload["changes"]] == [
        ("V012", "1r", "faulty"), ("V010", "s1", "worn"), ("V007", "2r", "recovered"), ("V012", "s1", "new_alarm")]
    assert m.payload["text"] == m.body and m.payload["changes"][0]["window_start"] == "2026-09-01T00:00:00+00:00"
    assert "run_id" not in m.payload["changes"][0]


def test_the_kinds_asked_for():
    only_faults = NotifySpec(webhook_url="http://x", worn=False, recovered=False, remaining_below_h=500.0)
    m = compose("DEMO", only_faults, CHANGES, run_at=AT, report="r")
    assert [c["change"] for c in m.payload["changes"]] == ["faulty", "remaining_below", "new_alarm"]
    assert "remaining life below 500 h" in m.body
    assert compose("DEMO", NotifySpec(webhook_url="http://x", faulty=False), CHANGES[:1], run_at=AT, report="r") is None


def test_no_change_sends_nothing_or_one_line():
    assert compose("DEMO", SPEC, [], run_at=AT, report="r") is None
    m = compose("DEMO", NotifySpec(webhook_url="http://x", no_change=True), [], run_at=AT, report="/wh/reports/report.html")
    assert m.n_changes == 0 and m.subject == "valvemon DEMO: no change" and "\n" not in m.body
    assert m.body == "valvemon, plant DEMO: no change at the run of 2026-09-02 02:30 UTC. Report: /wh/reports/report.html"

"""One message per run from the view ``condition_changes``: what the ``[notify]`` section asks
for, as a subject, a text body and the webhook's JSON payload (no I/O here)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from schemas.plant_config import NotifySpec

CHANGE_WORDS = {
    "faulty": "became faulty",
    "new_alarm": "new alarm",
    "worn": "became worn",
    "remaining_below": "remaining life below {h:g} h",
    "recovered": "back to healthy",
}
"""How each kind of change (``condition_changes.change``) reads in a message."""

SUBJECT_NAMES = 3
"""Edges named in the subject line (the body names them all)."""


@dataclass(frozen=True)
class Message:
    """What is sent on every channel."""

    subject: str
    body: str
    payload: dict
    n_changes: int


def wanted(spec: NotifySpec, change: str) -> bool:
    """Whether ``[notify]`` asks for this kind of change."""
    return {
        "faulty": spec.faulty, "new_alarm": spec.faulty, "worn": spec.worn, "recovered": spec.recovered,
        "remaining_below": spec.remaining_below_h is not None,
    }[change]  # fmt: skip


def _utc(t: datetime | None) -> str:
    return "—" if t is None else f"{t:%Y-%m-%d %H:%M} UTC"


def change_line(c: dict) -> str:
    """One change in words: valve, edge, states, what, where, why."""
    what = CHANGE_WORDS[c["change"]].format(h=c.get("remaining_below_h") or 0)
    return (f"{c['valve_id']} edge {c['edge']}: {c['state_before'] or 'not judged'} -> {c['state_after']}, {what} "
            f"(window {_utc(c['window_start'])}): {c['reason']}")  # fmt: skip


def compose(plant: str, spec: NotifySpec, changes: list[dict], *, run_at: datetime, report: str) -> Message | None:
    """The run's message: the changes ``spec`` asks for, in ``condition_changes`` order; with none,
    the one-line no-change message if ``spec.no_change``, else None (nothing is sent)."""
    chosen = [c for c in changes if wanted(spec, c["change"])]
    where = f"Report: {report}" if report else "No report was written by this run (valvemon report writes one)."
    if not chosen and not spec.no_change:
        return None
    if not chosen:
        body = f"valvemon, plant {plant}: no change at the run of {_utc(run_at)}. {where}"
        subject = f"valvemon {plant}: no change"
    else:
        names = [f"{c['valve_id']} {c['edge']} {c['change'].replace('_', ' ')}" for c in chosen]
        more = f", +{len(names) - SUBJECT_NAMES} more" if len(names) > SUBJECT_NAMES else ""
        subject = f"valvemon {plant}: {len(chosen)} change{'s' if len(chosen) > 1 else ''}: {', '.join(names[:SUBJECT_NAMES])}{more}"
        body = "\n".join([f"valvemon, plant {plant}: {len(chosen)} change{'s' if len(chosen) > 1 else ''} at the run of {_utc(run_at)}", "",
                          *(f"- {change_line(c)}" for c in chosen), "", where])  # fmt: skip
    payload = {
        "text": body,
        "plant": plant,
        "run_at": run_at.isoformat(),
        "report": report,
        "changes": [
            {k: (v.isoformat() if isinstance(v, datetime) else v) for k, v in c.items()
             if k in ("valve_id", "edge", "change", "state_before", "state_after", "reason", "window_start")}
            for c in chosen
        ],
    }  # fmt: skip
    return Message(subject, body, payload, len(chosen))

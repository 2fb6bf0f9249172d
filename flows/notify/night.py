"""A run's changes recorded and its message queued (:func:`record_run`), then every unsent
message sent (:func:`deliver_pending`).

:func:`record_run` writes, in one transaction of a short connection, the run's
``valve_condition`` rows into ``condition_history``, reads what changed since the run before
(view ``condition_changes``) and queues the run's message (:mod:`flows.notify.message`) in
table ``notifications``, one row per configured channel: ``unsent``, or ``suppressed`` when the
run must not send (a backfill without ``--notify``). :func:`deliver_pending` then sends every
``unsent`` message, this run's and any an earlier run could not send, oldest first, holding no
database connection while it waits on the network; records each outcome; and publishes the
snapshot, so ``valvemon query`` sees the run's changes and messages. A failed send never
raises: it is retried (:func:`flows.notify.channels.deliver`), logged, and kept ``unsent``
for the next run.
"""

from __future__ import annotations

import json
import logging
import time
import uuid
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import polars as pl

from flows.common.warehouse_db import connect, insert_frame, query_frame, transaction
from flows.notify.channels import channels, deliver
from flows.notify.message import compose
from flows.report.views import ensure_report_tables, publish_snapshot
from schemas.fields import CONDITION_HISTORY_FIELDS, NOTIFICATION_FIELDS, polars_schema
from schemas.plant_config import PlantConfig

log = logging.getLogger(__name__)


@dataclass
class NightChanges:
    """What :func:`record_run` found and queued."""

    run_id: str
    changes: pl.DataFrame
    """The view ``condition_changes`` after this run was recorded."""
    previous_run_at: datetime | None
    """The run compared with (None: the first recorded run)."""
    queued: int = 0
    """Messages queued (one per channel)."""


@dataclass
class Delivery:
    """What :func:`deliver_pending` sent."""

    sent: int = 0
    unsent: int = 0
    errors: list[str] = field(default_factory=list)

    def line(self) -> str:
        """One line for the command's output."""
        text = f"notify: {self.sent} message(s) sent"
        if self.unsent:
            text += f", {self.unsent} kept unsent for the next run ({'; '.join(self.errors)})"
        return text


def history_rows(conditions: pl.DataFrame, *, run_id: str, run_at: datetime, kind: str, remaining_below_h: float | None, report: str) -> pl.DataFrame:
    """``condition_history`` rows of one run from its ``valve_condition`` rows."""
    names = [f.name for f in CONDITION_HISTORY_FIELDS]
    extra = {"run_id": run_id, "run_at": run_at, "run_kind": kind, "remaining_below_h": remaining_below_h, "report_path": report}
    frame = conditions.with_columns(**{k: pl.lit(v) for k, v in extra.items()})
    return frame.select(names).cast(dict(polars_schema(CONDITION_HISTORY_FIELDS)))


def _queue(config: PlantConfig, changes: pl.DataFrame, run_id: str, now: datetime, report: str, status: str) -> pl.DataFrame:
    spec = config.notify
    try:
        message = compose(config.name, spec, changes.to_dicts(), run_at=now, report=report) if spec is not None else None
    except Exception:  # noqa: BLE001 - a message that cannot be composed must not fail the night's data work
        log.exception("valvemon notify: the message of run %s could not be composed; nothing is queued", run_id)
        message = None
    if message is None:
        return pl.DataFrame(schema=polars_schema(NOTIFICATION_FIELDS))
    rows = [{
        "notification_id": uuid.uuid4().hex, "run_id": run_id, "created_at": now, "channel": channel, "target": target,
        "status": status, "n_changes": message.n_changes, "subject": message.subject, "body": message.body,
        "payload": json.dumps(message.payload), "attempts": 0, "last_attempt_at": None, "sent_at": None, "error": "",
    } for channel, target in channels(spec)]  # fmt: skip
    return pl.DataFrame(rows, schema=polars_schema(NOTIFICATION_FIELDS))


def run_id_in_time_order() -> str:
    """A run's id: 16 hex digits of the wall clock's nanoseconds, then 16 random ones. Its text
    sorts as the runs were recorded, so view ``condition_changes`` (which orders by ``run_at``,
    whole seconds, then ``run_id``) compares tonight with the run before even when both fall in
    the same second; a random id sorted them by chance."""
    return f"{time.time_ns():016x}{uuid.uuid4().hex[:16]}"


def record_run(config: PlantConfig, warehouse: str | Path, conditions: pl.DataFrame, *, now: datetime, kind: str,
               report: str = "", send: bool = True) -> NightChanges:  # fmt: skip
    """Record the run's ``conditions`` (``valve_condition`` rows), read its changes and queue its
    message (module doc); ``send=False`` queues it ``suppressed``."""
    run_id = run_id_in_time_order()
    spec = config.notify
    rows = history_rows(conditions, run_id=run_id, run_at=now, kind=kind, report=report,
                        remaining_below_h=spec.remaining_below_h if spec is not None else None)  # fmt: skip
    with connect(warehouse) as con:
        ensure_report_tables(con)
        with transaction(con):
            previous = con.execute("SELECT max(run_at) FROM condition_history").fetchall()[0][0]
            insert_frame(con, "condition_history", rows)
            changes = query_frame(con, "SELECT * FROM condition_changes")
            queued = _queue(config, changes, run_id, now, report, "unsent" if send else "suppressed")
            insert_frame(con, "notifications", queued)
    return NightChanges(run_id, changes, previous, queued.height)


def deliver_pending(config: PlantConfig, warehouse: str | Path, now: datetime, *, send: bool = True) -> Delivery:
    """Send every ``unsent`` message (module doc; none when not ``send``), record the outcomes,
    publish the snapshot."""
    done = Delivery()
    with connect(warehouse) as con:
        ensure_report_tables(con)
        pending = query_frame(con, "SELECT * FROM notifications WHERE status = 'unsent' ORDER BY created_at, channel")
    updates = []
    if config.notify is not None and send:
        for r in pending.iter_rows(named=True):
            out = deliver(config.notify, r["channel"], r["subject"], r["body"], json.loads(r["payload"]))
            if out.attempts == 0:  # the channel is no longer configured: left as it is
                continue
            updates.append(("sent" if out.ok else "unsent", r["attempts"] + out.attempts, now if out.ok else None, out.error, r["notification_id"]))
            if out.ok:
                done.sent += 1
            else:
                done.unsent += 1
                done.errors.append(f"{r['channel']} to {r['target']}: {out.error}")
                log.warning("valvemon notify: %s message of run %s to %s not sent after %d attempt(s): %s; kept for the next run",
                            r["channel"], r["run_id"], r["target"], out.attempts, out.error)  # fmt: skip
    with connect(warehouse) as con:
        with transaction(con):
            for status, attempts, sent_at, error, nid in updates:
                con.execute(
                    "UPDATE notifications SET status = ?, attempts = ?, last_attempt_at = ?, sent_at = ?, error = ? WHERE notification_id = ?",
                    [status, attempts, now, sent_at, error, nid],
                )
        publish_snapshot(con, warehouse)
    return done


def after_backfill(config_path: str | Path, warehouse: str | Path, *, send: bool) -> tuple[NightChanges, Delivery]:
    """The end of ``valvemon backfill``: record the condition it left (from the snapshot its
    publish wrote), so the next report compares with it; with ``send`` (``--notify``) send its
    changes and every unsent message, else queue them ``suppressed``."""
    from datetime import timezone

    from flows.common.config import load_plant_config
    from flows.report.views import connect_snapshot, materialise_views

    config = load_plant_config(config_path)
    now = datetime.now(timezone.utc).replace(microsecond=0)
    con = connect_snapshot(warehouse)
    try:
        materialise_views(con, ("valve_condition",))
        conditions = query_frame(con, "SELECT * FROM valve_condition ORDER BY valve_id, edge_order")
    finally:
        con.close()
    night = record_run(config, warehouse, conditions, now=now, kind="backfill", send=send)
    return night, deliver_pending(config, warehouse, now, send=send)

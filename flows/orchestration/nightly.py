"""``valvemon serve``: the nightly deployment (``docs/orchestration.md``).

:func:`nightly_flow` is what runs every night: it

1. ingests the new exports of the ``exports`` inbox (all files there; content the manifest
   already holds is skipped by hash, files already done by path, size and mtime);
2. monitors the *previous day* — the calendar day before the run's scheduled time in the
   schedule's time zone (default the plant's) — for all valves, and the days of any newly
   ingested file that arrived late, one unit per valve and day (the backfill's machinery,
   :mod:`flows.orchestration.backfill`, so a failed night is simply continued by the next run);
3. refreshes the report (:func:`flows.report.flow.report_flow`: views, snapshot, pictures, HTML);
   with ``--no-report`` it only publishes the snapshot (:mod:`flows.report.publish`);
4. applies the plant's ``[retention]``, if it has one (:func:`flows.retention.flow.retention_flow`,
   as of the day after the monitored one): after monitoring and the report, because a partition
   may go only once its windows are fitted and the report's standstill check has read it.
   The snapshot is published again after retention, so its ``retention_log`` rows are queryable.

:func:`serve_nightly` registers it as a deployment with a cron schedule on the Prefect server
``PREFECT_API_URL`` names and serves it: this process polls the server and runs each scheduled
flow run (in a subprocess) until stopped. Schedules need a real server (``prefect server
start``); a temporary one never creates scheduled runs.
"""

from __future__ import annotations

from datetime import date, datetime, timedelta, timezone
from pathlib import Path
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from prefect import flow

from flows.common.config import load_plant_config
from flows.common.errors import ValvemonError
from flows.orchestration.backfill import BackfillFailed, backfill_flow
from flows.orchestration.dask_runner import task_runner

DEFAULT_CRON = "30 2 * * *"
"""02:30 every night, in the schedule's time zone."""
CONCURRENCY = 2


def zone(name: str) -> ZoneInfo:
    """An IANA time zone (a one-line error otherwise)."""
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValvemonError(f"--timezone: {name!r} is not an IANA time zone name") from None


def previous_day(now: datetime, tz: str) -> tuple[date, datetime, datetime]:
    """The calendar day before ``now`` in ``tz`` and its span in UTC ``[start, end)``."""
    z = zone(tz)
    local = now.astimezone(z)
    day = local.date() - timedelta(days=1)
    start = datetime(day.year, day.month, day.day, tzinfo=z).astimezone(timezone.utc)
    end = datetime(local.year, local.month, local.day, tzinfo=z).astimezone(timezone.utc)
    return day, start, end


def _scheduled_time() -> datetime:
    """The flow run's scheduled start (a late run still does the right day); now outside a deployment."""
    try:
        from prefect.runtime import flow_run

        t = flow_run.scheduled_start_time
        if t is not None:
            return datetime.fromisoformat(str(t)).astimezone(timezone.utc) if not isinstance(t, datetime) else t.astimezone(timezone.utc)
    except Exception:  # noqa: BLE001 - runtime information is best effort
        pass
    return datetime.now(timezone.utc)


@flow(name="valvemon-nightly", persist_result=False, validate_parameters=False)
def nightly_flow(
    config_path: str,
    exports: str,
    warehouse: str,
    timezone_name: str | None = None,
    day: str | None = None,
    concurrency: int = CONCURRENCY,
    dask_address: str | None = None,
    report: bool = True,
) -> dict:
    """Ingest the inbox, monitor the previous day, refresh the report, apply retention (module doc).

    ``day`` (ISO date) overrides "the previous day" for a manual run.
    """
    config = load_plant_config(config_path)
    tz = timezone_name or config.timezone
    if day:
        d = date.fromisoformat(day)
        z = zone(tz)
        start = datetime(d.year, d.month, d.day, tzinfo=z).astimezone(timezone.utc)
        end = (datetime(d.year, d.month, d.day, tzinfo=z) + timedelta(days=1)).astimezone(timezone.utc)
    else:
        d, start, end = previous_day(_scheduled_time(), tz)
    runner = task_runner(concurrency, dask_address)
    failure: BackfillFailed | None = None
    try:
        summary = backfill_flow.with_options(task_runner=runner, name="valvemon-nightly-backfill")(
            config_path=config_path, warehouse=warehouse, start=start.isoformat(), end=end.isoformat(),
            exports=exports, concurrency=concurrency, unit_days=1, filter_exports_by_name=False,
            monitor_new_data=True, kind="nightly", task_runner_name="dask" if dask_address else "threads",
        )  # fmt: skip
    except BackfillFailed as exc:  # some units failed: still report what is there, then fail
        failure, summary = exc, exc.summary
    result = {"day": d.isoformat(), "timezone": tz, "summary": summary.line(), "report": None, "retention": None}
    if report:
        result["report"] = str(refresh_report(config_path, warehouse))
    if config.retention is not None:
        result["retention"] = apply_retention(config_path, warehouse, d + timedelta(days=1))
    if not report or config.retention is not None:  # the report published before retention; without it nothing did
        from flows.report.publish import publish

        publish(config, warehouse)
    if failure is not None:
        raise failure
    return result


def refresh_report(config_path: str, warehouse: str) -> Path:
    """The report step of the nightly run: :func:`flows.report.flow.report_flow` (a subflow)."""
    from flows.report.flow import report_flow

    return report_flow(config_path=config_path, warehouse=warehouse).html


def apply_retention(config_path: str, warehouse: str, as_of: date) -> str:
    """The retention step of the nightly run (a subflow): the summary's last line."""
    from flows.retention.flow import retention_flow

    return retention_flow(config_path=config_path, warehouse=warehouse, as_of=as_of.isoformat()).lines()[-1]


def serve_nightly(
    config_path: str | Path,
    exports: str | Path,
    warehouse: str | Path,
    *,
    cron: str = DEFAULT_CRON,
    timezone_name: str | None = None,
    concurrency: int = CONCURRENCY,
    dask_address: str | None = None,
    report: bool = True,
    name: str | None = None,
) -> None:
    """Create the nightly deployment on the Prefect server and serve it until stopped."""
    from prefect.deployments.runner import EntrypointType
    from prefect.schedules import Cron
    from prefect.settings import PREFECT_API_URL

    config = load_plant_config(config_path)
    tz = timezone_name or config.timezone
    zone(tz)
    exports = Path(exports)
    if not exports.is_dir():
        raise ValvemonError(f"--exports {exports}: no such folder")
    api = PREFECT_API_URL.value()
    if not api:
        raise ValvemonError(
            "valvemon serve needs a Prefect server for its schedule: start one (prefect server start) "
            "and set PREFECT_API_URL, e.g. http://127.0.0.1:4200/api"
        )
    _check_api(api)
    try:
        schedule = Cron(cron, timezone=tz)
    except ValueError as exc:
        raise ValvemonError(f"--cron {cron!r}: {str(exc).splitlines()[0]}") from None
    parameters = {
        "config_path": str(Path(config_path).resolve()),
        "exports": str(exports.resolve()),
        "warehouse": str(Path(warehouse).resolve()),
        "timezone_name": tz,
        "concurrency": concurrency,
        "dask_address": dask_address,
        "report": report,
    }
    nightly_flow.serve(
        name=name or f"{config.name}-nightly",
        schedules=[schedule],
        parameters=parameters,
        description=f"valvemon nightly: ingest {exports}, monitor the previous day, refresh the report ({cron}, {tz})",
        tags=["valvemon", config.name],
        entrypoint_type=EntrypointType.MODULE_PATH,
    )


def _check_api(api: str, timeout_s: float = 10.0) -> None:
    import httpx

    try:
        r = httpx.get(api.rstrip("/") + "/health", timeout=timeout_s)
        r.raise_for_status()
    except httpx.HTTPError as exc:
        raise ValvemonError(f"PREFECT_API_URL {api}: the Prefect server does not answer ({type(exc).__name__}: {exc})") from None

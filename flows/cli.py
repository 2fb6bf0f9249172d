"""The ``valvemon`` command line (``docs/interfaces.md``).

Every command takes ``--warehouse DIR`` (or ``$VALVEMON_WAREHOUSE``; default ``warehouse/``).
Exit status 0 on success; otherwise non-zero with a one-line reason on stderr (:func:`main`).

Start-up is kept short: a command imports its stage only inside its function, and the stages
run without Prefect unless a Prefect API is configured (:mod:`flows.common.prefect_run`).
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Iterator, Optional

import typer

from flows.common.config import WAREHOUSE_ENV, warehouse_dir
from flows.common.errors import ValvemonError
from schemas.errors import ConfigError

app = typer.Typer(
    name="valvemon",
    help="Condition monitoring of electro-hydraulic servo valves (Steinboeck et al. 2013).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # click's plain help: rendering it with rich imports ~0.3 s of modules
)

Warehouse = Annotated[
    Optional[Path],
    typer.Option("--warehouse", envvar=WAREHOUSE_ENV, help="Warehouse folder (lake, DuckDB file, reports). [default: warehouse/]"),
]
Config = Annotated[Path, typer.Option("--config", help="Plant configuration (TOML).")]
Valves = Annotated[Optional[list[str]], typer.Option("--valves", help="Only these valve ids (repeat the option).")]
From = Annotated[Optional[str], typer.Option("--from", help="Start (ISO-8601 date or date-time, UTC unless an offset is given).")]
To = Annotated[Optional[str], typer.Option("--to", help="End, exclusive (ISO-8601).")]


@contextmanager
def publishing(config: Path, warehouse: Path) -> Iterator[None]:
    """After the command's work, publish what it committed for ``valvemon query``
    (:mod:`flows.report.publish`); after a failure too (e.g. the quarantine of a rejected file),
    the command's own error then being the one reported. A publish that cannot get the database
    (another writer holds it past the wait) is a warning, not a failure: the work is committed,
    and that writer publishes it with its own when it ends."""
    from flows.report.publish import publish

    try:
        yield
    except Exception:
        try:
            publish(config, warehouse)
        except Exception:  # noqa: BLE001 - the command's own error is the one to report
            pass
        raise
    try:
        publish(config, warehouse)
    except ValvemonError as exc:
        print(f"valvemon: warning: the snapshot for queries was not published: {_first_line(exc)}", file=sys.stderr)


@app.command()
def demo(warehouse: Warehouse = None) -> None:
    """Simulate a small plant, run the whole pipeline on it, print the fleet's condition and the report's path."""
    from rich.console import Console
    from rich.table import Table

    import flows.demo as demo_flows
    from flows.common.prefect_run import run_flow
    from flows.report.remaining import remaining_text

    wh = warehouse_dir(warehouse)
    result = run_flow(demo_flows.demo_flow, warehouse=str(wh))
    report = result["report"]
    ranking = report.ranking if report.ranking is not None else None
    table = Table(title=f"Fleet condition, most urgent first ({result['config']})")
    columns = ("urgency_rank", "valve_id", "state", "worst_edge", "remaining life", "reason")
    for c in columns:
        table.add_column(c, overflow="fold")
    for row in ranking.iter_rows(named=True) if ranking is not None else []:
        table.add_row(str(row["urgency_rank"]), row["valve_id"], row["state"], row["worst_edge"], remaining_text(row), row["reason"])
    Console(width=max(Console().width, 160)).print(table)
    typer.echo(f"report: {report.html.resolve()}")


@app.command()
def simulate(
    out: Annotated[Path, typer.Option("--out", help="Archive folder: plant.toml, truth.parquet, exports/.")],
    config: Annotated[Optional[Path], typer.Option("--config", help="Plant configuration (TOML); without it a plant is generated.")] = None,
    n_valves: Annotated[Optional[int], typer.Option("--n-valves", help="Valves of a generated plant (V001…). [default: 3]")] = None,
    plant: Annotated[Optional[str], typer.Option("--plant", help="Name of a generated plant. [default: SIM1]")] = None,
    commissioned: Annotated[Optional[str], typer.Option("--commissioned", help="Commissioning of a generated plant's valves (ISO-8601). [default: 2025-01-01T00:00:00Z]")] = None,
    start: Annotated[Optional[str], typer.Option("--from", help="Start (ISO-8601, UTC unless an offset is given). [default: the (latest) commissioning]")] = None,
    end: Annotated[Optional[str], typer.Option("--to", help="End, exclusive (ISO-8601).")] = None,
    days: Annotated[Optional[float], typer.Option("--days", help="Length of the span instead of --to. [default: 1]")] = None,
    hours: Annotated[Optional[str], typer.Option("--hours", help="Span in operating hours, END or START:END (instead of --from/--to).")] = None,
    windows_per_day: Annotated[Optional[int], typer.Option("--windows-per-day", help="Snapshot windows per UTC day, evenly spaced from 00:00. [default: 24]")] = None,
    window_s: Annotated[Optional[float], typer.Option("--window-s", help="Window length; a longer one than --segment-s is one back-to-back recording. [s] [default: 10]")] = None,
    recording: Annotated[str, typer.Option("--recording", help="snapshot (windows) | continuous (back to back over the whole span).")] = "snapshot",
    segment_s: Annotated[float, typer.Option("--segment-s", help="Longer recordings are simulated in segments of this length (clock-aligned), each with its own operating inputs and condition. [s]")] = 60.0,
    file_minutes: Annotated[Optional[float], typer.Option("--file-minutes", help="Split the exports into files of N minutes named <PLANT>_<YYYYMMDDTHHMMSS>. [default: continuous 60; snapshot one file a UTC day]")] = None,
    scenario: Annotated[Optional[list[str]], typer.Option("--scenario", help="NAME for every valve, or VALVE=NAME (repeat); healthy, wear, broken_edge[:EDGE][@HOURS]. [default: the valve's scenario key, else healthy]")] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of everything random; the same seed gives the same bytes.")] = 0,
    fmt: Annotated[str, typer.Option("--format", help="long | wide (CSV in that layout) | parquet (in the plant's layout) | ascii (wide text with the plant's header lines; a generated plant: iba's tag/name/unit lines) | tdms (wide).")] = "long",
    layout: Annotated[Optional[str], typer.Option("--layout", help="Layout of a generated plant's Parquet files: long | wide. [default: long]")] = None,
    gzip: Annotated[bool, typer.Option("--gzip", help="Compress text files (.csv.gz, .txt.gz).")] = False,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an archive already in --out.")] = False,
    workers: Annotated[Optional[int], typer.Option("--workers", help="Simulator processes beside the writer (0: simulate in-process). [default: CPUs - 1, at most 8, for archives of 2000 valve-s or more; else 0]")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    warehouse: Warehouse = None,
) -> None:
    """Write a synthetic archive (exports + the truth)."""
    from flows.simulate.archive import SimulateRequest, run_simulate

    request = SimulateRequest(
        out=out, config_path=config, n_valves=n_valves, plant=plant, commissioned=commissioned, start=start, end=end,
        days=days, hours=hours, windows_per_day=windows_per_day, window_s=window_s, recording=recording, segment_s=segment_s,
        file_minutes=file_minutes, scenarios=tuple(scenario or ()),
        seed=seed, format=fmt, layout=layout, gzip=gzip, overwrite=overwrite, workers=workers,
    )  # fmt: skip
    summary = run_simulate(request, show_progress=not quiet)
    typer.echo(
        f"wrote {len(summary.files)} export files ({summary.bytes / 1e6:,.1f} MB, {summary.rows:,} rows), "
        f"{summary.windows:,} valve segments ({summary.valve_seconds:,.0f} valve-s) in {summary.wall_s:,.1f} s "
        f"→ {summary.out}"
    )


@app.command()
def ingest(
    config: Config,
    paths: Annotated[list[Path], typer.Argument(help="Export files or folders.")],
    warehouse: Warehouse = None,
    force: Annotated[bool, typer.Option("--force", help="Read files again even if the manifest already holds their content.")] = False,
) -> None:
    """Historian exports into the sensor lake."""
    from flows.common.allocator import retain_polars_memory

    retain_polars_memory()  # before polars is imported: each batch's columns reuse freed pages
    import flows.ingest.flow as ingest_flows
    from flows.common.prefect_run import run_flow

    ingest_flows.preflight(config, paths)  # a bad configuration or path fails before anything starts
    wh = warehouse_dir(warehouse)
    with publishing(config, wh):
        counts = run_flow(
            ingest_flows.ingest_flow, config_path=str(config), paths=[str(p) for p in paths], warehouse=str(wh), force=force, show_progress=True
        )
    typer.echo(ingest_flows.summary_line(counts))


@app.command()
def monitor(config: Config, valves: Valves = None, start: From = None, end: To = None, warehouse: Warehouse = None) -> None:
    """Lake to opening-area points and fits."""
    from flows.common.allocator import retain_polars_memory

    retain_polars_memory()  # before polars is imported
    import flows.monitor.flow as monitor_flows
    from flows.common.prefect_run import run_flow

    wh = warehouse_dir(warehouse)
    with publishing(config, wh):
        reports = run_flow(monitor_flows.monitor_flow, config_path=str(config), warehouse=str(wh), valve_ids=valves, start=start, end=end)
    for r in reports:
        statuses = ", ".join(f"{s} {n}" for s, n in sorted(r.status_counts.items()))
        baseline = r.baseline_source + ("" if r.baseline_plausible else " (IMPLAUSIBLE: step 5a failed)")
        baseline += f" ({r.edge_law_note})" if r.edge_law_note else ""
        typer.echo(f"{r.valve_id}: {r.windows} windows, {r.rows_read} rows, fits {statuses or 'none'}; baseline {baseline}")


@app.command()
def report(
    config: Config,
    warehouse: Warehouse = None,
    detail: Annotated[int, typer.Option("--detail", help="Valves shown with pictures in the HTML report: the N most urgent.")] = 20,
    valves: Annotated[Optional[list[str]], typer.Option("--valves", help="Show these valves in detail instead (repeat the option).")] = None,
) -> None:
    """Refresh the views, write the pictures and the HTML report."""
    from flows.common.allocator import retain_polars_memory

    retain_polars_memory()  # before polars is imported: the standstill check's lake chunks reuse freed pages
    import flows.report.flow as report_flows
    from flows.common.prefect_run import run_flow

    result = run_flow(report_flows.report_flow, config_path=str(config), warehouse=str(warehouse_dir(warehouse)), detail=detail, valve_ids=valves)
    counts = result.ranking["state"].value_counts(sort=True) if result.ranking is not None else None
    summary = ", ".join(f"{n} {s}" for s, n in counts.iter_rows()) if counts is not None and counts.height else "no valves"
    changed = f"; {result.changes.height} change(s) since the previous report" if result.changes is not None else ""
    typer.echo(f"{summary}{changed}; {len(result.pngs)} pictures, export in {result.exports.get('valve_condition', Path()).parent}")
    _delivery_line(result.delivery)
    typer.echo(str(result.html.resolve()))


def _delivery_line(delivery) -> None:
    """The messages sent (stdout), or a warning naming those kept for the next run (stderr)."""
    if delivery is not None and delivery.unsent:
        print(f"valvemon: warning: {delivery.line()}", file=sys.stderr)
    elif delivery is not None and delivery.sent:
        typer.echo(delivery.line())


@app.command()
def notify(
    config: Config,
    test: Annotated[bool, typer.Option("--test", help="Send a test message on every channel of [notify] and say how each went; the warehouse is not touched.")] = False,
    warehouse: Warehouse = None,
) -> None:
    """Send the messages earlier runs could not (status unsent), or with --test a test message."""
    from flows.common.config import load_plant_config

    plant = load_plant_config(config)
    if plant.notify is None:
        raise ValvemonError(f"{config}: no [notify] section: nothing to send to (docs/notify.md)")
    if test:
        from flows.notify.channels import test_message

        failed = 0
        for channel, target, outcome in test_message(plant):
            line = f"{channel} to {target}: " + ("sent" if outcome.ok else f"NOT sent after {outcome.attempts} attempt(s): {outcome.error}")
            typer.echo(line)
            failed += not outcome.ok
        if failed:
            raise ValvemonError(f"{failed} of the [notify] channels did not take the test message")
        return
    from datetime import datetime, timezone

    from flows.common.warehouse_db import db_path
    from flows.notify.night import deliver_pending

    wh = warehouse_dir(warehouse)
    if not db_path(wh).is_file():
        raise ValvemonError(f"{db_path(wh)}: no warehouse database, so no message waits to be sent")
    delivery = deliver_pending(plant, wh, datetime.now(timezone.utc).replace(microsecond=0))
    typer.echo(delivery.line())
    if delivery.unsent:
        raise ValvemonError(f"{delivery.unsent} message(s) still unsent")


@app.command()
def query(
    sql: Annotated[str, typer.Argument(help="SQL against the warehouse (tables and views; docs/warehouse.md).")],
    fmt: Annotated[str, typer.Option("--format", help="table | csv | json | parquet (parquet needs --out).")] = "table",
    out: Annotated[Optional[Path], typer.Option("--out", help="Write the result to this file instead of standard output (never inside the warehouse folder).")] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --out file.")] = False,
    live: Annotated[bool, typer.Option("--live", help="Query the live database (read-only; waits while a writer holds it, and keeps writers out) instead of the snapshot every writing command publishes.")] = False,
    max_rows: Annotated[int, typer.Option("--max-rows", help="Rows shown by --format table (the others write all rows).")] = 200,
    warehouse: Warehouse = None,
) -> None:
    """An ad-hoc query against the warehouse, printed as a table."""
    from flows.report.query import run_query

    run_query(sql, warehouse_dir(warehouse), fmt=fmt, out=out, live=live, max_rows=max_rows, force=force)


DaskAddress = Annotated[
    Optional[str],
    typer.Option("--dask-address", help="Run the tasks on the Dask cluster whose scheduler is here (tcp://HOST:8786); see docs/orchestration.md."),
]


@app.command()
def backfill(
    config: Config,
    start: Annotated[str, typer.Option("--from", help="Start (ISO-8601 date or date-time, UTC unless an offset is given).")],
    end: Annotated[str, typer.Option("--to", help="End, exclusive (ISO-8601).")],
    valves: Valves = None,
    exports: Annotated[Optional[Path], typer.Option("--exports", help="Historian exports to ingest first (a folder, searched recursively, or a file); files whose name carries a date outside the span are left out.")] = None,
    concurrency: Annotated[Optional[int], typer.Option("--concurrency", help="Units in flight at once. [default: 2 on threads; twice the cluster's worker threads on Dask]")] = None,
    unit_days: Annotated[float, typer.Option("--unit-days", help="Days of one valve per monitor unit.")] = 7.0,
    retries: Annotated[int, typer.Option("--retries", help="Retries of a failed unit (as Prefect task retries when a Prefect API is configured).")] = 2,
    force: Annotated[bool, typer.Option("--force", help="Redo every monitor unit and re-read every file (content already in the manifest is still skipped).")] = False,
    notify: Annotated[bool, typer.Option("--notify", help="Send what changed since the last report ([notify]), and what is still unsent; without it the changes are recorded, not sent.")] = False,
    dask_address: DaskAddress = None,
    dask_workers: Annotated[Optional[int], typer.Option("--dask-workers", help="Run the tasks on a temporary local Dask cluster of N worker processes.")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bars.")] = False,
    warehouse: Warehouse = None,
) -> None:
    """Ingest + monitor over a span, resumable: rerun the same command to continue a stopped backfill."""
    from contextlib import ExitStack

    from flows.common.prefect_run import run_flow
    from flows.orchestration.backfill import CONCURRENCY, BackfillFailed, backfill_flow
    from flows.orchestration.dask_runner import cluster_threads, local_cluster, shared_api, task_runner

    if dask_address and dask_workers:
        raise ValvemonError("--dask-address and --dask-workers exclude each other")
    wh = warehouse_dir(warehouse)
    with ExitStack() as stack:
        address = dask_address
        if address or dask_workers:
            if dask_workers:
                address = stack.enter_context(local_cluster(dask_workers))
            threads = cluster_threads(address)  # reachable, and how big
            stack.enter_context(shared_api())
            n = concurrency or 2 * threads
        else:
            n = concurrency or CONCURRENCY
        if n < 1:
            raise ValvemonError("--concurrency must be at least 1")
        stack.enter_context(publishing(config, wh))
        try:
            summary = run_flow(
                backfill_flow, prefect_options=lambda: {"task_runner": task_runner(n, address)},
                config_path=str(config), warehouse=str(wh), start=start, end=end, valve_ids=valves,
                exports=str(exports) if exports else None, concurrency=n, unit_days=unit_days, retries=retries, force=force,
                show_progress=not quiet, task_runner_name=f"dask {address}" if address else f"threads ({n})",
            )  # fmt: skip
        except BackfillFailed as exc:
            typer.echo(exc.summary.line())
            raise
    typer.echo(summary.line())
    from flows.notify.night import after_backfill

    night, delivery = after_backfill(config, wh, send=notify)
    typer.echo(f"{night.changes.height} change(s) since the last recorded run" + ("" if notify else " (recorded, not sent: --notify sends them)"))
    _delivery_line(delivery)


@app.command()
def serve(
    config: Config,
    exports: Annotated[Path, typer.Option("--exports", help="The inbox of historian exports the nightly run ingests (new files only).")],
    cron: Annotated[str, typer.Option("--cron", help="When the nightly run starts (cron syntax, in --timezone).")] = "30 2 * * *",
    tz: Annotated[Optional[str], typer.Option("--timezone", help="IANA time zone of the schedule and of 'the previous day'. [default: the plant's plant.timezone]")] = None,
    concurrency: Annotated[int, typer.Option("--concurrency", help="Units in flight at once in a nightly run.")] = 2,
    dask_address: DaskAddress = None,
    no_report: Annotated[bool, typer.Option("--no-report", help="Skip the report step.")] = False,
    name: Annotated[Optional[str], typer.Option("--name", help="Deployment name. [default: PLANT-nightly]")] = None,
    warehouse: Warehouse = None,
) -> None:
    """The nightly deployment on a Prefect server (PREFECT_API_URL): serves it until stopped."""
    from flows.orchestration.nightly import serve_nightly

    serve_nightly(
        config, exports, warehouse_dir(warehouse), cron=cron, timezone_name=tz, concurrency=concurrency,
        dask_address=dask_address, report=not no_report, name=name,
    )  # fmt: skip


@app.command()
def retention(
    config: Config,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Only print what would be dropped or thinned; write nothing.")] = False,
    valves: Valves = None,
    as_of: Annotated[Optional[str], typer.Option("--as-of", help="Reference date (ISO): partitions older than keep_days before it are eligible. [default: today, UTC]")] = None,
    list_all: Annotated[bool, typer.Option("--list", help="Also print every partition's decision.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Accept an --as-of later than today or more than a day after the latest ingest.")] = False,
    warehouse: Warehouse = None,
) -> None:
    """Thin or drop lake partitions older than retention.keep_days (plant TOML) once their fits exist."""
    from contextlib import nullcontext

    import flows.retention.flow as retention_flows
    from flows.common.prefect_run import run_flow

    wh = warehouse_dir(warehouse)
    with nullcontext() if dry_run else publishing(config, wh):  # a dry run writes nothing, not even the snapshot
        summary = run_flow(
            retention_flows.retention_flow, config_path=str(config), warehouse=str(wh), valve_ids=valves, as_of=as_of, dry_run=dry_run, force=force
        )
    if summary is None:
        typer.echo(f"{config}: no [retention] table: retention is off, nothing is deleted (docs/warehouse.md, Retention)")
        return
    if list_all:
        for o in summary.outcomes:
            rows = "" if o.rows_before is None else f"  rows {o.rows_before:,} -> {o.rows_after if o.rows_after is not None else o.rows_before:,}"
            typer.echo(f"{o.valve_id} {o.day}  {o.action:4}  {o.reason}{rows}")
    for line in summary.lines():
        typer.echo(line)


@app.command()
def discrepancy(
    config: Config,
    valve: Annotated[str, typer.Option("--valve", help="Valve id.")],
    start: From = None,
    end: To = None,
    warehouse: Warehouse = None,
    max_records: Annotated[Optional[int], typer.Option("--max-records", help="Diagnose at most this many records (windows), evenly spaced over the span. [default: 48]")] = None,
    valve_condition: Annotated[str, typer.Option("--valve-condition", help="auto | design | commissioning: the valve's α and underlaps in the model; commissioning fits them on the configured baseline_window, auto does so when there is one.")] = "auto",
    reconstruct_spool: Annotated[bool, typer.Option("--reconstruct-spool", help="Take the spool position as Eq. 1's response to the recorded x_ref plus the reading's offset, not the smoothed reading: for spool transducers as noisy as 0.2 % of stroke; at 1 µm it reads worse.")] = False,
) -> None:
    """The model-discrepancy workflow: replay, name the missing effect, add it, its effect on monitoring."""
    import flows.discrepancy.flow as discrepancy_flows
    from flows.common.prefect_run import run_flow

    discrepancy_flows.check_arguments(config, valve, start, end, valve_condition, max_records)  # fail fast, before anything starts
    wh = warehouse_dir(warehouse)
    with publishing(config, wh):
        report = run_flow(
            discrepancy_flows.discrepancy_flow, config_path=str(config), warehouse=str(wh), valve_id=valve, start=start, end=end,
            max_records=max_records, condition_mode=valve_condition, reconstruct_spool=reconstruct_spool,
        )
    for line in discrepancy_flows.summary_lines(report):
        typer.echo(line)


TRACEBACK_ENV = "VALVEMON_TRACEBACK"
"""Set to 1 to get the traceback of an unexpected failure instead of its one line."""


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _interrupted(exc: BaseException) -> bool:
    """Whether DuckDB gave up a statement because of Ctrl-C (its ``InterruptException``, or the
    ``RuntimeError`` its Python client raises when it notices the signal itself)."""
    return type(exc).__name__ == "InterruptException" or (isinstance(exc, RuntimeError) and str(exc).startswith("Query interrupted"))


def _fail(message: str, code: int = 1) -> None:
    print(f"valvemon: error: {message}", file=sys.stderr)
    sys.exit(code)


class _PipeClosed(Exception):
    """Standard output's reader went away (``valvemon ... | head -1``)."""


def _stdout_closed() -> bool:
    """Whether standard output is a pipe whose reading end is closed (poll reports an error)."""
    import select

    try:
        poll = select.poll()
        poll.register(sys.__stdout__.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):
        return False


def _pipe_closed_is_done(invoke):
    """``invoke`` with a broken pipe on standard output raised as :class:`_PipeClosed`: click
    would turn it into exit status 1 (``typer.core``), though the output is written after the
    command's work, which stands."""

    def wrapped(ctx):
        try:
            return invoke(ctx)
        except BrokenPipeError:
            if _stdout_closed():
                raise _PipeClosed() from None
            raise

    return wrapped


def _silence_stdout() -> None:
    """Point standard output at ``/dev/null``, so that what is still buffered flushes quietly."""
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, sys.__stdout__.fileno())
    os.close(null)


def main() -> None:
    """Entry point: every failure is one line on stderr and a non-zero exit status: 1, or 2 for
    a usage error (bad option or argument); an interrupt exits with 130, silently. Standard
    output closed by its reader (``| head -1``) once the work is done exits 0, silently."""
    from flows.common.cli_values import convert_plainly

    try:
        command = typer.main.get_command(app)
        convert_plainly(command)  # the values converted without pydantic (~0.15–0.2 CPU-s a command)
        command.invoke = _pipe_closed_is_done(command.invoke)
        code = command(standalone_mode=False, prog_name="valvemon")
        sys.stdout.flush()  # a closed pipe shows here when the output was still buffered
    except (_PipeClosed, BrokenPipeError):  # the latter from the flush: standard output's
        _silence_stdout()
        sys.exit(0)
    except (ValvemonError, ConfigError) as exc:  # the reason, naming file, row, key …
        _fail(_first_line(exc))
    except typer.TyperException as exc:  # click's usage errors (click as vendored by typer)
        from typer._click.exceptions import NoArgsIsHelpError

        if isinstance(exc, NoArgsIsHelpError):  # `valvemon` alone: the help
            exc.show()
            sys.exit(exc.exit_code)
        ctx = getattr(exc, "ctx", None)
        _fail(_first_line(exc) + (f" (see '{ctx.command_path} --help')" if ctx is not None else ""), exc.exit_code)
    except typer.Abort:
        _fail("aborted")
    except KeyboardInterrupt:
        sys.exit(130)
    except OSError as exc:  # the file system: permissions, a full disk, a vanished file
        _fail(f"{exc.filename}: {exc.strerror}" if exc.filename and exc.strerror else _first_line(exc))
    except Exception as exc:  # noqa: BLE001 - a bug or an unforeseen failure: still one line (the traceback on request)
        if _interrupted(exc):  # DuckDB stopped a statement for Ctrl-C: its transaction is rolled back
            sys.exit(130)
        if os.environ.get(TRACEBACK_ENV) == "1":
            raise
        _fail(f"unexpected {type(exc).__name__}: {_first_line(exc)} (set {TRACEBACK_ENV}=1 for the traceback)")
    sys.exit(code if isinstance(code, int) else 0)


def console() -> None:
    """The installed ``valvemon`` command (``[project.scripts]``): :func:`main`, and after a
    command that succeeded the process ends at once (:func:`_end_now`), without the
    interpreter's teardown, which after ``valvemon monitor`` on a valve-day (modules, numba's
    compiled code, DuckDB and polars freeing ~750 MB object by object) cost ~0.6 CPU-s
    (BENCHMARKS.md). A failure or an interrupt exits as :func:`main` does (its one line, its
    status). :func:`main` itself never ends the process this way: tests and other Python code
    call it in-process."""
    try:
        main()
    except SystemExit as exc:
        if exc.code in (0, None):
            _end_now()
        raise


def _end_now() -> None:
    """End the process with status 0 without finalizing the interpreter (``os._exit``), once
    what an ordinary exit still does that anyone could observe is done: the ``atexit`` handlers
    run (the warehouse's DuckDB host detached, so checkpointed and unlocked; logging flushed;
    temporary directories removed; child processes reaped), then standard output and error are
    flushed. Left undone: freeing memory and finalizing modules and objects one by one, which
    the operating system reclaiming the process replaces. A command closes every file and
    connection it opens before it returns (what it wrote is then the kernel's, which
    ``os._exit`` does not touch; a killed run loses nothing either), so no destructor is left
    with data to write.

    Returns instead (the ordinary exit follows) when that would not be safe: a thread that is
    neither the main one nor a daemon still runs (an ordinary exit waits for it), Prefect was
    loaded (its API clients ship logs and events from their own threads and exit hooks), or a
    standard stream cannot be flushed (e.g. a closed pipe, which the ordinary exit reports)."""
    import atexit
    import threading

    if "prefect" in sys.modules:
        return
    if any(t is not threading.main_thread() and not t.daemon and t.is_alive() for t in threading.enumerate()):
        return
    atexit._run_exitfuncs()  # noqa: SLF001 - the exit handlers, as an ordinary exit runs them (then cleared)
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
    except (OSError, ValueError):
        return
    os._exit(0)

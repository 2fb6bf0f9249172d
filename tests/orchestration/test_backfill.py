"""valvemon backfill: same result as ingest + monitor, idempotent, resumable, bounded, locked partitions."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import duckdb
import polars as pl
import pytest

import flows.orchestration.backfill as bf
from flows.common.errors import ValvemonError
from flows.common.instants import utc_instant
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.orchestration.backfill import BackfillFailed, MonitorUnit, backfill_flow, export_in_span, extra_units, unit_grid
from flows.orchestration.dask_runner import task_runner
from tests.orchestration.conftest import END, START, assert_same, copy_warehouse, lake_files, snapshot, table

UTC = timezone.utc


def run(archive: Path, wh: Path, *, concurrency: int = 2, threads: int | None = None, prefect: bool = False, **kw):
    """The backfill as a command runs it without a Prefect API (the flow's function, units on a
    thread pool), or with ``prefect`` as a Prefect flow run on a runner of ``threads`` threads."""
    flow_ = backfill_flow.with_options(task_runner=task_runner(threads or concurrency)) if prefect else backfill_flow.fn
    return flow_(
        config_path=str(archive / "plant.toml"), warehouse=str(wh), start=kw.pop("start", START), end=kw.pop("end", END),
        exports=str(archive / "exports"), concurrency=concurrency, unit_days=kw.pop("unit_days", 1), **kw,
    )  # fmt: skip


# --- planning (no Prefect) -----------------------------------------------------------------------


def test_unit_grid_and_late_data_units():
    t0, t1 = datetime(2025, 1, 1, tzinfo=UTC), datetime(2025, 1, 20, tzinfo=UTC)
    grid = unit_grid(t0, t1, 7)
    assert [(a.day, b.day) for a, b in grid] == [(1, 8), (8, 15), (15, 20)]
    assert grid[0][0] == t0 and grid[-1][1] == t1
    # late exports of 2024-12-30 12:00 … 2025-01-02: units before the span, on its grid
    extra = extra_units(t0, 1, [("V1", datetime(2024, 12, 30, 12, tzinfo=UTC), datetime(2025, 1, 2, tzinfo=UTC))])
    assert [(u.start.day, u.end.day) for u in extra] == [(30, 31), (31, 1)]
    assert MonitorUnit("V1", t0, t0 + timedelta(hours=30)).days() == [t0.date(), t0.date() + timedelta(days=1)]


def test_exports_outside_the_span_are_left_out_by_name():
    t0, t1 = datetime(2025, 3, 1, tzinfo=UTC), datetime(2025, 4, 1, tzinfo=UTC)
    assert export_in_span(Path("P_2025-03-15.parquet"), t0, t1)
    assert export_in_span(Path("P_2025-02-28.csv"), t0, t1)  # a day of slack (local-midnight exports)
    assert export_in_span(Path("P_2025-04-01.csv"), t0, t1)
    assert not export_in_span(Path("P_2025-02-27.csv"), t0, t1)
    assert not export_in_span(Path("P_2025-04-02.csv.gz"), t0, t1)
    assert export_in_span(Path("dump.parquet"), t0, t1)  # no date in the name: always read


def test_span_instants_are_utc_and_a_bad_one_names_its_option(tmp_path):
    assert utc_instant(" 2025-01-01T01:00+01:00 ", "--from") == datetime(2025, 1, 1, tzinfo=UTC)
    assert utc_instant("2025-01-01T00:00Z") == utc_instant(datetime(2025, 1, 1).date()) == datetime(2025, 1, 1, tzinfo=UTC)
    plant = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"
    with pytest.raises(ValvemonError, match=r"^--to: 'tomorrow' is not an ISO-8601 date or date-time$"):
        backfill_flow.fn(config_path=plant, warehouse=tmp_path, start="2025-01-01", end="tomorrow")  # checked before any work


# --- the flow ------------------------------------------------------------------------------------


def test_backfill_equals_ingest_plus_monitor(clean, archive, tmp_path):
    """Units cut at day boundaries give exactly the fits of one monitor run over the whole lake."""
    wh, summary = clean
    assert summary.files_ingested == 3 and summary.units_done == 6 and summary.units_failed == 0
    assert summary.windows == 24 and summary.fits == 96
    ref = tmp_path / "ref"
    run_ingest(archive / "plant.toml", [archive / "exports"], ref)
    run_monitor(archive / "plant.toml", ref)
    for name in ("edge_fits", "selection_stats"):
        a, b = table(wh, name), table(ref, name)
        a = a.drop("monitored_at") if "monitored_at" in a.columns else a
        b = b.drop("monitored_at") if "monitored_at" in b.columns else b
        assert a.height > 0 and a.equals(b), name
    assert lake_files(wh) == lake_files(ref)


def _fit_rows(frame: pl.DataFrame) -> pl.DataFrame:
    frame = frame.drop("monitored_at")
    utc = [c for c, t in frame.schema.items() if isinstance(t, pl.Datetime)]
    return frame.with_columns(pl.col(utc).dt.convert_time_zone("UTC")).sort(["valve_id", "edge", "window_start"])


def test_windows_belong_to_the_unit_they_start_in(clean, archive, tmp_path):
    """Another unit grid gives the same rows; a unit boundary inside a window leaves the window
    whole to the unit it starts in (read on past its end), and out of the next one."""
    wh, _ = clean
    ref = _fit_rows(table(wh, "edge_fits"))
    other = run(archive, tmp_path / "wh", unit_days=2.5 / 24)
    assert other.units_done == 2 * 29  # every 2.5 h unit of the three days with data
    assert _fit_rows(table(tmp_path / "wh", "edge_fits")).equals(ref)

    cfg = bf.load_plant_config(archive / "plant.toml")
    base = bf._baselines_from_rows(cfg, "V001", bf._current_baselines(tmp_path / "wh", ["V001"])["V001"])
    day0, day1 = datetime(2025, 1, 1, tzinfo=UTC), datetime(2025, 1, 2, tzinfo=UTC)
    cut = datetime(2025, 1, 1, 6, 0, 4, tzinfo=UTC)  # 4 s into the 06:00 window
    a = bf.monitor_unit(cfg, MonitorUnit("V001", day0, cut), base, tmp_path / "wh")
    b = bf.monitor_unit(cfg, MonitorUnit("V001", cut, day1), base, tmp_path / "wh")
    assert (a.windows, b.windows) == (2, 2)  # 00:00, 06:00 | 12:00, 18:00
    v1 = ref.filter(pl.col("valve_id") == "V001")
    assert _fit_rows(a.fits).equals(v1.filter(pl.col("window_start") < cut))
    assert _fit_rows(b.fits).equals(v1.filter((pl.col("window_start") >= cut) & (pl.col("window_start") < day1)))


def test_second_run_changes_nothing(clean, archive, tmp_path):
    wh = copy_warehouse(clean[0], tmp_path / "wh")
    before = snapshot(wh)
    again = run(archive, wh)
    assert (again.files_ingested, again.files_resumed, again.units_done, again.units_skipped) == (0, 3, 0, 6)
    assert_same(snapshot(wh), before)  # every column, the lake's bytes and file times
    # --force recomputes every unit: same rows (but new monitored_at), the lake untouched
    forced = run(archive, wh, force=True)
    assert forced.units_done == 6 and forced.files_ingested == 0 and forced.files_skipped == 3
    assert_same(snapshot(wh, volatile=False), snapshot(clean[0], volatile=False))
    assert lake_files(wh, mtimes=True) == before["lake"]


def test_a_stopped_backfill_is_continued_by_the_same_command(clean, archive, tmp_path, monkeypatch):
    """Ingest dies on the 2nd file and monitoring after 2 units; the rerun ends like a clean run."""
    wh = tmp_path / "wh"
    real_ingest, real_monitor = bf.ingest_export, bf.monitor_unit
    calls = {"monitor": 0}

    def flaky_ingest(path, *a, **k):
        if "2025-01-02" in str(path):
            raise OSError("disk went away")
        return real_ingest(path, *a, **k)

    def flaky_monitor(*a, **k):
        calls["monitor"] += 1
        if calls["monitor"] > 2:
            raise RuntimeError("worker lost")
        return real_monitor(*a, **k)

    monkeypatch.setattr(bf, "ingest_export", flaky_ingest)
    monkeypatch.setattr(bf, "monitor_unit", flaky_monitor)
    with pytest.raises(BackfillFailed) as failed:
        run(archive, wh, concurrency=1, retries=0)
    s = failed.value.summary
    assert (s.files_ingested, s.files_failed) == (2, 1)
    assert s.units_done == 2 and s.units_failed == 2  # days 1 and 3 only had data: 4 units
    assert "disk went away" in str(failed.value)
    progress = table(wh, "backfill_progress")
    assert (progress["unit_kind"] == "monitor").sum() == 2 and (progress["unit_kind"] == "ingest").sum() == 2
    runs = table(wh, "backfill_runs")
    assert runs["status"].to_list() == ["failed"]

    monkeypatch.setattr(bf, "ingest_export", real_ingest)
    monkeypatch.setattr(bf, "monitor_unit", real_monitor)
    again = run(archive, wh, concurrency=1, retries=0)
    assert again.files_ingested == 1 and again.files_resumed == 2
    # the two units done before are redone only where the new day's partitions are their neighbours
    assert again.units_done + again.units_skipped == 6 and again.units_done >= 4
    assert_same(snapshot(wh, volatile=False, tables=("edge_fits", "selection_stats", "baselines", "ingest_manifest", "quarantine", "ingest_gaps")),
                snapshot(clean[0], volatile=False, tables=("edge_fits", "selection_stats", "baselines", "ingest_manifest", "quarantine", "ingest_gaps")))  # fmt: skip


@pytest.mark.parametrize("prefect", [False, True], ids=["plain", "prefect"])
def test_retries_absorb_a_transient_failure(archive, tmp_path, monkeypatch, request, prefect):
    """Each unit fails once and is retried: Prefect's task retries in a flow run, the same policy on the thread pool."""
    if prefect:
        request.getfixturevalue("prefect_server")
    real = bf.monitor_unit
    failed_once: set = set()

    def once(config, unit, *a, **k):
        if unit.key not in failed_once:
            failed_once.add(unit.key)
            raise OSError("transient")
        return real(config, unit, *a, **k)

    monkeypatch.setattr(bf, "monitor_unit", once)
    monkeypatch.setattr(bf, "RETRY_DELAY_S", (0.0, 0.0))
    s = run(archive, tmp_path / "wh", retries=1, prefect=prefect)
    assert s.units_done == 6 and s.units_failed == 0 and len(failed_once) == 6

    def always(*a, **k):
        raise OSError("always")

    monkeypatch.setattr(bf, "monitor_unit", always)  # failing after its retry too: reported, the run fails
    with pytest.raises(BackfillFailed, match=r"6 backfill units failed \(first: monitor V00\d/.*: always\)"):
        run(archive, tmp_path / "wh", retries=1, prefect=prefect, force=True)


def test_concurrency_is_bounded(archive, tmp_path, monkeypatch, prefect_server):
    """At most --concurrency units run at once, even on a runner with more threads."""
    lock = threading.Lock()
    active, peak = {"n": 0}, {"ingest": 0, "monitor": 0}

    def tracked(kind, fn):
        def wrapper(*a, **k):
            with lock:
                active["n"] += 1
                peak[kind] = max(peak[kind], active["n"])
            try:
                time.sleep(1.0)
                return fn(*a, **k)
            finally:
                with lock:
                    active["n"] -= 1

        return wrapper

    monkeypatch.setattr(bf, "ingest_export", tracked("ingest", bf.ingest_export))
    monkeypatch.setattr(bf, "monitor_unit", tracked("monitor", bf.monitor_unit))
    s = run(archive, tmp_path / "wh", concurrency=2, threads=6, prefect=True)
    assert s.units_done == 6 and s.max_in_flight == 2
    assert peak == {"ingest": 2, "monitor": 2}


def test_partitions_shared_by_two_files_are_merged_under_a_lock(archive, tmp_path):
    """One day split into six files ingested six at a time: the lake is the one of the whole file."""
    exports = tmp_path / "exports"
    exports.mkdir()
    day = pl.read_parquet(archive / "exports" / "SIM1_2025-01-01.parquet")
    ts = bf.load_plant_config(archive / "plant.toml").export.timestamp_column
    n = 6
    times = day[ts].unique(maintain_order=True)
    cuts = [times[i * len(times) // n] for i in range(n)] + [None]
    for i in range(n):  # whole time stamps per file (a sample's tags are never split)
        part = day.filter(pl.col(ts) >= cuts[i]) if cuts[i + 1] is None else day.filter((pl.col(ts) >= cuts[i]) & (pl.col(ts) < cuts[i + 1]))
        part.write_parquet(exports / f"part{i}.parquet")
    wh, ref = tmp_path / "wh", tmp_path / "ref"
    backfill_flow.fn(
        config_path=str(archive / "plant.toml"), warehouse=str(wh), start="2025-01-01", end="2025-01-02",
        exports=str(exports), concurrency=n, unit_days=1,
    )  # fmt: skip
    run_ingest(archive / "plant.toml", [archive / "exports" / "SIM1_2025-01-01.parquet"], ref)
    for part in (wh / "lake").rglob("part-0.parquet"):
        a, b = pl.read_parquet(part), pl.read_parquet(ref / part.relative_to(wh))
        assert a.equals(b), part
    assert len(list((wh / "lake").rglob("part-0.parquet"))) == 2


def test_killed_process_is_continued(clean, archive, tmp_path):
    """SIGKILL of `valvemon backfill` mid-run (after some units are recorded); the rerun completes it."""
    wh = tmp_path / "wh"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")} | {"VALVEMON_WAREHOUSE": str(wh)}
    cmd = [sys.executable, "-c", "from flows.cli import main; main()", "backfill", "--config", str(archive / "plant.toml"),
           "--exports", str(archive / "exports"), "--from", START, "--to", END, "--unit-days", str(1 / 24), "--concurrency", "1", "--quiet"]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    done = 0
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            # the backfill holds the database only while it writes a unit: poll often, so the count
            # is read between units, not once the run has ended (polled every 0.5 s, a CI run read
            # it only after the backfill had finished, which then could not be killed)
            time.sleep(0.05)
            try:
                con = duckdb.connect(str(wh / "valvemon.duckdb"), read_only=True)
            except (duckdb.IOException, duckdb.CatalogException, duckdb.InvalidInputException):
                continue
            try:
                done = con.execute("SELECT count(*) FROM backfill_progress WHERE unit_kind = 'monitor'").fetchone()[0]
            except duckdb.CatalogException:
                done = 0
            finally:
                con.close()
            if done >= 3:
                break
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert done >= 3, proc.stderr.read().decode()[-2000:]
    assert proc.returncode == -signal.SIGKILL  # killed, not finished
    again = run(archive, wh, unit_days=1 / 24)
    assert again.units_skipped >= 3 and again.units_failed == 0
    assert_same(snapshot(wh, volatile=False, tables=("edge_fits", "selection_stats", "ingest_manifest")),
                snapshot(clean[0], volatile=False, tables=("edge_fits", "selection_stats", "ingest_manifest")))  # fmt: skip

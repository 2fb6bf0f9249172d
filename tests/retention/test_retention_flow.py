"""flows/retention/flow.py on a small simulated warehouse (run_simulate → run_ingest → run_monitor →
the report's standstill pass, the plain functions the flows run), then retention with --as-of."""

from __future__ import annotations

import hashlib
import shutil
from datetime import date, timedelta
from pathlib import Path

import polars as pl
import pytest

import flows.retention.flow as fr
from flows.common.lake import day_files, dropped_folders, hour_path, partition_folders, partition_rows, read_lake, write_partition
from flows.common.warehouse_db import connect, query_frame
from tests.retention.conftest import AS_OF, DAYS, plant_with

pytestmark = pytest.mark.xdist_group("retention_base")  # one worker builds the shared `base` once


def _fingerprint(wh: Path) -> dict[str, str]:
    """Every file of the warehouse (lake, database, hidden folders) → sha256 of its bytes."""
    return {str(p.relative_to(wh)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(wh.rglob("*")) if p.is_file()}


def _q(wh: Path, sql: str) -> pl.DataFrame:
    with connect(wh, read_only=True) as con:
        return query_frame(con, sql)


def _decisions(summary) -> dict[tuple[str, date], tuple[str, str]]:
    return {(o.valve_id, o.day): (o.action, o.reason) for o in summary.outcomes}


def test_drop_only_fitted_old_days_and_dry_run_writes_nothing(base, wh, tmp_path):
    plant = plant_with(base, tmp_path, keep_days=3, mode="drop")
    lake_before = read_lake(wh).collect()
    # V002's 2025-01-02 08:00 window was never fitted: its day stays
    with connect(wh) as con:
        con.execute("DELETE FROM edge_fits WHERE valve_id = 'V002' AND window_start >= '2025-01-02T08:00Z' AND window_start < '2025-01-02T09:00Z'")
    before = _fingerprint(wh)
    dry = fr.run_retention(plant, wh, as_of=AS_OF, dry_run=True)
    assert _fingerprint(wh) == before  # a dry run writes nothing, the database included
    expected = {
        ("V001", DAYS[0]): ("keep", "kept: commissioning window"),
        ("V001", DAYS[1]): ("drop", "drop: fitted, checked and older than 3 days"),
        ("V001", DAYS[2]): ("drop", "drop: fitted, checked and older than 3 days"),
        ("V001", DAYS[3]): ("keep", "kept: within 3 days"),
        ("V002", DAYS[0]): ("drop", "drop: fitted, checked and older than 3 days"),
        ("V002", DAYS[1]): ("keep", "kept: not all windows fitted yet"),
        ("V002", DAYS[2]): ("drop", "drop: fitted, checked and older than 3 days"),
        ("V002", DAYS[3]): ("keep", "kept: within 3 days"),
    }
    assert _decisions(dry) == expected
    per_day = lake_before.group_by("valve_id", "date").len()
    rows = {(v, d): n for v, d, n in per_day.iter_rows()}
    groups = {(a, r): (n, r0, r1) for a, r, n, r0, r1, _, _ in dry.groups()}
    dropped = [k for k, v in expected.items() if v[0] == "drop"]
    assert groups[("drop", expected[dropped[0]][1])] == (4, sum(rows[k] for k in dropped), 0)
    assert "DRY RUN" in dry.lines()[0] and dry.lines()[-1].startswith("would free")

    done = fr.run_retention(plant, wh, as_of=AS_OF)
    assert _decisions(done) == expected
    assert {(v, d) for v, d, _ in partition_folders(wh)} == set(expected) - set(dropped)
    assert not dropped_folders(wh)
    lake_after = read_lake(wh).collect()
    assert lake_after.equals(lake_before.filter(~pl.struct("valve_id", "date").is_in([{"valve_id": v, "date": d} for v, d in dropped])))
    log = _q(wh, "SELECT valve_id, date, action, rows_before, rows_after, size_after_bytes, keep_days, as_of FROM retention_log ORDER BY ALL")
    assert log.rows() == [(v, d, "drop", rows[(v, d)], 0, 0, 3, AS_OF) for v, d in sorted(dropped)]
    assert (_q(wh, "SELECT size_before_bytes FROM retention_log")["size_before_bytes"] > 0).all()
    assert done.freed_bytes() == dry.freed_bytes() > 0
    # fits and baselines are kept
    assert _q(wh, "SELECT count(*) AS n FROM edge_fits")["n"][0] == 2 * 24 * 4 - 4
    assert _q(wh, "SELECT count(DISTINCT valve_id) AS n FROM baselines")["n"][0] == 2

    # a second run changes nothing
    snap = _fingerprint(wh)
    again = fr.run_retention(plant, wh, as_of=AS_OF)
    assert _fingerprint(wh) == snap
    assert all(o.action == "keep" for o in again.outcomes) and again.freed_bytes() == 0


def test_thin_keeps_the_first_seconds_of_every_hour_once(base, wh, tmp_path):
    plant = plant_with(base, tmp_path, keep_days=3, mode="thin", thin_keep_s_per_hour=2.0)
    lake_before = read_lake(wh).collect()
    summary = fr.run_retention(plant, wh, as_of=AS_OF)
    thinned = {(o.valve_id, o.day) for o in summary.outcomes if o.action == "thin"}
    assert thinned == {("V001", DAYS[1]), ("V001", DAYS[2]), ("V002", DAYS[0]), ("V002", DAYS[1]), ("V002", DAYS[2])}
    lake_after = read_lake(wh).collect()
    first = pl.col("timestamp_utc").min().over("valve_id", pl.col("timestamp_utc").dt.truncate("1h"))
    is_thinned = pl.struct("valve_id", "date").is_in([{"valve_id": v, "date": d} for v, d in thinned])
    expected = lake_before.filter(~is_thinned | (pl.col("timestamp_utc") - first < timedelta(seconds=2)))
    assert lake_after.equals(expected)
    # 6 windows a day, each in its own hour: 2 s of 1 kHz samples kept from each
    log = _q(wh, "SELECT valve_id, date, rows_after, size_before_bytes, size_after_bytes, thin_keep_s_per_hour FROM retention_log ORDER BY ALL")
    assert log.height == 5 and set(log["rows_after"]) == {6 * 2000} and set(log["thin_keep_s_per_hour"]) == {2.0}
    assert (log["size_after_bytes"] < log["size_before_bytes"]).all()
    # the thinned days are still covered by their fits: a second run finds them thinned already
    snap = _fingerprint(wh)
    again = fr.run_retention(plant, wh, as_of=AS_OF)
    assert _fingerprint(wh) == snap
    assert {(o.valve_id, o.day) for o in again.outcomes if o.reason == "kept: already thinned"} == thinned
    # ... without reading them: each is as its log row left it. A partition written since is read again
    assert all(o.rows_before is None for o in again.outcomes if o.reason == "kept: already thinned")
    folder = next(f for v, d, f in partition_folders(wh) if (v, d) == ("V002", DAYS[0]))
    (only,) = day_files(folder)
    write_partition(only, pl.read_parquet(only))
    third = {(o.valve_id, o.day): o for o in fr.run_retention(plant, wh, as_of=AS_OF).outcomes}
    assert third[("V002", DAYS[0])].reason == "kept: already thinned" and third[("V002", DAYS[0])].rows_before == 6 * 2000
    assert third[("V002", DAYS[1])].rows_before is None


def test_unchecked_days_are_kept(base, wh, tmp_path):
    plant = plant_with(base, tmp_path, keep_days=1, mode="drop")
    with connect(wh) as con:
        con.execute("UPDATE standstill_progress SET checked_through = TIMESTAMPTZ '2025-01-02 12:00:00Z' WHERE valve_id = 'V002'")
        con.execute("DELETE FROM standstill_progress WHERE valve_id = 'V001'")
    d = _decisions(fr.run_retention(plant, wh, as_of=AS_OF, dry_run=True))
    assert {k for k, v in d.items() if v[0] == "drop"} == {("V002", DAYS[0])}
    assert {k for k, v in d.items() if v[1] == "kept: standstill check not yet run"} == {("V001", d_) for d_ in DAYS[1:]} | {("V002", d_) for d_ in DAYS[1:]}


def test_no_database_keeps_everything(base, tmp_path):
    wh = tmp_path / "lake_only"
    shutil.copytree(base[0] / "lake", wh / "lake")
    d = _decisions(fr.run_retention(plant_with(base, tmp_path, keep_days=1, mode="drop"), wh, as_of=AS_OF))
    assert {v[1] for v in d.values()} == {"kept: no fits yet", "kept: commissioning window"}
    assert not (wh / "valvemon.duckdb").exists()


class Killed(BaseException):
    """Stands for the process being killed at that point (not caught by ordinary handlers)."""


def _split_into_hour_files(wh: Path, valve_id: str, day: date) -> None:
    """Store a partition as two hour files (as the ingest stores a continuous day)."""
    folder = next(f for v, d, f in partition_folders(wh) if (v, d) == (valve_id, day))
    (only,) = day_files(folder)
    frame = pl.read_parquet(only)
    write_partition(hour_path(folder, 0), frame.filter(pl.col("timestamp_utc").dt.hour() < 12))
    write_partition(hour_path(folder, 12), frame.filter(pl.col("timestamp_utc").dt.hour() >= 12))
    only.unlink()


def _log(wh: Path) -> pl.DataFrame:
    return _q(wh, "SELECT valve_id, date, action, rows_before, rows_after, state FROM retention_log ORDER BY valve_id, date, action")


KILL_POINTS = {
    # drop: intent → rename → delete → done; the n-th call of the step is where the run dies (before it)
    "drop": [("drop_partition", 1), ("remove_dropped", 1), ("complete", 1), ("drop_partition", 2)],
    # thin (V002's first day in two hour files): intent → file → file → done
    "thin": [("write_partition_pieces", 1), ("write_partition_pieces", 2), ("complete", 1)],
}


@pytest.mark.parametrize("mode", ["drop", "thin"])
def test_a_run_killed_at_any_point_leaves_every_removed_row_in_the_log(base, wh, tmp_path, monkeypatch, mode):
    """Before: killed after a thinned file was in place but before its log row, the rows it removed
    were in no record and the rerun said "already thinned". Now the intent is recorded first: at
    every point the log accounts for at least every removed row, and the next run completes it to
    the clean run's lake and log."""
    plant = plant_with(base, tmp_path, keep_days=3, mode=mode, thin_keep_s_per_hour=2.0)
    if mode == "thin":
        _split_into_hour_files(wh, "V002", DAYS[0])
    rows_before = read_lake(wh, ["V002"]).collect().height
    clean = tmp_path / "clean"
    shutil.copytree(wh, clean)
    fr.run_retention(plant, clean, valve_ids=["V002"], as_of=AS_OF)
    expected_lake, expected_log = read_lake(clean, ["V002"]).collect(), _log(clean)
    assert set(expected_log["state"]) == {"done"} and expected_log.height == 3
    for k, (step, n) in enumerate(KILL_POINTS[mode]):
        run = tmp_path / f"killed{k}"
        shutil.copytree(wh, run)
        real, calls = getattr(fr, step), []

        def dies(*a, _real=real, _calls=calls, _n=n, **kw):
            _calls.append(1)
            if len(_calls) == _n:
                raise Killed
            return _real(*a, **kw)

        monkeypatch.setattr(fr, step, dies)
        with pytest.raises(Killed):
            fr.run_retention(plant, run, valve_ids=["V002"], as_of=AS_OF)
        monkeypatch.undo()
        removed = rows_before - read_lake(run, ["V002"]).collect().height
        log = _log(run)
        assert "intent" in set(log["state"]), (step, n)
        assert removed <= (log["rows_before"] - log["rows_after"]).sum(), (step, n)  # every removed row is in a record
        summary = fr.run_retention(plant, run, valve_ids=["V002"], as_of=AS_OF)
        begun = step != "drop_partition"  # a drop killed before its rename is withdrawn: nothing was removed
        assert bool(summary.interrupted) == begun and not dropped_folders(run)
        assert read_lake(run, ["V002"]).collect().equals(expected_lake), (step, n)
        assert _log(run).equals(expected_log), (step, n)



def test_standstill_progress_is_the_last_sample_the_report_read(base, wh):
    from datetime import datetime, timezone

    from flows.report.flow import mark_standstill_progress

    last = read_lake(wh).group_by("valve_id").agg(pl.col("timestamp_utc").max()).collect().sort("valve_id")
    progress = _q(wh, "SELECT valve_id, checked_through AS timestamp_utc FROM standstill_progress ORDER BY valve_id")
    assert progress.equals(last)
    with connect(wh) as con:  # it never moves back
        mark_standstill_progress(con, "V001", datetime(2025, 1, 2, tzinfo=timezone.utc), datetime.now(timezone.utc))
    assert _q(wh, "SELECT valve_id, checked_through AS timestamp_utc FROM standstill_progress ORDER BY valve_id").equals(last)


def test_stray_samples_get_fit_rows_so_their_day_can_go(base, wh, tmp_path):
    """A day holding only a 1-sample and a 2-sample window: the monitor gives both fit rows (no
    estimate), so the day is fitted and, once checked, dropped rather than kept forever."""
    from datetime import datetime, timezone

    from flows.common.config import load_plant_config
    from flows.common.lake import partition_path
    from flows.monitor.flow import run_monitor
    from flows.report.flow import update_standstill

    plant = plant_with(base, tmp_path, keep_days=1, mode="drop")
    day = date(2025, 1, 6)
    sample = read_lake(wh, ["V002"]).head(3).collect().with_columns(pl.lit(day).alias("date"))
    times = [datetime(2025, 1, 6, 12, tzinfo=timezone.utc), datetime(2025, 1, 6, 13, tzinfo=timezone.utc), datetime(2025, 1, 6, 13, 0, 0, 1000, tzinfo=timezone.utc)]
    write_partition(partition_path(wh, "V002", day), sample.with_columns(pl.Series("timestamp_utc", times, dtype=pl.Datetime("us", "UTC"))))
    cfg = tmp_path / "plant.toml"
    run_monitor(cfg, wh, ["V002"], "2025-01-06", "2025-01-07")
    fits = _q(wh, "SELECT window_start, status FROM edge_fits WHERE window_start >= '2025-01-06'")
    assert fits.height == 2 * 4 and fits["window_start"].n_unique() == 2 and "ok" not in set(fits["status"])
    update_standstill(load_plant_config(cfg), wh, datetime.now(timezone.utc))
    d = _decisions(fr.run_retention(plant, wh, valve_ids=["V002"], as_of=date(2025, 1, 8), dry_run=True))
    assert d[("V002", day)][0] == "drop"


def test_thinning_a_file_of_one_row_group_larger_than_a_batch_keeps_exactly_the_kept_rows(tmp_path):
    """An older lake file may hold a row group of more rows than a read batch: the kept rows of an
    hour that begins in its second batch are still found at their rows of the file."""
    import numpy as np
    import pyarrow.parquet as pq

    from flows.common.lake import ROW_GROUP_MAX_ROWS, SENSOR_ARROW_SCHEMA, iter_file_batches
    from transforms.retention import HOUR_US, thin_mask

    n = ROW_GROUP_MAX_ROWS + 60_000  # 1 kHz from hh:42:30: the next hour begins at row 1,050,000, in the second batch
    t0 = 1_735_700_000 * 10**6 // HOUR_US * HOUR_US + 42 * 60_000_000 + 30_000_000
    t = t0 + np.arange(n, dtype=np.int64) * 1000
    frame = pl.DataFrame({"valve_id": "V1", "date": pl.Series(t).cast(pl.Datetime("us", "UTC")).dt.date(),
                          "timestamp_utc": pl.Series(t).cast(pl.Datetime("us", "UTC")),
                          **{c: np.arange(n, dtype=np.float32) for c in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")},
                          "x_ref_m": pl.Series([None] * n, dtype=pl.Float32)})  # fmt: skip
    folder = tmp_path / "valve_id=V1" / "date=x"
    folder.mkdir(parents=True)
    path = folder / "part-0.parquet"
    pq.write_table(frame.to_arrow().select(SENSOR_ARROW_SCHEMA.names).cast(SENSOR_ARROW_SCHEMA), path, row_group_size=n)
    assert pq.ParquetFile(path).metadata.num_row_groups == 1
    scan = fr.scan_partition(folder, (t[:1], t[-1:]), True)
    per_file = fr.count_kept(folder, scan, 10.0)
    assert fr.thin_partition(per_file, "none") == 2 * 10_000
    kept = pl.concat(list(iter_file_batches(path)))
    assert kept.equals(frame.filter(pl.Series(thin_mask(t, scan.firsts, 10.0))).select(kept.columns))

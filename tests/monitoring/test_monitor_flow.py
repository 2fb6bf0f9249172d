"""flows/monitor/flow.py through the real flows (run_simulate → run_ingest → run_monitor, the plain
functions the Prefect flows run): reruns, baseline versions, errors, unusable windows, chunking."""

from __future__ import annotations

import dataclasses
import shutil
from datetime import timedelta
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import tomli_w

import flows.monitor.flow as fm
from flows.common.config import load_plant_config
from flows.common.errors import ValvemonError
from flows.common.warehouse_db import connect, query_frame
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.simulate.archive import DEFAULT_COMMISSIONED, SimulateRequest, run_simulate
from schemas.plant_config import plant_config_to_dict

DAY0 = DEFAULT_COMMISSIONED  # 2025-01-01T00:00Z, the generated plant's commissioning instant


def _simulate(out: Path, **kw) -> Path:
    req = dict(out=out, n_valves=2, windows_per_day=6, format="parquet", seed=2, workers=0,
               scenarios=("V001=wear", "V002=broken_edge"))  # fmt: skip
    req.update(kw)
    run_simulate(SimulateRequest(**req), show_progress=False)
    return out


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """Two valves, two UTC days, a 10 s window every 4 h (24 windows)."""
    return _simulate(tmp_path_factory.mktemp("archive") / "sim", days=2.0)


@pytest.fixture(scope="module")
def short_windows(tmp_path_factory) -> Path:
    """The same plant on its third day: six 0.3 s windows each, too short to move the cylinder
    (every window opens with a 0.2–0.5 s dwell), so no estimate."""
    return _simulate(tmp_path_factory.mktemp("short") / "sim", start=(DAY0 + timedelta(days=2)).isoformat(), days=1.0, window_s=0.3)


def _warehouse(tmp_path: Path, *archives: Path) -> Path:
    wh = tmp_path / "wh"
    run_ingest(archives[0] / "plant.toml", [a / "exports" for a in archives], wh)
    return wh


def _table(wh: Path, sql: str) -> pl.DataFrame:
    with connect(wh) as con:
        return query_frame(con, sql)


FITS = "SELECT * EXCLUDE (monitored_at) FROM edge_fits ORDER BY valve_id, window_start, edge"


def _config_with(config_path: Path, out: Path, **changes_by_valve) -> Path:
    """A copy of the plant configuration with some valves' fields replaced."""
    config = load_plant_config(config_path)
    valves = tuple(dataclasses.replace(v, **changes_by_valve.get(v.id, {})) for v in config.valves)
    out.write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, valves=valves))).encode())
    return out


def test_rerun_replaces(archive, tmp_path):
    wh = _warehouse(tmp_path, archive)
    first = run_monitor(archive / "plant.toml", wh)
    assert [r.windows for r in first] == [12, 12]
    fits1 = _table(wh, FITS)
    sel1 = _table(wh, "SELECT count(*) AS n FROM selection_stats")["n"][0]
    assert fits1.height == 2 * 12 * 4
    again = run_monitor(archive / "plant.toml", wh)
    assert [r.status_counts for r in again] == [r.status_counts for r in first]
    fits2 = _table(wh, FITS)
    assert fits2.equals(fits1)  # same rows, same values, no duplicates
    assert _table(wh, "SELECT count(*) AS n FROM selection_stats")["n"][0] == sel1
    assert _table(wh, "SELECT count(*) AS n FROM baselines")["n"][0] == 8  # reused, not remade
    # a part of the span only replaces that part
    run_monitor(archive / "plant.toml", wh, valve_ids=["V002"], start=(DAY0 + timedelta(days=1)).isoformat())
    assert _table(wh, FITS).equals(fits1)
    # bounds inside windows: only the windows that start in [from, to) are refitted, whole
    with connect(wh) as con:
        con.execute("UPDATE edge_fits SET alpha_hat = -1")
    cut = run_monitor(archive / "plant.toml", wh, valve_ids=["V001"], start=DAY0 + timedelta(hours=4, seconds=5),
                      end=DAY0 + timedelta(hours=12, seconds=5))  # fmt: skip
    assert cut[0].windows == 2  # 08:00 and 12:00; the 04:00 window began before --from
    now = _table(wh, FITS)
    redone = (pl.col("valve_id") == "V001") & pl.col("window_start").is_in([DAY0 + timedelta(hours=8), DAY0 + timedelta(hours=12)])
    assert now.filter(redone).equals(fits1.filter(redone))
    assert (now.filter(~redone)["alpha_hat"].drop_nulls() == -1).all() and now.height == fits1.height


def test_changed_baseline_definition_makes_new_version(archive, tmp_path):
    wh = _warehouse(tmp_path, archive)
    run_monitor(archive / "plant.toml", wh)
    # V001 gets a commissioning window (its first day): a new baseline version, fitted (step 4a)
    commissioning = (DAY0, DAY0 + timedelta(days=1))
    cfg = _config_with(archive / "plant.toml", tmp_path / "plant.toml", V001={"baseline_window": commissioning})
    run_monitor(cfg, wh)
    b = _table(wh, "SELECT valve_id, edge, version, source, plausible, n_points FROM baselines ORDER BY valve_id, edge, version")
    v1 = b.filter(pl.col("valve_id") == "V001")
    assert v1.height == 8 and sorted(set(v1["version"])) == [1, 2]
    new = v1.filter(pl.col("version") == 2)
    assert set(new["source"]) == {"commissioning"} and new["plausible"].all() and (new["n_points"] >= 500).all()
    assert b.filter(pl.col("valve_id") == "V002")["version"].to_list() == [1] * 4  # unchanged
    fits = _table(wh, FITS)
    assert set(fits.filter(pl.col("valve_id") == "V001")["baseline_version"]) == {2}
    assert set(fits.filter(pl.col("valve_id") == "V002")["baseline_version"]) == {1}
    # against its own commissioning day a wearing valve barely changes within two days
    ok = fits.filter((pl.col("valve_id") == "V001") & (pl.col("status") == "ok"))
    assert ok.height >= 40 and (ok["alpha_hat"] - 1).abs().max() < 0.02 and ok["x_hat_pct"].abs().max() < 0.5
    # a design change (the head-side volume, piping included, measured again) makes version 3
    valve = load_plant_config(cfg).valve("V001")
    cfg2 = _config_with(cfg, tmp_path / "plant2.toml", V001={"baseline_window": commissioning, "v01_m3": valve.v01_m3 + 0.1e-3})
    run_monitor(cfg2, wh, valve_ids=["V001"])
    assert _table(wh, "SELECT max(version) AS v FROM baselines WHERE valve_id = 'V001'")["v"][0] == 3
    assert set(_table(wh, FITS).filter(pl.col("valve_id") == "V001")["baseline_version"]) == {3}


def test_edge_law_not_the_configured_one_is_named(archive, tmp_path):
    """The archive's V001 has Eq. 3 edges; configured as sharp-edged, its commissioning window
    shows the curved Eq. 3 law instead: the baselines follow that law and say so, and so does
    valve_condition's reason (what a linear-gradient valve configured as Eq. 3 gets the other way
    round: tests/monitoring/test_shift_any_law.py)."""
    from flows.report.publish import publish

    wh = _warehouse(tmp_path, archive)
    config = load_plant_config(archive / "plant.toml")
    sharp = dataclasses.replace(config.valve("V001").design, area_law="sharp")
    valves = tuple(dataclasses.replace(v, type="servo_sharp", design=sharp, baseline_window=(DAY0, DAY0 + timedelta(days=1)))
                   if v.id == "V001" else v for v in config.valves)  # fmt: skip
    config = dataclasses.replace(config, valve_types={**config.valve_types, "servo_sharp": sharp}, valves=valves)
    cfg = tmp_path / "plant.toml"
    cfg.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    assert load_plant_config(cfg).valve("V001").design.area_law == "sharp"
    run_monitor(cfg, wh, valve_ids=["V001"])
    b = _table(wh, "SELECT edge, edge_law, edge_law_note FROM baselines WHERE valve_id = 'V001'")
    assert set(b["edge_law"]) == {"eq3"}
    note = b["edge_law_note"][0]
    assert "not the configured straight" in note and 'area_law = "eq3"' in note and b["edge_law_note"].n_unique() == 1
    publish(cfg, wh)
    cond = _table(wh, "SELECT edge, reason, edge_law FROM valve_condition WHERE valve_id = 'V001'")
    assert cond.height == 4 and set(cond["edge_law"]) == {"eq3"}
    assert all(r.endswith("; " + note) for r in cond["reason"]), cond["reason"].to_list()


def test_commissioning_window_without_data(archive, tmp_path):
    wh = _warehouse(tmp_path, archive)
    empty = (DAY0 + timedelta(days=30), DAY0 + timedelta(days=31))
    cfg = _config_with(archive / "plant.toml", tmp_path / "plant.toml", V002={"baseline_window": empty})
    with pytest.raises(ValvemonError, match=r"valve V002: its baseline_window .* holds no lake data"):
        run_monitor(cfg, wh, valve_ids=["V002"])
    assert _table(wh, "SELECT count(*) AS n FROM baselines WHERE valve_id = 'V002'")["n"][0] == 0


def test_unknown_valve_named(archive, tmp_path):
    wh = tmp_path / "wh"
    with pytest.raises(ValvemonError, match="no valve 'V999'"):
        run_monitor(archive / "plant.toml", wh, valve_ids=["V001", "V999"])
    with pytest.raises(ValvemonError, match="later than"):
        run_monitor(archive / "plant.toml", wh, start="2025-01-02", end="2025-01-01")


def test_windows_without_estimate_are_recorded(archive, short_windows, tmp_path):
    wh = _warehouse(tmp_path, archive, short_windows)
    reports = run_monitor(archive / "plant.toml", wh)
    assert [r.windows for r in reports] == [18, 18]
    fits = _table(wh, FITS)
    assert fits.height == 2 * 18 * 4  # every window, every edge: a row
    short = fits.filter(pl.col("window_start") >= DAY0 + timedelta(days=2))
    assert short.height == 2 * 6 * 4
    assert set(short["status"]) <= {"no_points", "too_few_points"} and short["alpha_hat"].is_null().all()
    assert (short["n_points"] < 500).all()
    for r in reports:
        assert sum(r.status_counts.values()) == 18 * 4 and r.status_counts.get("ok", 0) == r.fits_ok
    # and their selection counts are kept too
    sel = _table(wh, "SELECT DISTINCT valve_id, window_start FROM selection_stats")
    assert sel.height == 2 * 18


def _shift_exports(src: Path, dst: Path, seconds: float) -> Path:
    """A copy of an archive whose export time stamps, and its valves' commissioning, are moved by
    ``seconds`` (the ingest quarantines samples from before ``commissioned``)."""
    shutil.copytree(src, dst)
    config = load_plant_config(dst / "plant.toml")
    moved = [dataclasses.replace(v, commissioned=v.commissioned + timedelta(seconds=seconds)) for v in config.valves]
    (dst / "plant.toml").write_bytes(tomli_w.dumps(plant_config_to_dict(dataclasses.replace(config, valves=tuple(moved)))).encode())
    for f in sorted((dst / "exports").glob("*.parquet")):
        pl.read_parquet(f).with_columns(pl.col("timestamp") + pl.duration(microseconds=int(seconds * 1e6))).write_parquet(f)
    return dst


def test_chunking_never_splits_a_window(archive, tmp_path):
    """Windows 5 s before each 00:00: the one at midnight between the two days lies in two lake
    partitions. One-day chunks and the default week give the same fits, and that window is one
    window of 10 s in both."""
    shifted = _shift_exports(archive, tmp_path / "shifted", -5.0)
    wh = _warehouse(tmp_path, shifted)
    days = _table(wh, "SELECT DISTINCT CAST(timestamp_utc AS DATE) AS d FROM read_parquet('" + str(wh / "lake" / "sensors") + "/**/*.parquet') ORDER BY d")
    assert days.height == 3  # 31 Dec (the first window's 5 s), 1 Jan, 2 Jan
    run_monitor(shifted / "plant.toml", wh, chunk_days=1)
    one = _table(wh, FITS)
    run_monitor(shifted / "plant.toml", wh)  # default CHUNK_DAYS, replaces
    week = _table(wh, FITS)
    assert fm.CHUNK_DAYS == 7 and one.equals(week)
    assert one.height == 2 * 12 * 4
    midnight = one.filter(pl.col("window_start") == DAY0 + timedelta(days=1) - timedelta(seconds=5))
    assert midnight.height == 8
    assert ((midnight["window_end"] - midnight["window_start"]).dt.total_milliseconds() == 9_999).all()
    # the same windows as the unshifted archive, fitted the same (5 s earlier)
    ref_wh = _warehouse(tmp_path / "ref", archive)
    run_monitor(archive / "plant.toml", ref_wh, chunk_days=1)
    ref = _table(ref_wh, FITS)
    assert ref.select("valve_id", "edge", "status", "n_points").equals(one.select("valve_id", "edge", "status", "n_points"))
    assert (ref["alpha_hat"] - one["alpha_hat"]).abs().max() < 1e-9


def test_fit_tables_drop_the_unique_indexes_of_earlier_versions(tmp_path):
    """edge_fits and selection_stats keep their keys by replace-in-one-transaction (the rerun tests
    above); an index an earlier version made is dropped, the baselines' stays."""
    with connect(tmp_path) as con:
        fm.ensure_monitor_tables(con)
        for name, (_, key) in fm.MONITOR_TABLES.items():
            con.execute(f"CREATE UNIQUE INDEX IF NOT EXISTS {name}_key ON {name} ({', '.join(key)})")
        fm.ensure_monitor_tables(con)
        names = sorted(r[0] for r in con.sql("SELECT index_name FROM duckdb_indexes()").fetchall())
    assert names == ["baselines_key"]


def test_span_bounds_read_whole_windows_and_little_else(tmp_path):
    # runs of 1 s samples (gap limit 1.5 s) around a span [D1, D2): A straddles D1 (left out),
    # B lies inside, B2 ends 6 s before D2, C starts 1 s before D2 and runs for three hours
    # (longer than RUN_LOOKAHEAD: read to its end), D starts after D2 (left out)
    from flows.common.lake import SENSOR_POLARS_SCHEMA, partition_path, write_partition

    d1, d2 = DAY0 + timedelta(days=1), DAY0 + timedelta(days=2)
    runs = {
        "A": (d1 - timedelta(hours=1), 7200),
        "B": (d1 + timedelta(hours=2), 600),
        "B2": (d2 - timedelta(seconds=65), 60),
        "C": (d2 - timedelta(seconds=1), 3 * 3600),
        "D": (d2 + timedelta(hours=4), 600),
    }
    times = sorted(t0 + timedelta(seconds=i) for t0, n in runs.values() for i in range(n))
    lake = pl.DataFrame({"timestamp_utc": times}).with_columns(
        pl.lit("V9").alias("valve_id"), pl.col("timestamp_utc").dt.date().alias("date"),
        *(pl.lit(0.0).alias(c) for c in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m", "x_ref_m")),
    ).select(SENSOR_POLARS_SCHEMA.names()).cast(dict(SENSOR_POLARS_SCHEMA))  # fmt: skip
    for (day,), part in lake.partition_by("date", as_dict=True).items():
        write_partition(partition_path(tmp_path, "V9", day), part)
    got = pl.concat(fm.lake_chunks(tmp_path, "V9", 1.5, d1, d2, days=1, columns=("p1_pa",)))
    starts = got.filter(pl.col("timestamp_utc").diff().dt.total_seconds().fill_null(99) > 1.5)["timestamp_utc"].to_list()
    assert starts == [runs["B"][0], runs["B2"][0], runs["C"][0]]
    assert got["timestamp_utc"].max() == runs["C"][0] + timedelta(seconds=3 * 3600 - 1)
    assert got.height == 600 + 60 + 3 * 3600
    # the first gap after D2 is two hours past the lookahead: _run_end looked that far
    assert fm._run_end(tmp_path, "V9", 1.5, d2) >= runs["C"][0] + timedelta(seconds=3 * 3600)
    assert fm._run_end(tmp_path, "V9", 1.5, d2 + timedelta(hours=5)) == d2 + timedelta(hours=5)  # no data after


@pytest.mark.parametrize("gaps", [[], [5], [100, 250_000], [299_999], [10, 20, 70_000]])
def test_last_window_found_from_the_end(gaps):
    # 1 ms steps, a 1 s jump before each index in `gaps`; the search looks at 64 k samples first,
    # then at four times as many: a gap far from the end must still be found
    steps = np.full(300_000, 1_000, dtype=np.int64)
    steps[0] = 0
    steps[gaps] = 1_000_000
    t = pl.Series(np.cumsum(steps) + 1_700_000_000_000_000).cast(pl.Datetime("us", "UTC"))
    assert fm._last_window(t, 0.005) == (max(gaps) if gaps else 0)

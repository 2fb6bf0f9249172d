"""One hand-written export per historian quirk, each ending in the expected lake (or quarantine)."""

from __future__ import annotations

import gzip
import shutil
from datetime import datetime, timedelta, timezone

import polars as pl
import pytest
from polars.testing import assert_frame_equal

from tests.ingest.conftest import BASE, DATA, T0, base_lake, expected_lake, ingest, lake, table

LONG_QUALITY = dict(layout="long", timestamp_column="timestamp", tag_column="tag", value_column="value", quality_column="quality")
WIDE = dict(layout="wide", timestamp_column="timestamp", tag_column=None, value_column=None, quality_column=None, good_quality=None)


def test_long_csv_time_major(plant, tmp_path):
    cfg, _ = plant()
    report = ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert (report.rows_read, report.rows_written, report.quarantined, report.duplicates, report.gaps) == (30, 5, 0, 0, 0)


def test_pi_tag_major_seven_fraction_digits_and_digital_states(plant, tmp_path):
    """PI: one block per tag, 100 ns timestamps, digital states instead of numbers, no quality column."""
    cfg, _ = plant(timestamp_column="timestamp", quality_column=None, good_quality=None)
    report = ingest(cfg, DATA / "pi_tag_major.csv", tmp_path / "wh")
    want = dict(BASE)
    want["pr"] = [2.0, 2.5, (2.5 + 2.25) / 2, 2.25, 1.75]  # the I/O Timeout sample is interpolated
    want["p1"] = [100.0, 101.5, 102.0, (102.0 + 104.0) / 2, 104.0]  # the Bad Input sample too
    got = lake(tmp_path / "wh")
    assert_frame_equal(got, expected_lake([T0 + timedelta(seconds=i) for i in range(5)], want), check_exact=False, rel_tol=2e-7)
    q = table(tmp_path / "wh", "quarantine").sort("line")
    assert q.select("line", "tag", "value_raw", "reason").rows() == [
        (7, "MILL1.V017.PS", "Shutdown", "non_numeric"),
        (10, "MILL1.V017.PR", "I/O Timeout", "non_numeric"),
        (16, "MILL1.V017.P1", "Bad Input", "non_numeric"),
    ]
    assert q["source_file"].unique().to_list() == [str(DATA / "pi_tag_major.csv")]
    assert q["timestamp_raw"][0] == "2025-03-01T12:00:05.0000000Z"
    assert report.quarantined == 3 and report.rows_read == 31


def test_ignition_tall_epoch_ms_with_quality_codes(plant, tmp_path):
    """Ignition "tall": epoch milliseconds, quality 192 = good; a bad-quality row is set aside."""
    cfg, _ = plant(timestamp_format="epoch_ms", timestamp_column="t_stamp", tag_column="tagpath", value_column="floatvalue", quality_column="dataintegrity")
    ingest(cfg, DATA / "ignition_tall_epoch.csv", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    q = table(tmp_path / "wh", "quarantine")
    assert q.select("line", "tag", "value_raw", "quality", "reason").rows() == [(17, "MILL1.V017.P2", "999.0", "0", "bad_quality")]


def test_wincc_semicolon_decimal_comma_local_strftime(plant, tmp_path):
    """WinCC: ';' separated, decimal comma, '%d.%m.%Y %H:%M:%S%.f' in local time (CET = UTC+1)."""
    cfg, _ = plant(
        separator=";", decimal=",", timestamp_format="%d.%m.%Y %H:%M:%S%.f",
        timestamp_column="Zeit", tag_column="Variable", value_column="Wert", quality_column="Qualitaet",
    )  # fmt: skip
    ingest(cfg, DATA / "wincc_semicolon_decimal_comma.csv", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


def test_iba_wide_tab_separated_decimal_comma(plant, tmp_path):
    """ibaAnalyzer ASCII: wide, tab separated, decimal comma also in the time, local time."""
    cfg, _ = plant(**(WIDE | dict(timestamp_column="Time", separator="\t", decimal=",", timestamp_format="%Y-%m-%d %H:%M:%S,%3f")))
    ingest(cfg, DATA / "iba_wide_tab.txt", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


def test_ignition_wide_with_offsets_and_a_blank_line(plant, tmp_path):
    cfg, _ = plant(**(WIDE | dict(timestamp_column="t_stamp")))
    report = ingest(cfg, DATA / "ignition_wide_offset.csv", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert report.rows_read == 5 and report.samples_read == 30


def test_gzip_csv(plant, tmp_path):
    cfg, _ = plant()
    gz = tmp_path / "base_long.csv.gz"
    gz.write_bytes(gzip.compress((DATA / "base_long.csv").read_bytes()))
    ingest(cfg, gz, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert table(tmp_path / "wh", "ingest_manifest")["file_format"].to_list() == ["csv.gz"]


def test_out_of_order_rows_are_sorted(plant, tmp_path):
    cfg, _ = plant()
    ingest(cfg, DATA / "out_of_order.csv", tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


@pytest.mark.parametrize("rule, p1_at_2s", [("last", 150.0), ("first", 102.0)])
def test_duplicates_dropped_and_conflicts_resolved_by_rule(plant, tmp_path, rule, p1_at_2s):
    cfg, _ = plant(duplicate_rule=rule)
    report = ingest(cfg, DATA / "duplicates.csv", tmp_path / "wh")
    want = {s: v[:3] for s, v in BASE.items()}
    want["p1"] = [100.0, 101.5, p1_at_2s]
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([T0 + timedelta(seconds=i) for i in range(3)], want))
    assert (report.duplicates, report.conflicts) == (2, 1)
    m = table(tmp_path / "wh", "ingest_manifest").row(0, named=True)
    assert (m["duplicates"], m["conflicts"], m["rows_in"], m["rows_out"]) == (2, 1, 21, 3)


def test_gaps_are_recorded_and_not_interpolated(plant, tmp_path):
    """1 Hz grid, max_gap_s = 2.5: the 2 s hole is interpolated, the 5 s gap is not."""
    cfg, _ = plant(**(WIDE | dict(timestamp_column="timestamp")))
    report = ingest(cfg, DATA / "gap.csv", tmp_path / "wh")
    secs = [0, 1, 2, 3, 8, 9]
    want = {
        "ps": [210.0, 210.5, 211.0, 211.5, 209.0, 209.5],
        "pr": [2.0, 2.5, 2.5, 2.5, 1.5, 2.0],
        "p1": [100.0, 101.5, 102.5, 103.5, 104.0, 104.5],
        "p2": [90.0, 89.5, 89.0, 88.5, 88.0, 87.5],
        "x_spool": [0.1, 0.2, 0.30000000000000004, 0.4, 0.5, 0.6],
        "x_cyl": [300.0, 300.5, 301.0, 301.5, 302.0, 302.5],
    }
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([T0 + timedelta(seconds=s) for s in secs], want), check_exact=False, rel_tol=2e-7)
    gaps = table(tmp_path / "wh", "ingest_gaps")
    assert report.gaps == 6 and gaps.height == 6
    assert set(gaps["gap_start"].to_list()) == {T0 + timedelta(seconds=3)}
    assert set(gaps["gap_end"].to_list()) == {T0 + timedelta(seconds=8)}
    assert set(gaps["duration_s"].to_list()) == {5.0}


def test_compressed_irregular_data_is_interpolated_in_time(plant, tmp_path):
    """PI-compressed samples off the grid: linear in time between the bracketing samples."""
    cfg, _ = plant(max_gap_s=5.0)
    ingest(cfg, DATA / "compressed.csv", tmp_path / "wh")
    want = {
        "ps": [210.0, 212.0, 214.0, 214.0],
        "pr": [2.125, 2.375, 2.625, 2.875],
        "p1": [100.0, 101.0, 102.0, 103.0],
        "p2": [90.0, 90.0, 90.0, 90.0],
        "x_spool": [0.0, 0.4, 0.5, 0.5],
        "x_cyl": [300.0, 301.0, 302.0, 303.0],
    }
    got = lake(tmp_path / "wh")
    assert_frame_equal(got, expected_lake([T0 + timedelta(seconds=i) for i in range(4)], want), check_exact=False, rel_tol=2e-7, abs_tol=1e-12)
    # samples exactly on the grid keep their value bit for bit
    assert got["p1_pa"].to_list() == [100.0 * 1e5, 101.0 * 1e5, 102.0 * 1e5, 103.0 * 1e5]
    assert got["ps_pa"][0] == 210.0 * 1e5 and got["ps_pa"][3] == 214.0 * 1e5


def test_utc_midnight_splits_partitions_and_optional_x_ref(plant, tmp_path):
    cfg, _ = plant(**(WIDE | dict(timestamp_column="timestamp")))
    ingest(cfg, DATA / "midnight.csv", tmp_path / "wh")
    t = datetime(2025, 3, 1, 23, 59, 58, tzinfo=timezone.utc)
    want = {s: v[:4] for s, v in BASE.items()} | {"x_ref": [0.1, (0.1 - 0.25) / 2, -0.25, 0.35]}
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([t + timedelta(seconds=i) for i in range(4)], want), check_exact=False, rel_tol=2e-7)
    parts = sorted(p.relative_to(tmp_path / "wh").as_posix() for p in (tmp_path / "wh").rglob("*.parquet"))
    assert parts == [
        "lake/sensors/valve_id=V017/date=2025-03-01/part-0.parquet",
        "lake/sensors/valve_id=V017/date=2025-03-02/part-0.parquet",
    ]
    # the keys are inside the files too
    inside = pl.read_parquet(tmp_path / "wh" / parts[1], hive_partitioning=False)
    assert inside["valve_id"].unique().to_list() == ["V017"] and inside["date"].unique().to_list() == [datetime(2025, 3, 2).date()]


@pytest.mark.parametrize("fixture", ["dst_autumn_long.csv", "dst_autumn_wide.csv"])
def test_dst_autumn_repeated_hour_resolved_by_row_order(plant, tmp_path, fixture):
    """Local 02:59:58, 02:59:59 (summer time), then 02:00:00, 02:00:01 (winter time): four
    consecutive UTC seconds across the change."""
    layout = {} if "long" in fixture else WIDE | dict(timestamp_column="timestamp")
    cfg, _ = plant(**layout)
    ingest(cfg, DATA / fixture, tmp_path / "wh")
    t = datetime(2025, 10, 26, 0, 59, 58, tzinfo=timezone.utc)
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([t + timedelta(seconds=i) for i in range(4)], {s: v[:4] for s, v in BASE.items()}))


def test_same_data_long_wide_parquet_and_gzip_give_identical_lakes(plant, tmp_path):
    cfg_long, _ = plant("long.toml")
    cfg_wide, _ = plant("wide.toml", **(WIDE | dict(timestamp_column="timestamp")))
    long_df = pl.read_csv(DATA / "base_long.csv")
    wide_df = pl.read_csv(DATA / "base_wide.csv")
    # Parquet as historians write it: typed UTC timestamps and float values
    long_pq, wide_pq = tmp_path / "long.parquet", tmp_path / "wide.parquet"
    long_df.with_columns(pl.col("timestamp").str.to_datetime(time_zone="UTC")).write_parquet(long_pq)
    wide_df.with_columns(pl.col("timestamp").str.to_datetime(time_zone="UTC")).write_parquet(wide_pq)
    gz = tmp_path / "wide.csv.gz"
    gz.write_bytes(gzip.compress((DATA / "base_wide.csv").read_bytes()))
    lakes = {}
    for name, cfg, path in [
        ("long_csv", cfg_long, DATA / "base_long.csv"),
        ("wide_csv", cfg_wide, DATA / "base_wide.csv"),
        ("long_parquet", cfg_long, long_pq),
        ("wide_parquet", cfg_wide, wide_pq),
        ("wide_gz", cfg_wide, gz),
    ]:
        ingest(cfg, path, tmp_path / name)
        lakes[name] = lake(tmp_path / name)
    for name, frame in lakes.items():
        assert_frame_equal(frame, lakes["long_csv"], check_exact=True), name
    assert_frame_equal(lakes["long_csv"], base_lake())


def test_parquet_with_text_timestamps_and_values(plant, tmp_path):
    """A Parquet export whose columns are text (as some historians write) reads like the CSV."""
    cfg, _ = plant()
    path = tmp_path / "text.parquet"
    pl.read_csv(DATA / "base_long.csv", infer_schema=False).write_parquet(path)
    ingest(cfg, path, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


def test_folder_argument_finds_exports_recursively(plant, tmp_path):
    cfg, _ = plant()
    folder = tmp_path / "exports" / "2025" / "03"
    folder.mkdir(parents=True)
    shutil.copy(DATA / "base_long.csv", folder / "a.csv")
    (folder / "notes.md").write_text("not an export")
    report = ingest(cfg, tmp_path / "exports", tmp_path / "wh")
    assert report.files_seen == 1 and report.files_ingested == 1
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


def test_wide_quality_column_quarantines_the_whole_row(plant, tmp_path):
    cfg, _ = plant(**(WIDE | dict(timestamp_column="timestamp", quality_column="q", good_quality=["Good"])))
    lines = (DATA / "base_wide.csv").read_text().splitlines()
    rows = [lines[0] + ",q"] + [r + (",Bad" if i == 2 else ",Good") for i, r in enumerate(lines[1:])]
    path = tmp_path / "wide_q.csv"
    path.write_text("\n".join(rows) + "\n")
    report = ingest(cfg, path, tmp_path / "wh")
    want = dict(BASE)
    for s, v in BASE.items():  # second 2 is interpolated from seconds 1 and 3
        want[s] = [v[0], v[1], (v[1] + v[3]) / 2, v[3], v[4]]
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([T0 + timedelta(seconds=i) for i in range(5)], want), check_exact=False, rel_tol=2e-7)
    q = table(tmp_path / "wh", "quarantine")
    assert report.quarantined == 6 and set(q["reason"]) == {"bad_quality"} and set(q["line"]) == {4}


def test_text_that_is_not_utf8_is_read_and_quarantined(plant, tmp_path):
    """A Latin-1 digital state ("Störung") in a UTF-8 export: the file is still read."""
    cfg, _ = plant()
    path = tmp_path / "latin1.csv"
    raw = (DATA / "base_long.csv").read_bytes() + "2025-03-01T12:00:05.000Z,MILL1.V017.PS,Störung,Good\n".encode("latin-1")
    path.write_bytes(raw)
    report = ingest(cfg, path, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    q = table(tmp_path / "wh", "quarantine").row(0, named=True)
    assert report.quarantined == 1 and q["line"] == 32 and q["reason"] == "non_numeric" and q["value_raw"].startswith("St")


def test_units_from_the_configuration_including_percent_of_x_max(plant, tmp_path):
    """psi, MPa, kPa, Pa, µm, m and the spool position in % of x_max (3.5 mm)."""
    units = {"ps": "psi", "pr": "MPa", "p1": "kPa", "p2": "Pa", "x_spool": "%", "x_cyl": "um"}
    cfg, _ = plant(units=units)
    ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")
    got = lake(tmp_path / "wh")
    factor = {"ps": 6894.757293168361, "pr": 1e6, "p1": 1e3, "p2": 1.0, "x_spool": 3.5e-3 / 100, "x_cyl": 1e-6}
    for signal, column in [("ps", "ps_pa"), ("pr", "pr_pa"), ("p1", "p1_pa"), ("p2", "p2_pa"), ("x_spool", "x_spool_m"), ("x_cyl", "x_cyl_m")]:
        want = pl.Series([v * factor[signal] for v in BASE[signal]]).cast(got[column].dtype)
        assert got[column].to_list() == want.to_list(), signal
    assert got["x_spool_m"][4] == pytest.approx(0.5 / 100 * 3.5e-3, rel=1e-7)  # 0.5 % of 3.5 mm

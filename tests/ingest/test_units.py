"""The pieces on their own: timestamps, grid, merge, row groups, lake reads."""

from __future__ import annotations

from datetime import date, datetime, timedelta, timezone

import numpy as np
import polars as pl
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from polars.testing import assert_frame_equal

from flows.common.lake import partition_path, read_lake, row_group_bounds, write_partition
from tests.ingest.conftest import DATA, base_lake, ingest
from transforms.ingest import Grid, IngestError, merge_partition, parse_timestamps, prepare_tag, to_grid
from transforms.ingest.samples import split_by_tag

UTC = timezone.utc


def _utc(*a):
    return datetime(*a, tzinfo=UTC)


# --- timestamps -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, expected_ns",
    [
        ("2025-03-01T12:00:00.1234567Z", 1_740_830_400_123_456_700),  # PI: 7 digits, 100 ns kept
        ("2025-03-01T13:00:00.5+01:00", 1_740_830_400_500_000_000),
        ("2025-03-01T13:00:00+0100", 1_740_830_400_000_000_000),
        ("2025-03-01 12:00:00Z", 1_740_830_400_000_000_000),
        ("2025-03-01T12:00:00.000000001Z", 1_740_830_400_000_000_001),
    ],
)
def test_iso8601_with_offsets_and_fractions(text, expected_ns):
    got = parse_timestamps(pl.Series([text]), "iso8601", "Europe/Vienna")
    assert got.dtype == pl.Datetime("ns", "UTC") and got.to_physical()[0] == expected_ns


def test_iso8601_mixed_offsets_and_local_in_one_column():
    s = pl.Series(["2025-03-01T12:00:00Z", "2025-03-01T13:00:01+01:00", "2025-03-01T13:00:02"])
    assert parse_timestamps(s, "iso8601", "Europe/Vienna").to_list() == [_utc(2025, 3, 1, 12, 0, s) for s in range(3)]


def test_epoch_ms_text_and_numbers():
    assert parse_timestamps(pl.Series(["1740830400123", "1740830400123.5"]), "epoch_ms", "UTC").to_physical().to_list() == [1_740_830_400_123_000_000, 1_740_830_400_123_500_000]
    assert parse_timestamps(pl.Series([1740830400123]), "epoch_ms", "UTC").to_list() == [_utc(2025, 3, 1, 12, 0, 0, 123000)]


def test_typed_timestamps_naive_ones_are_local():
    naive = pl.Series([datetime(2025, 7, 1, 14, 0)])
    zoned = pl.Series([datetime(2025, 7, 1, 14, 0)]).dt.replace_time_zone("America/New_York")
    assert parse_timestamps(naive, "iso8601", "Europe/Vienna").to_list() == [_utc(2025, 7, 1, 12, 0)]
    assert parse_timestamps(zoned, "iso8601", "Europe/Vienna").to_list() == [_utc(2025, 7, 1, 18, 0)]


def test_autumn_row_order_is_judged_per_tag():
    """Tags A and B each stay inside the repeated hour without going back: their order cannot tell
    the pass (refused by default, issue 46), and with export.ambiguous_time = "earlier" both are
    summer time, each tag judged on its own rows (B's 02:10 after A's 02:30 is no step back)."""
    s = pl.Series(["2025-10-26 02:30:00", "2025-10-26 02:10:00", "2025-10-26 02:40:00", "2025-10-26 02:20:00", "2025-10-26 02:50:00"])
    groups = pl.Series([0, 1, 0, 1, 0])
    with pytest.raises(IngestError, match="is in the hour Europe/Vienna repeats"):
        parse_timestamps(s, "iso8601", "Europe/Vienna", groups=groups)
    got = parse_timestamps(s, "iso8601", "Europe/Vienna", groups=groups, ambiguous="earlier").to_list()
    # A: 02:30 summer, 02:40 summer, 02:50 summer (never went back); B: 02:10, 02:20 summer
    assert got == [_utc(2025, 10, 26, 0, 30), _utc(2025, 10, 26, 0, 10), _utc(2025, 10, 26, 0, 40), _utc(2025, 10, 26, 0, 20), _utc(2025, 10, 26, 0, 50)]
    s2 = pl.Series(["2025-10-26 02:30:00", "2025-10-26 02:10:00", "2025-10-26 02:40:00"])
    got2 = parse_timestamps(s2, "iso8601", "Europe/Vienna").to_list()  # one sequence: went back at row 2
    assert got2 == [_utc(2025, 10, 26, 0, 30), _utc(2025, 10, 26, 1, 10), _utc(2025, 10, 26, 1, 40)]


def test_spring_gap_names_the_line_and_tag():
    s = pl.Series(["2025-03-30 01:59:59", "2025-03-30 02:00:00"])
    with pytest.raises(IngestError) as err:
        parse_timestamps(s, "iso8601", "Europe/Vienna", lines=pl.Series([10, 11]), tags=pl.Series(["A", "B"]))
    assert err.value.line == 11 and err.value.tag == "B" and "does not exist in Europe/Vienna" in str(err.value)


def test_strftime_pattern_local_and_with_offset():
    assert parse_timestamps(pl.Series(["01.03.2025 13:00:00.250"]), "%d.%m.%Y %H:%M:%S%.f", "Europe/Vienna").to_list() == [_utc(2025, 3, 1, 12, 0, 0, 250000)]
    assert parse_timestamps(pl.Series(["01.03.2025 14:00:00 +0200"]), "%d.%m.%Y %H:%M:%S %z", "Europe/Vienna").to_list() == [_utc(2025, 3, 1, 12, 0)]


# --- grid -------------------------------------------------------------------------------------


def test_exactly_gridded_input_is_bit_identical():
    rng = np.random.default_rng(1)
    t = np.arange(1000, dtype=np.int64) * 1_000_000 + 1_740_830_400_000_000_000
    v = rng.standard_normal(1000) * 1e7
    g = to_grid(t, v, Grid.from_export(1000.0, 0.005))
    assert np.array_equal(g.t_us, t // 1000) and g.values.tobytes() == v.tobytes()
    # also through the general path (a hole inside the gap limit forces interpolation there only)
    keep = np.ones(1000, dtype=bool)
    keep[500] = False
    g2 = to_grid(t[keep], v[keep], Grid.from_export(1000.0, 0.005))
    assert np.array_equal(g2.t_us, t // 1000)
    assert g2.values[keep].tobytes() == v[keep].tobytes()
    assert g2.values[500] == pytest.approx((v[499] + v[501]) / 2, rel=1e-12)


def test_grid_is_aligned_to_utc_multiples_of_the_period_and_never_extrapolates():
    grid = Grid.from_export(4.0, 1.0)  # 250 ms
    t = np.array([100_000_000, 600_000_000, 1_100_000_000], dtype=np.int64)  # 0.1 s, 0.6 s, 1.1 s
    g = to_grid(t, np.array([0.0, 5.0, 10.0]), grid)
    assert g.t_us.tolist() == [250_000, 500_000, 750_000, 1_000_000]
    assert g.values.tolist() == pytest.approx([1.5, 4.0, 6.5, 9.0])


def test_gap_splits_segments_and_is_reported():
    grid = Grid.from_export(1.0, 2.5)
    s = 1_000_000_000
    t = np.array([0, 1, 2, 6, 7], dtype=np.int64) * s
    g = to_grid(t, np.arange(5.0), grid)
    assert (g.t_us // 1_000_000).tolist() == [0, 1, 2, 6, 7]
    assert (g.gap_start_ns.tolist(), g.gap_end_ns.tolist()) == ([2 * s], [6 * s])


def test_prepare_tag_sorts_and_counts_duplicates_and_conflicts():
    t = np.array([3, 1, 2, 1, 2, 2], dtype=np.int64)
    v = np.array([30.0, 10.0, 20.0, 10.0, 21.0, 20.0])
    last = prepare_tag(t, v, np.arange(6), "last")
    assert last.t_ns.tolist() == [1, 2, 3] and last.values.tolist() == [10.0, 20.0, 30.0]
    assert (last.duplicates, last.conflicts) == (2, 1)
    first = prepare_tag(t, v, np.arange(6), "first")
    assert first.values.tolist() == [10.0, 20.0, 30.0]
    v2 = v.copy()
    v2[5] = 22.0
    assert prepare_tag(t, v2, np.arange(6), "last").values.tolist() == [10.0, 22.0, 30.0]
    assert prepare_tag(t, v2, np.arange(6), "first").values.tolist() == [10.0, 20.0, 30.0]


@pytest.mark.parametrize("layout", ["blocks", "interleaved", "interleaved_then_broken", "shuffled"])
def test_split_by_tag_gives_each_tags_rows_in_file_order(layout):
    """Every layout (PI blocks, Ignition "tall" interleaving, an interleaving that breaks in its
    last rows, any order) splits into each tag's times and values in file order."""
    rng = np.random.default_rng(3)
    k, m = 5, 40
    tag_id = {
        "blocks": np.repeat(np.arange(k), m),
        "interleaved": np.tile(np.arange(k), m),
        "interleaved_then_broken": np.r_[np.tile(np.arange(k), m - 1), [0, 2, 1, 3, 4]],
        "shuffled": rng.permutation(np.tile(np.arange(k), m)),
    }[layout].astype(np.uint8)
    t_ns = rng.integers(0, 10**12, len(tag_id))
    values = rng.standard_normal(len(tag_id))
    got = {tid: (t, v, sel) for tid, t, v, sel in split_by_tag(tag_id, t_ns, values)}
    assert sorted(got) == list(range(k))
    for tid, (t, v, sel) in got.items():
        rows = np.flatnonzero(tag_id == tid)
        np.testing.assert_array_equal(t, t_ns[rows])
        np.testing.assert_array_equal(v, values[rows])
        np.testing.assert_array_equal(np.arange(len(tag_id))[sel], rows)


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(st.sampled_from([1000, 1000, 1000, 999, 1001, 2000, 7000, 9000]), min_size=0, max_size=40),
    start=st.integers(-5, 5).map(lambda k: 1_740_830_400_000_000_000 + k * 1000 + (k % 3 == 0) * 17),
)
def test_grid_scan_agrees_with_its_definition(steps, start):
    """The one-pass scan of to_grid and prepare_tag against the definitions it replaces: gaps
    are steps beyond ``max_gap``; "gridded" = every time a grid instant, no instant missing
    inside a segment; the order state."""
    from transforms.ingest.grid import _grid_scan, _order_state

    P, max_gap = 1000, 5000
    t = start + np.r_[0, np.cumsum(steps)].astype(np.int64)
    t_us, n_breaks, gridded = _grid_scan(t, P, max_gap)
    d = np.diff(t)
    np.testing.assert_array_equal(t_us, t // 1000)
    assert n_breaks == int(np.sum(d > max_gap))
    assert gridded == bool(np.all(t % P == 0) and np.all((d == P) | (d > max_gap)))
    assert _order_state(t) == 0
    if len(t) > 2:
        assert _order_state(np.r_[t[:2], t[1:]]) == 1
        assert _order_state(t[::-1].copy()) == 2


def test_sample_rate_must_give_a_whole_microsecond_period():
    assert Grid.from_export(1000.0, 0.005).period_us == 1000
    assert Grid.from_export(8000.0, 0.001).period_us == 125
    with pytest.raises(IngestError, match="whole number of microseconds"):
        Grid.from_export(3000.0, 0.005)


# --- merge ------------------------------------------------------------------------------------


def test_merge_adds_new_rows_keeps_equal_ones_and_applies_the_rule():
    base = base_lake()
    old, new = base[:3], base[2:]
    m = merge_partition(old, new, "last")
    assert_frame_equal(m.frame, base)
    assert (m.rows_added, m.lake_conflicts, m.changed) == (2, 0, True)
    same = merge_partition(base, base[1:4], "error")
    assert (same.changed, same.rows_added) == (False, 0)
    revised = base[2:3].with_columns(pl.col("p1_pa") * 2)
    assert merge_partition(base, revised, "last").frame["p1_pa"][2] == base["p1_pa"][2] * 2
    kept = merge_partition(base, revised, "first")
    assert not kept.changed and kept.lake_conflicts == 1
    with pytest.raises(IngestError, match="column p1_pa"):
        merge_partition(base, revised, "error")


# --- lake -------------------------------------------------------------------------------------


def test_row_groups_follow_windows():
    t = np.concatenate([np.arange(10) * 1000, 3_600_000_000 + np.arange(10) * 1000, 7_200_000_000 + np.arange(25) * 1000])
    assert row_group_bounds(t, 5000, min_rows=10, max_rows=20) == [(0, 10), (10, 20), (20, 40), (40, 45)]
    assert row_group_bounds(t, 5000, min_rows=15, max_rows=100) == [(0, 20), (20, 45)]


def test_partition_file_layout_codec_and_sorting(tmp_path):
    frame = base_lake()
    path = partition_path(tmp_path, "V017", date(2025, 3, 1))
    write_partition(path, frame, gap_us=2_500_000)
    meta = pq.ParquetFile(path).metadata
    assert meta.num_rows == 5 and meta.row_group(0).column(3).compression == "UNCOMPRESSED"  # the default codec
    for codec, name in (("lz4", "LZ4"), ("zstd", "ZSTD")):  # a plant's [lake] codec
        write_partition(path, frame, gap_us=2_500_000, codec=codec)
        assert pq.ParquetFile(path).metadata.row_group(0).column(3).compression == name
        assert_frame_equal(pl.read_parquet(path), frame.sort("timestamp_utc"), check_dtypes=False)
    schema = pq.read_schema(path)
    assert schema.field("timestamp_utc").type.unit == "us" and str(schema.field("timestamp_utc").type.tz) == "UTC"
    assert schema.field("p1_pa").metadata[b"unit"] == b"Pa"
    assert meta.row_group(0).sorting_columns[0].column_index == 2


def test_the_plants_lake_codec_is_what_the_ingest_writes(plant, tmp_path):
    cfg, _ = plant("wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    ingest(cfg, DATA / "midnight.csv", tmp_path / "none")
    cfg.write_text(cfg.read_text() + '\n[lake]\ncodec = "lz4"\n')
    ingest(cfg, DATA / "midnight.csv", tmp_path / "lz4")
    files = {k: sorted((tmp_path / k).rglob("*.parquet")) for k in ("none", "lz4")}
    assert files["none"] and [p.relative_to(tmp_path / "none") for p in files["none"]] == [p.relative_to(tmp_path / "lz4") for p in files["lz4"]]
    for k, name in (("none", "UNCOMPRESSED"), ("lz4", "LZ4")):
        assert {pq.ParquetFile(p).metadata.row_group(0).column(3).compression for p in files[k]} == {name}
    assert read_lake(tmp_path / "lz4").collect().equals(read_lake(tmp_path / "none").collect())


def test_read_lake_filters_valves_and_time(plant, tmp_path):
    cfg, _ = plant("wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    ingest(cfg, DATA / "midnight.csv", tmp_path / "wh")
    all_rows = read_lake(tmp_path / "wh")
    assert isinstance(all_rows, pl.LazyFrame) and all_rows.collect().height == 4
    assert read_lake(tmp_path / "wh", start="2025-03-02").collect().height == 2
    assert read_lake(tmp_path / "wh", end=date(2025, 3, 2)).collect().height == 2
    assert read_lake(tmp_path / "wh", start="2025-03-01T23:59:59Z", end=_utc(2025, 3, 2, 0, 0, 1)).collect()["timestamp_utc"].to_list() == [
        _utc(2025, 3, 1, 23, 59, 59),
        _utc(2025, 3, 2),
    ]
    assert read_lake(tmp_path / "wh", valve_ids=["V999"]).collect().height == 0
    assert read_lake(tmp_path / "nowhere").collect().schema == base_lake().schema
    assert read_lake(tmp_path / "wh", start=_utc(2025, 3, 1) + timedelta(days=5)).collect().height == 0


@pytest.mark.parametrize(
    "start, end",
    [("2025-03-02", "2025-03-03"), ("2025-03-01T23:00:00Z", "2025-03-03T00:30:00Z"), (None, "2025-03-02"), ("2025-03-02T12:00:00Z", None)],
)
def test_read_lake_bounds_at_and_between_midnights(tmp_path, start, end):
    # samples every 30 min over three UTC days; a midnight bound selects partitions only, any
    # other bound filters rows too: either way exactly start <= t < end
    t = [datetime(2025, 3, 1, tzinfo=timezone.utc) + timedelta(minutes=30 * i) for i in range(3 * 48)]
    frame = base_lake(1)
    rows = pl.concat([frame.with_columns(pl.lit(ti).cast(frame.schema["timestamp_utc"]).alias("timestamp_utc"), pl.lit(ti.date()).alias("date")) for ti in t])
    for (day,), part in rows.partition_by("date", as_dict=True).items():
        write_partition(partition_path(tmp_path, "V017", day), part.with_columns(pl.lit("V017").alias("valve_id")))
    got = read_lake(tmp_path, ["V017"], start, end).collect()["timestamp_utc"].to_list()
    lo = datetime.fromisoformat(start).replace(tzinfo=timezone.utc) if start else t[0]
    hi = datetime.fromisoformat(end).replace(tzinfo=timezone.utc) if end else t[-1] + timedelta(seconds=1)
    assert got == [ti for ti in t if lo <= ti < hi]

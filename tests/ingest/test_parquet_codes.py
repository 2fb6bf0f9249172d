"""Parquet exports: text tag and quality columns are read by their dictionary codes
(``flows.ingest.formats.parquet.enum_column``), and the result is the same as reading the text."""

from __future__ import annotations

import polars as pl
import pyarrow as pa
import pytest
from polars.testing import assert_frame_equal

from flows.common.errors import ValvemonError
from flows.ingest.formats.parquet import enum_column
from tests.ingest.conftest import DATA, ingest, lake, table


def _dict_chunks(*chunks: list[str | None]) -> pa.ChunkedArray:
    return pa.chunked_array([pa.array(c, type=pa.string()).dictionary_encode() for c in chunks])


def test_enum_column_maps_each_chunks_own_dictionary():
    col = _dict_chunks(["b", None, "a", "b"], ["c", "a"])  # two row groups, two dictionaries
    got = enum_column(col, ("a", "b", "c", "d"))
    assert got.dtype == pl.Enum(["a", "b", "c", "d"])
    assert got.to_list() == ["b", None, "a", "b", "c", "a"]
    own = enum_column(col)
    assert own.dtype == pl.Enum(["b", "a", "c"]) and own.to_list() == ["b", None, "a", "b", "c", "a"]


def test_enum_column_refuses_a_value_outside_the_categories_or_a_null_in_a_dictionary():
    assert enum_column(_dict_chunks(["a"], ["b", "x"]), ("a", "b")) is None
    with_null = pa.chunked_array([pa.DictionaryArray.from_arrays(pa.array([0, 1], pa.int32()), pa.array(["a", None]))])
    assert enum_column(with_null) is None and enum_column(with_null, ("a",)) is None


def test_enum_column_of_one_code():
    assert enum_column(_dict_chunks(["Good"] * 3, ["Good"])).to_list() == ["Good"] * 4
    assert enum_column(_dict_chunks(["Good", None])).to_list() == ["Good", None]


def _as_parquet(csv, path, **read):
    """The CSV export as a Parquet file of text columns, in row groups of 7 rows (so each row
    group has a dictionary of its own)."""
    pl.read_csv(csv, infer_schema=False, **read).write_parquet(path, row_group_size=7)
    return path


def _quarantine(wh, line_offset):
    q = table(wh, "quarantine").sort("line")
    return q.select(pl.col("line") - line_offset, "tag", "timestamp_raw", "value_raw", "quality", "reason")


@pytest.mark.parametrize(
    "fixture, export",
    [
        ("base_long.csv", {}),
        ("pi_tag_major.csv", dict(quality_column=None, good_quality=None)),  # digital states, no quality
        ("out_of_order.csv", {}),
        ("duplicates.csv", {}),
    ],
)
def test_parquet_export_reads_like_its_csv(plant, tmp_path, fixture, export):
    cfg, _ = plant(**export)
    ingest(cfg, DATA / fixture, tmp_path / "csv")
    ingest(cfg, _as_parquet(DATA / fixture, tmp_path / "x.parquet"), tmp_path / "pq")
    assert_frame_equal(lake(tmp_path / "pq"), lake(tmp_path / "csv"), check_exact=True)
    # a CSV line counts the header; a Parquet row does not
    assert_frame_equal(_quarantine(tmp_path / "pq", 0), _quarantine(tmp_path / "csv", 1))


def test_bad_and_missing_quality_codes_in_parquet(plant, tmp_path):
    cfg, _ = plant()
    lines = (DATA / "base_long.csv").read_text().splitlines()
    lines[5] = lines[5].rsplit(",", 1)[0] + ",Bad"  # CSV line 6, Parquet row 5
    lines[20] = lines[20].rsplit(",", 1)[0] + ","  # no code (CSV line 21, Parquet row 20): bad too
    csv = tmp_path / "q.csv"
    csv.write_text("\n".join(lines) + "\n")
    report = ingest(cfg, _as_parquet(csv, tmp_path / "q.parquet"), tmp_path / "pq")
    ingest(cfg, csv, tmp_path / "csv")
    q = _quarantine(tmp_path / "pq", 0)
    assert q.select("line", "quality", "reason").rows() == [(5, "Bad", "bad_quality"), (20, None, "bad_quality")]
    assert report.quarantined == 2
    assert_frame_equal(q, _quarantine(tmp_path / "csv", 1))
    assert_frame_equal(lake(tmp_path / "pq"), lake(tmp_path / "csv"), check_exact=True)


def test_unknown_tag_in_parquet_is_named_with_its_row(plant, tmp_path):
    cfg, _ = plant(other_tags="error")
    path = _as_parquet(DATA / "unknown_tag.csv", tmp_path / "unknown.parquet")
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, tmp_path / "wh")
    assert str(err.value) == f"{path}: line 3: unknown tag 'MILL1.V099.P1': no valve of the plant configuration has it"


def test_parquet_of_text_columns_only_names_the_missing_column(plant, tmp_path):
    cfg, _ = plant()
    path = tmp_path / "no_time.parquet"
    pl.read_csv(DATA / "base_long.csv", infer_schema=False).select("tag", "quality").write_parquet(path)
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, tmp_path / "wh")
    assert str(err.value).startswith(f"{path}: missing column 'timestamp' (export.timestamp_column)")


@pytest.mark.parametrize(
    ("groups", "rows"),
    [([60_000] * 60, 599_186), ([1_000_000, 10, 10], 300_000), ([5], 1024), ([3, 3, 3], 5), ([7, 1, 7], 8)],
)
def test_typed_parquet_slices_end_at_row_group_ends(tmp_path, groups, rows):
    import numpy as np
    import pyarrow.parquet as pq

    from flows.ingest.formats.parquet import _slices

    path = tmp_path / "groups.parquet"
    with pq.ParquetWriter(path, pa.schema([("x", pa.int64())])) as w:
        for n in groups:
            w.write_table(pa.table({"x": np.arange(n)}), row_group_size=n)
    cuts = _slices(pq.ParquetFile(path).metadata, rows)
    ends = set(np.cumsum(groups).tolist())
    assert cuts[0] == 0 and cuts[-1] == sum(groups) and all(0 < b - a <= rows for a, b in zip(cuts[:-1], cuts[1:]))
    for a, b in zip(cuts[1:-1], cuts[2:]):  # a cut inside a row group only where that row group alone exceeds a slice
        assert a in ends or max(groups) > rows
    assert len(cuts) - 1 <= 2 * (-(-sum(groups) // rows)) + 1

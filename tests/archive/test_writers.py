"""The export writers on hand-made chunks: layouts, time formats, separators, rounding."""

from __future__ import annotations

import dataclasses
import gzip
from datetime import datetime, timezone

import numpy as np
import polars as pl
import pytest

from flows.simulate.writers import ExportColumns, decimals_for_step, open_day_writer
from schemas.plant_config import ExportSpec

T0 = int(datetime(2025, 3, 30, 0, 59, 59, 998000, tzinfo=timezone.utc).timestamp()) * 1_000_000 + 998_000
LONG = ExportSpec(layout="long", quality_column="quality", good_quality=("Good", "192"))
COLUMNS = ExportColumns(("A.P", "A.X"), (4, 5))


def _chunk(n=4, t0=T0):
    ts = t0 + np.arange(n, dtype=np.int64) * 1000
    values = np.column_stack([100.0 + np.arange(n) * 0.0038147 + 1e-7, -0.0001221 * np.arange(n)])
    return ts, values


@pytest.mark.parametrize(
    "step, noise, d",
    [(250e5 / 65536 / 1e5, 0.05, 4), (25e5 / 65536 / 1e5, 0.05, 5), (8e-3 / 65536 * 1e3, 1e-3, 5), (1e-3, 1e-3, 4), (381.47, 5e3, 0), (0, 0.01, 3), (0, 0, None)],
)
def test_decimals_keep_a_tenth_of_the_resolution(step, noise, d):
    assert decimals_for_step(step, noise) == d
    if d is not None:
        assert 10.0**-d <= (step or noise) / 10 * (1 + 1e-12)


def test_long_csv_two_chunks_one_header(tmp_path):
    path = tmp_path / "x.csv"
    with open_day_writer(path, LONG, COLUMNS, "UTC", "csv") as w:
        for k in range(2):
            ts, v = _chunk(t0=T0 + k * 4000)
            assert w.write(ts, v) == 8
    lines = path.read_text().splitlines()
    assert lines[0] == "timestamp,tag,value,quality"
    assert lines[1] == "2025-03-30T00:59:59.998000Z,A.P,100.0,Good"
    assert lines[4] == "2025-03-30T00:59:59.999000Z,A.X,-0.00012,Good"
    assert len(lines) == 1 + 16
    df = pl.read_csv(path)
    assert df["value"].to_list()[:4] == [100.0, 0.0, 100.0038, -0.00012]


def test_gzip_chunks_are_one_readable_stream(tmp_path):
    path = tmp_path / "x.csv.gz"
    with open_day_writer(path, LONG, COLUMNS, "UTC", "csv", gzip=True) as w:
        for k in range(3):
            w.write(*_chunk(t0=T0 + k * 4000))
    with gzip.open(path, "rt") as fh:
        text = fh.read()
    assert text.count("timestamp") == 1 and text.count("\n") == 1 + 24
    assert pl.read_csv(path).height == 24


def test_wide_csv_semicolon_decimal_comma_local_pattern(tmp_path):
    spec = ExportSpec(layout="wide", timestamp_column="Zeit", timestamp_format="%d.%m.%Y %H:%M:%S%.3f", separator=";", decimal=",")
    path = tmp_path / "w.csv"
    with open_day_writer(path, spec, COLUMNS, "Europe/Vienna", "csv") as w:
        w.write(*_chunk())
    lines = path.read_text().splitlines()
    assert lines[0] == "Zeit;A.P;A.X"
    # 00:59:59.998 UTC is 01:59:59.998 CET; two ms later the clocks have jumped to CEST
    assert lines[1] == "30.03.2025 01:59:59.998;100,0;0,0"
    assert lines[3] == "30.03.2025 03:00:00.000;100,0076;-0,00024"


def test_epoch_ms_and_wide_parquet(tmp_path):
    spec = ExportSpec(layout="wide", timestamp_format="epoch_ms")
    with open_day_writer(tmp_path / "w.csv", spec, COLUMNS, "UTC", "csv") as w:
        w.write(*_chunk())
    df = pl.read_csv(tmp_path / "w.csv")
    assert df["timestamp"].to_list() == [T0 // 1000 + k for k in range(4)]
    with open_day_writer(tmp_path / "w.parquet", dataclasses.replace(spec, timestamp_format="iso8601"), COLUMNS, "UTC", "parquet") as w:
        w.write(*_chunk())
        w.write(*_chunk(t0=T0 + 4000))
    p = pl.read_parquet(tmp_path / "w.parquet")
    assert p.columns == ["timestamp", "A.P", "A.X"] and p.height == 8
    assert p.schema["timestamp"] == pl.Datetime("us", "UTC")
    assert p["A.X"].to_list()[:4] == df["A.X"].to_list()


def test_long_parquet_tags_are_strings(tmp_path):
    with open_day_writer(tmp_path / "l.parquet", LONG, COLUMNS, "UTC", "parquet") as w:
        w.write(*_chunk())
    p = pl.read_parquet(tmp_path / "l.parquet")
    assert p.schema == pl.Schema({"timestamp": pl.Datetime("us", "UTC"), "tag": pl.String, "value": pl.Float64, "quality": pl.String})
    assert p["tag"].to_list() == ["A.P", "A.X"] * 4


def test_chunk_shape_is_checked(tmp_path):
    with open_day_writer(tmp_path / "x.csv", LONG, COLUMNS, "UTC", "csv") as w:
        with pytest.raises(ValueError, match="columns"):
            w.write(np.arange(3, dtype=np.int64), np.zeros((3, 3)))


@pytest.mark.parametrize("fmt, dtype, first", [("epoch_ms", pl.Int64, T0 // 1000), ("%d.%m.%Y %H:%M:%S%.3f", pl.String, "30.03.2025 01:59:59.998")])
def test_parquet_time_formats(tmp_path, fmt, dtype, first):
    spec = dataclasses.replace(LONG, timestamp_format=fmt)
    with open_day_writer(tmp_path / "l.parquet", spec, COLUMNS, "Europe/Vienna", "parquet") as w:
        w.write(*_chunk())
    p = pl.read_parquet(tmp_path / "l.parquet")
    assert p.schema["timestamp"] == dtype and p.height == 8
    assert p["timestamp"].to_list()[:3] == [first, first, p["timestamp"][2]]
    if dtype == pl.String:
        assert p["timestamp"][4] == "30.03.2025 03:00:00.000"
    assert p["quality"].unique().to_list() == ["Good"]

"""The lake's file format as written (read back from the Parquet footers), and lake files of older
formats still read beside new ones: by polars, DuckDB and retention's thinning."""

from __future__ import annotations

import hashlib
from datetime import date

import duckdb
import numpy as np
import polars as pl
import pyarrow.parquet as pq

import flows.retention.flow as fr
from flows.common.lake import (
    COLUMN_ENCODING,
    COMPRESSION,
    SENSOR_ARROW_SCHEMA,
    STATISTICS_COLUMNS,
    day_files,
    hour_path,
    partition_path,
    read_lake,
    row_group_bounds,
    write_partition,
)
from tests.ingest.conftest import FLOATS, T0_US
from transforms.retention import HOUR_US, thin_mask


def _continuous(hour: int, n: int) -> pl.DataFrame:
    """``n`` rows of valve V1 at 1 kHz from the start of UTC hour ``hour`` of 2025-01-01, float32
    signals like a recording's (a quantised sine), ``x_ref_m`` with nulls."""
    t = T0_US + hour * HOUR_US + np.arange(n, dtype=np.int64) * 1000
    wave = np.round(np.sin(np.arange(n) * 2e-3) * 3000) / 3000
    time = pl.Series(t).cast(pl.Datetime("us", "UTC"))
    frame = pl.DataFrame({"valve_id": "V1", "date": time.dt.date(), "timestamp_utc": time,
                          **{c: ((i + 1) * 1e5 * (1 + wave)).astype(np.float32) for i, c in enumerate(FLOATS[:-1])},
                          "x_ref_m": pl.Series(np.where(np.arange(n) % 7 == 0, np.nan, wave * 1e-3), dtype=pl.Float32).fill_nan(None)})  # fmt: skip
    return frame.select(SENSOR_ARROW_SCHEMA.names)


def test_lake_file_encodings_codec_and_statistics_from_the_footer_and_rerun_bytes(tmp_path):
    frame = _continuous(0, 20_000)
    frame = pl.concat([frame, _continuous(1, 70_000)])  # a window start after 20 k rows, then 70 k gapless rows
    path = partition_path(tmp_path, "V1", date(2025, 1, 1))
    write_partition(path, frame, gap_us=5_000)
    first = hashlib.sha256(path.read_bytes()).hexdigest()
    md = pq.ParquetFile(path).metadata
    sizes = [md.row_group(g).num_rows for g in range(md.num_row_groups)]
    t = frame["timestamp_utc"].to_physical().to_numpy()
    assert sizes == [b - a for a, b in row_group_bounds(t, 5_000)] == [90_000]  # < 64 k rows at the window start: one group
    rg = md.row_group(0)
    float_encoding = COLUMN_ENCODING.get(FLOATS[0], "PLAIN")
    for i in range(rg.num_columns):
        col = rg.column(i)
        name = col.path_in_schema
        assert col.compression == {"none": "UNCOMPRESSED"}.get(COMPRESSION, COMPRESSION.upper()), name
        assert (col.statistics is not None and col.statistics.has_min_max) == (name in STATISTICS_COLUMNS), name
        if name in FLOATS:
            assert float_encoding in col.encodings and "RLE_DICTIONARY" not in col.encodings, (name, col.encodings)
        elif name == "timestamp_utc":
            assert "DELTA_BINARY_PACKED" in col.encodings, col.encodings
        else:
            assert "RLE_DICTIONARY" in col.encodings, (name, col.encodings)
    write_partition(path, frame)  # a rerun writes the same bytes
    assert hashlib.sha256(path.read_bytes()).hexdigest() == first


def test_older_lake_files_are_read_beside_new_ones(tmp_path):
    """A day folder after an upgrade: hour 0 written by an older valvemon (zstd, PLAIN time,
    dictionary-encoded floats, small row groups), hour 1 with byte-stream-split floats (measured
    for the lake and not taken: ``docs/ingest.md``, "The lake's format"), hour 2 by this one.
    polars (``read_lake``), DuckDB and retention's thinning read them all alike."""
    wh = tmp_path / "wh"
    folder = partition_path(wh, "V1", date(2025, 1, 1)).parent
    folder.mkdir(parents=True)
    frames = [_continuous(h, 30_000) for h in range(3)]
    pq.write_table(frames[0].to_arrow().cast(SENSOR_ARROW_SCHEMA), hour_path(folder, 0), compression="zstd", row_group_size=7_000)
    pq.write_table(frames[1].to_arrow().cast(SENSOR_ARROW_SCHEMA), hour_path(folder, 1), compression="lz4", row_group_size=16_384,
                   use_dictionary=["valve_id", "date"], column_encoding={c: "BYTE_STREAM_SPLIT" for c in FLOATS})  # fmt: skip
    write_partition(hour_path(folder, 2), frames[2])
    encodings = [pq.ParquetFile(p).metadata.row_group(0).column(5).encodings for p in day_files(folder)]
    assert "RLE_DICTIONARY" in encodings[0] and "BYTE_STREAM_SPLIT" in encodings[1]
    whole = pl.concat(frames)

    assert read_lake(wh).collect().equals(whole)
    sums = ", ".join(f"sum({c}::DOUBLE), count({c})" for c in FLOATS)
    got = duckdb.connect().execute(f"SELECT count(*), {sums} FROM read_parquet('{wh}/lake/sensors/*/*/*.parquet')").fetchone()
    want = whole.select(pl.len(), *[e for c in FLOATS for e in (pl.col(c).cast(pl.Float64).sum(), pl.col(c).count().alias(f"n_{c}"))]).row(0)
    assert got[0] == want[0] and np.allclose(got[1:], want[1:], rtol=1e-12)

    t = whole["timestamp_utc"].to_physical().to_numpy()
    scan = fr.scan_partition(folder, (t[:1], t[-1:]), True)
    assert fr.thin_partition(fr.count_kept(folder, scan, 10.0), "lz4") == 3 * 10_000
    assert {pq.ParquetFile(p).metadata.row_group(0).column(3).compression for p in folder.glob("*.parquet")} == {"LZ4"}  # [lake] codec
    assert read_lake(wh).collect().equals(whole.filter(pl.Series(thin_mask(t, scan.firsts, 10.0))))

"""A lake file rewritten by another program that carried the footer's key-value metadata over
(pyarrow keeps it) but not the rows: its time grid record no longer tells the file's times
(issue 46, item 5). Reversed rows, or one 10 s window moved by an hour, keep the row count, the
minimum and the maximum, so the footer alone agrees; the record must be bound to the time column
itself, and a file that disagrees is decoded as one without a record: the monitor's reader then
reads exactly what decoding reads."""

from __future__ import annotations

from datetime import date

import numpy as np
import polars as pl
import pyarrow.parquet as pq
import pytest

import flows.monitor.flow as fm
from flows.common.lake import partition_path, time_grid, write_partition
from tests.ingest.conftest import T0_US
from tests.ingest.test_time_grid import _frame

WINDOW = 10_000  # rows of a 10 s window at 1 kHz
WINDOWS = 4  # at 00:00, 06:00, 12:00, 18:00


def _day() -> np.ndarray:
    return np.concatenate([T0_US + k * 6 * 3_600_000_000 + np.arange(WINDOW, dtype=np.int64) * 1_000 for k in range(WINDOWS)])


def _rewrite(path, frame: pl.DataFrame) -> None:
    """``frame`` written over ``path`` by plain pyarrow, the old footer's key-value metadata kept."""
    md = pq.ParquetFile(path).metadata
    kept = {k: v for k, v in md.metadata.items() if k.startswith(b"valvemon.")}
    table = frame.to_arrow().cast(pq.read_schema(path))
    pq.write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), **kept}), path, row_group_size=md.row_group(0).num_rows,
                   write_statistics=["timestamp_utc"])  # fmt: skip
    assert kept and kept.items() <= pq.ParquetFile(path).metadata.metadata.items()


@pytest.mark.parametrize("change", ["reversed", "a-window-moved-by-an-hour", "same-rows"])
def test_a_stale_record_is_not_trusted(tmp_path, change):
    t = _day()
    frame = _frame(t)
    path = partition_path(tmp_path, "V1", date(2025, 1, 1))
    write_partition(path, frame)
    assert time_grid(pq.ParquetFile(path).metadata, path) is not None  # the writer's own record is trusted
    if change == "reversed":
        new = frame.reverse()
    elif change == "a-window-moved-by-an-hour":
        moved = t.copy()
        moved[2 * WINDOW : 3 * WINDOW] += 3_600_000_000  # the 12:00 window at 13:00: min, max and rows unchanged
        new = _frame(moved)
    else:
        new = frame
    _rewrite(path, new)
    md = pq.ParquetFile(path).metadata
    assert (md.num_rows, *fm.row_group_spans(md)[0][1:]) == (frame.height, int(t.min()), int(t.max()))
    if change != "same-rows":  # the same rows by another writer may be trusted or decoded: either reads the same
        assert time_grid(md, path) is None
    want = pl.read_parquet(path).select("timestamp_utc", "valve_id", "p1_pa", "x_cyl_m")
    got = pl.concat(fm.lake_chunks(tmp_path, "V1", 0.005, None, None, days=1, columns=("valve_id", "p1_pa", "x_cyl_m"), window_s=10.0))
    assert got.equals(want)

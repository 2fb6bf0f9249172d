"""What binding the lake's time grid record to the time column costs (``valvemon.time_digest``).

Writes one continuous hour file (3.6 M rows at 1 kHz) with the lake's writer and prints the
median time of: the reader's check (:func:`flows.common.lake.time_grid`: footer, runs and the
digests of the time column chunks), the footer read alone, the writer's extra step (the digests
of the closed file), and decoding the time column, which a file whose record is not trusted costs.

    taskset -c 1 .venv/bin/python bench/time_grid_check.py
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from flows.common import lake  # noqa: E402
from schemas.fields import SENSOR_FIELDS  # noqa: E402

T0_US = 1_735_689_600 * 10**6  # 2025-01-01T00:00Z
ROWS = 3_600_000


def _hour_file(folder: Path) -> Path:
    t = pl.Series(T0_US + np.arange(ROWS, dtype=np.int64) * 1_000).cast(pl.Datetime("us", "UTC"))
    i = np.arange(ROWS)
    floats = [f.name for f in SENSOR_FIELDS if f.name.endswith(("_pa", "_m"))]
    frame = pl.DataFrame({"valve_id": "V1", "date": t.dt.date(), "timestamp_utc": t, **{c: np.sin(i * (k + 1) * 1e-3) for k, c in enumerate(floats)}})
    path = lake.hour_path(lake.partition_path(folder, "V1", date(2025, 1, 1)).parent, 0)
    lake.write_partition(path, frame.select(lake.SENSOR_ARROW_SCHEMA.names))
    return path


def _median_ms(f, n: int) -> float:
    times = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = _hour_file(Path(tmp))
        md = pq.ParquetFile(path).metadata
        chunk = sum(md.row_group(g).column(md.schema.names.index("timestamp_utc")).total_compressed_size for g in range(md.num_row_groups))
        assert lake.time_grid(md, path) is not None
        print(f"hour file: {md.num_rows:,} rows, {md.num_row_groups} row groups, {chunk:,} B of time column")
        print(f"reader's check (footer + digests): {_median_ms(lambda: lake.time_grid(pq.ParquetFile(path).metadata, path), 50):.3f} ms")
        print(f"footer read alone:                 {_median_ms(lambda: pq.ParquetFile(path).metadata, 50):.3f} ms")
        with open(path, "rb") as fh:
            print(f"writer's extra step (digests):     {_median_ms(lambda: lake._time_digests(fh, md), 20):.3f} ms")  # noqa: SLF001
        print(f"decoding the time column:          {_median_ms(lambda: pl.read_parquet(path, columns=['timestamp_utc']), 10):.1f} ms")


if __name__ == "__main__":
    main()

"""The lake files' time grid record: the writer's runs rebuild the time stamps exactly, the
monitor's reader builds the time column from it and reads what decoding reads, and a file
without the record or with one that disagrees with its footer is decoded as before."""

from __future__ import annotations

import json
from datetime import date, datetime, timedelta, timezone

import numpy as np
import polars as pl
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flows.monitor.flow as fm
from flows.common.lake import (
    SENSOR_ARROW_SCHEMA,
    SENSOR_POLARS_SCHEMA,
    TIME_GRID_KEY,
    TIME_GRID_MAX_RUNS,
    grid_rows_before,
    grid_runs,
    grid_series,
    hour_path,
    partition_path,
    read_lake,
    time_grid,
    write_partition,
)
from tests.ingest.conftest import FLOATS, T0_US


def _frame(t_us: np.ndarray) -> pl.DataFrame:
    """Sensor rows of valve V1 at the time stamps ``t_us``, each signal a different function of the row."""
    time = pl.Series(t_us).cast(pl.Datetime("us", "UTC"))
    i = np.arange(t_us.shape[0])
    return pl.DataFrame({"valve_id": "V1", "date": time.dt.date(), "timestamp_utc": time,
                         **{c: np.sin(i * (k + 1) * 1e-3).astype(np.float32) for k, c in enumerate(FLOATS)}}).select(SENSOR_ARROW_SCHEMA.names)  # fmt: skip


def _times(steps: list[int], t0: int = T0_US) -> np.ndarray:
    return t0 + np.concatenate([[0], np.cumsum(steps)]).astype(np.int64)


@settings(max_examples=60, deadline=None)
@given(
    pieces=st.lists(st.tuples(st.integers(1, 5_000), st.integers(0, 40)), min_size=1, max_size=12),
    probes=st.lists(st.integers(-3_000, 400_000), min_size=1, max_size=8),
    cut=st.tuples(st.integers(0, 500), st.integers(0, 500)),
)
def test_grid_runs_rebuild_the_time_stamps_and_find_their_rows(pieces, probes, cut):
    # stretches of equal steps (a step repeated 0–40 times): runs of any length, single rows too
    t = _times([step for step, n in pieces for _ in range(n + 1)])
    runs = grid_runs(t)
    assert runs is not None and sum(r[2] for r in runs) == t.shape[0] and len(runs) <= len(pieces) + 1
    assert np.array_equal(grid_series(runs, 0, t.shape[0]).to_physical().to_numpy(), t)
    for x in probes:
        assert grid_rows_before(runs, T0_US + x) == np.searchsorted(t, T0_US + x, side="left")
    a = min(cut[0], t.shape[0])
    b = min(t.shape[0], a + cut[1])
    lengths = [(b - a) // 3, (b - a) - (b - a) // 3]
    s = grid_series(runs, a, b, lengths)
    assert np.array_equal(s.to_physical().to_numpy(), t[a:b]) and s.dtype == SENSOR_POLARS_SCHEMA["timestamp_utc"]
    assert [c.len() for c in s.get_chunks() if c.len()] == [m for m in lengths if m]


def test_grid_runs_give_up_on_an_irregular_clock_or_unsorted_times():
    rng = np.random.default_rng(0)
    jitter = T0_US + np.cumsum(rng.integers(990, 1_010, 10_000))
    assert grid_runs(jitter) is None
    steps = [1_000] * 10 + [3_000]
    assert len(grid_runs(_times(steps * (TIME_GRID_MAX_RUNS - 1)))) == TIME_GRID_MAX_RUNS
    assert grid_runs(_times(steps * TIME_GRID_MAX_RUNS)) is None
    assert grid_runs(np.array([5, 7, 7, 9])) is None and grid_runs(np.array([5, 4])) is None
    assert grid_runs(np.zeros(0, dtype=np.int64)) == [] and grid_runs(np.array([5])) == [[5, 1, 1]]


def _lake(tmp_path, record: bool, grid=None) -> tuple:
    """A continuous day in hour files (hours 0–2, 1 ms steps, with a 40 ms gap, a 2 ms step and a
    doubled rate stretch) written by the lake's writer; ``record=False``: the same rows by plain
    pyarrow (no record); ``grid``: the record replaced by this one."""
    rows = []
    for h in range(3):
        steps = [1_000] * 30_000 + [40_000] + [1_000] * 20_000 + [2_000] + [500] * 1_000 + [1_000] * 15_000
        rows.append(_frame(_times(steps, T0_US + h * 3_600_000_000)))
    folder = partition_path(tmp_path, "V1", date(2025, 1, 1)).parent
    for h, frame in enumerate(rows):
        path = hour_path(folder, h)
        if record and grid is None:
            write_partition(path, frame)
            continue
        table = frame.to_arrow().cast(SENSOR_ARROW_SCHEMA)
        if grid is not None:
            table = table.replace_schema_metadata({**(table.schema.metadata or {}), TIME_GRID_KEY: json.dumps(grid(frame))})
        folder.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, row_group_size=30_000, write_statistics=["timestamp_utc"])
    return folder, pl.concat(rows)


def _chunks(wh, start=None, end=None, columns=("valve_id", "p1_pa", "x_cyl_m")) -> pl.DataFrame:
    return pl.concat(fm.lake_chunks(wh, "V1", 0.005, start, end, days=1, columns=columns, window_s=60.0))


@pytest.mark.parametrize("case", ["writer", "no record", "bad first", "bad step", "bad rows", "groups", "not a list"])
def test_the_span_reader_reads_every_file_as_decoding_does(tmp_path, monkeypatch, case):
    def record(frame, change=None):  # the writer's record of 30 k-row groups, one value changed
        t = frame["timestamp_utc"].dt.epoch("us").to_numpy()
        groups = [grid_runs(t[a:a + 30_000]) for a in range(0, t.shape[0], 30_000)]
        if change is not None:
            groups[1][-1][change] += 1
        return groups

    bad = {"bad first": lambda f: record(f, 0), "bad step": lambda f: record(f, 1), "bad rows": lambda f: record(f, 2),
           "groups": lambda f: record(f)[:-1], "not a list": lambda f: {"rows": 3}}.get(case)  # fmt: skip
    folder, whole = _lake(tmp_path, case != "no record", bad)
    files = fm._lake_files(tmp_path, "V1", None, None)
    assert [f.grid is not None for f in files] == [case == "writer"] * 3
    if case == "writer":
        assert files[0].grid == [(T0_US, 1_000, 30_001), (T0_US + 30_040_000, 1_000, 20_001), (T0_US + 50_042_000, 500, 1_001),
                                 (T0_US + 50_543_000, 1_000, 15_000)]  # fmt: skip
    # a whole day in two spans a time (hour files read whole or sliced at the span's ends) and
    # bounds inside files: the rows decoding gives
    monkeypatch.setattr(fm, "CHUNK_ROWS", 50_000)
    monkeypatch.setattr(fm, "CHUNK_SPAN_S", 3_600.0)
    want = whole.select("timestamp_utc", "valve_id", "p1_pa", "x_cyl_m")
    assert _chunks(tmp_path).equals(want)
    # the windows starting in [00:00:20, 02:00:45): from the one after the 40 ms gap of hour 0 to
    # the one of hour 2 before the minute
    got = _chunks(tmp_path, datetime(2025, 1, 1, 0, 0, 20, tzinfo=timezone.utc), datetime(2025, 1, 1, 2, 0, 45, tzinfo=timezone.utc))
    first, last = datetime(2025, 1, 1, 0, 0, 30, 40_000, tzinfo=timezone.utc), datetime(2025, 1, 1, 2, 0, 59, 999_000, tzinfo=timezone.utc)
    assert got.equals(want.filter(want["timestamp_utc"].is_between(first, last)))
    assert _chunks(tmp_path, columns=()).equals(want.select("timestamp_utc"))  # the time alone: nothing decoded from a gridded file
    assert read_lake(tmp_path).collect().equals(whole)


def test_a_gridded_file_is_read_back_identical_to_decoding(tmp_path):
    folder, whole = _lake(tmp_path, True)
    md = pq.ParquetFile(hour_path(folder, 1)).metadata
    runs = time_grid(md, hour_path(folder, 1))
    decoded = pl.read_parquet(hour_path(folder, 1))["timestamp_utc"]
    assert grid_series(runs, 0, md.num_rows).equals(decoded)
    assert json.loads(md.metadata[TIME_GRID_KEY.encode()])[0][0] == [T0_US + 3_600_000_000, 1_000, 30_001]
    # a row group of an irregular clock: no record, the file decoded as before
    jitter = T0_US + np.cumsum(np.random.default_rng(1).integers(990, 1_010, 5_000))
    path = partition_path(tmp_path / "j", "V1", date(2025, 1, 1))
    write_partition(path, _frame(jitter))
    assert TIME_GRID_KEY.encode() not in (pq.ParquetFile(path).metadata.metadata or {})
    assert _chunks(tmp_path / "j").equals(_frame(jitter).select("timestamp_utc", "valve_id", "p1_pa", "x_cyl_m"))
    assert whole.height == 3 * 66_003 and timedelta(0) < whole["timestamp_utc"].diff().min()

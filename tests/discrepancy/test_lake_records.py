"""flows.discrepancy.lake_records: the records chosen from the time stamps and read piece by piece
are those of reading the whole span and cutting it (split_records), on snapshots and on a
continuous recording; on a continuous recording no record straddles a clock window; and what is
read at once does not grow with the span."""

from dataclasses import replace
from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl
import pytest

import flows.discrepancy.lake_records as lr
import flows.monitor.flow as fm
from flows.common.lake import partition_path, read_lake, write_partition
from transforms.discrepancy import DiscrepancySettings, split_records

VALVE = "V1"
DT = 0.01  # 100 Hz keeps the lakes small; the rules are in samples and seconds alike
EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
SETTINGS = DiscrepancySettings(sample_period_s=DT, min_record_s=2.0, max_record_s=25.0, window_s=60.0)


def _frame(t_us: np.ndarray, seed: int = 0) -> pl.DataFrame:
    rng = np.random.default_rng(seed)
    n = t_us.size
    ts = pl.Series("timestamp_utc", t_us).cast(pl.Datetime("us", "UTC"))
    sig = {c: rng.normal(1e6, 1e4, n) for c in ("ps_pa", "pr_pa", "p1_pa", "p2_pa")}
    sig |= {c: rng.normal(0.0, 1e-4, n) for c in ("x_spool_m", "x_cyl_m", "x_ref_m")}
    return pl.DataFrame({"valve_id": [VALVE] * n, "date": ts.dt.date(), "timestamp_utc": ts, **sig})


def _write(warehouse, frame: pl.DataFrame) -> None:
    for (day,), part in frame.partition_by("date", as_dict=True).items():
        write_partition(partition_path(warehouse, VALVE, day), part.sort("timestamp_utc"))


def _us(t: datetime) -> int:
    return (t - EPOCH) // timedelta(microseconds=1)


def _continuous(warehouse, start: datetime, minutes: float) -> None:
    """Back-to-back samples from an instant off the clock, over midnight, with a 2 s gap, a 1 s
    island after it and one NaN sample."""
    n = int(minutes * 60 / DT)
    t = _us(start) + np.arange(n, dtype=np.int64) * int(DT * 1e6)
    t[n // 3:] += 2_000_000  # a gap
    island = _us(start) + int(minutes * 60e6) + 10_000_000 + np.arange(int(1 / DT), dtype=np.int64) * int(DT * 1e6)
    frame = _frame(np.r_[t, island])
    p1 = frame["p1_pa"].to_numpy().copy()
    p1[n // 2] = np.nan
    _write(warehouse, frame.with_columns(pl.Series("p1_pa", p1)))


def _snapshots(warehouse, start: datetime, hours: int) -> None:
    """10 s every hour, at an offset in the hour."""
    per = int(10 / DT)
    t = np.concatenate([_us(start) + h * 3_600_000_000 + 17_000_000 + np.arange(per, dtype=np.int64) * int(DT * 1e6) for h in range(hours)])
    _write(warehouse, _frame(t, seed=1))


def _key(recs):
    return [(r.start_us, r.end_us, r.n) for r in recs]


def _same(a, b):
    assert _key(a) == _key(b)
    for x, y in zip(a, b):
        for k in x.raw:
            np.testing.assert_array_equal(x.raw[k], y.raw[k])


@pytest.mark.parametrize("shape", ["snapshots", "continuous"])
@pytest.mark.parametrize("max_records", [4, 1000])
@pytest.mark.parametrize("span", [(None, None), (datetime(2025, 3, 1, 23, 58, 10, 5000, tzinfo=timezone.utc), datetime(2025, 3, 2, 0, 5, 1, tzinfo=timezone.utc))])
def test_records_from_time_stamps_are_those_of_the_whole_span(tmp_path, monkeypatch, shape, max_records, span):
    monkeypatch.setattr(fm, "CHUNK_ROWS", 20_000)  # several chunks, carried windows included
    monkeypatch.setattr(fm, "CHUNK_SPAN_S", 120.0)
    if shape == "continuous":
        _continuous(tmp_path, datetime(2025, 3, 1, 23, 56, 17, 300_000, tzinfo=timezone.utc), 12)
    else:
        _snapshots(tmp_path, datetime(2025, 3, 1, 12, tzinfo=timezone.utc), 30)
    s = replace(SETTINGS, max_records=max_records)
    start, end = span
    got, n_rows = lr.lake_records(tmp_path, VALVE, start, end, s)
    whole = read_lake(tmp_path, [VALVE], start, end).collect()
    assert n_rows == whole.height > 0
    want = split_records(whole, s)
    assert len(want) > 0
    _same(got, want)


def test_snapshot_records_are_the_whole_run_records_of_before(tmp_path):
    """Snapshots (10 s < window_s / 2) are whole runs with a window length or without (the old rule)."""
    _snapshots(tmp_path, datetime(2025, 3, 1, 12, tzinfo=timezone.utc), 30)
    whole = read_lake(tmp_path, [VALVE]).collect()
    s = replace(SETTINGS, min_record_s=1.0, max_record_s=4.0, max_records=40)
    old = split_records(whole, replace(s, window_s=None))
    assert len(old) == 40 and {r.n for r in old} == {400, 200}
    _same(split_records(whole, s), old)


def test_continuous_records_keep_inside_clock_windows(tmp_path):
    _continuous(tmp_path, datetime(2025, 3, 1, 23, 56, 17, 300_000, tzinfo=timezone.utc), 12)
    whole = read_lake(tmp_path, [VALVE]).collect()
    s = replace(SETTINGS, max_records=1000)
    recs = split_records(whole, s)
    L = int(s.window_s * 1e6)
    assert all(r.start_us // L == r.end_us // L for r in recs)
    # a full window gives 25 + 25 + 10 s; the first record starts at the recording's first sample
    starts = [r.start_us for r in recs]
    assert starts[0] == whole["timestamp_utc"].to_physical()[0]
    on_clock = [r.n for r in recs if r.start_us % L == 0]
    assert on_clock.count(2500) >= 5 and 1730 in on_clock  # the window 00:00:00 ends at the gap, 17.3 s in
    # without the length the records run over the clock (the old rule), so the rule is what cuts them
    old = split_records(whole, replace(s, window_s=None))
    assert any(r.start_us // L != r.end_us // L for r in old)


class _Counting:
    """A LazyFrame stand-in that logs the cells (rows × columns) every collect returns."""

    def __init__(self, lf, log):
        self.lf, self.log = lf, log

    def select(self, *a, **k):
        return _Counting(self.lf.select(*a, **k), self.log)

    def collect(self, *a, **k):
        df = self.lf.collect(*a, **k)
        self.log.append(df.height * df.width)
        return df


def _cells_read(tmp_path, monkeypatch, minutes):
    wh = tmp_path / f"m{minutes}"
    _continuous(wh, datetime(2025, 3, 1, 22, 0, tzinfo=timezone.utc), minutes)
    log: list[int] = []
    monkeypatch.setattr(fm, "CHUNK_ROWS", 20_000)
    monkeypatch.setattr(fm, "CHUNK_SPAN_S", 120.0)
    for mod in (fm, lr):
        monkeypatch.setattr(mod, "read_lake", lambda *a, **k: _Counting(read_lake(*a, **k), log))
    chunks = fm.span_chunks

    def counted_chunks(*a, **k):  # the time stamps held at once, carried windows included
        for c in chunks(*a, **k):
            log.append(c.height * c.width)
            yield c

    monkeypatch.setattr(fm, "span_chunks", counted_chunks)
    recs, n_rows = lr.lake_records(wh, VALVE, None, None, replace(SETTINGS, max_records=6))
    assert len(recs) == 6
    return max(log), n_rows


def test_what_is_read_at_once_does_not_grow_with_the_span(tmp_path, monkeypatch):
    short, rows_short = _cells_read(tmp_path, monkeypatch, 15)
    long, rows_long = _cells_read(tmp_path, monkeypatch, 60)
    assert rows_long > 3.9 * rows_short
    width = len(read_lake(tmp_path / "m15").collect_schema())
    assert long == short == 2500 * width  # the largest read: one 25 s record (a time-stamp chunk is smaller)

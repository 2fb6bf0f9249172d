"""Continuous recordings: bounded memory, hour files, a late file, kill -9 and rerun.

The recordings are wide Parquet exports of valve V017 on a 10 Hz grid (so that a few hundred
thousand rows span many hours), written by ``bench/continuous.py``'s generator; the lake's sizes
(day file limit, batch size, buffer) are lowered so that these small files behave as a valve-day
of 1 kHz data does with the real ones.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

import flows.ingest.formats
import flows.ingest.staging
from flows.common.config import load_plant_config
from tests.ingest.conftest import ingest, lake, table, write_plant
from transforms.ingest import process_export

ROOT = Path(__file__).parents[2]
START_US = 1_740_787_200_000_000  # 2025-03-01T00:00:00Z
SMALL = {"BATCH_SAMPLES": 6_000, "DAY_FILE_MAX_ROWS": 20_000, "BUFFER_ROWS": 60_000}


def recording(path: Path, first_s: float, seconds: float, seed: int = 0, rate_hz: float = 10.0) -> Path:
    """A wide Parquet recording of V017 from ``first_s`` (seconds after 2025-03-01 00:00 UTC)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    t = START_US + int(first_s * 1e6) + np.arange(n, dtype=np.int64) * int(1e6 / rate_hz)
    data = {"timestamp": pl.Series(t).cast(pl.Datetime("us", "UTC"))}
    for tag, lo, hi in (("PS", 200, 220), ("PR", 1, 3), ("P1", 50, 150), ("P2", 50, 150), ("XS", -1, 1), ("XC", 100, 500)):
        data[f"MILL1.V017.{tag}"] = np.round(rng.uniform(lo, hi, n), 3)
    pl.DataFrame(data).write_parquet(path, row_group_size=5_000)
    return path


def tdms_recording(path: Path, first_s: float, seconds: float, seed: int = 0, rate_hz: float = 10.0) -> Path:
    """The same recording as :func:`recording`, as a TDMS file: a channel per tag, waveform time,
    one segment per 5,000 samples (as a recorder writes blocks)."""
    from nptdms import ChannelObject, TdmsWriter

    df = pl.read_parquet(recording(path.with_suffix(".parquet"), first_s, seconds, seed, rate_hz))
    path.with_suffix(".parquet").unlink()
    start = np.datetime64(START_US + int(first_s * 1e6), "us")
    with TdmsWriter(str(path)) as w:
        for a in range(0, df.height, 5_000):
            props = lambda tag: {"wf_start_time": start, "wf_increment": 1 / rate_hz, "unit_string": "mm" if tag[-2:] in ("XS", "XC") else "bar"}  # noqa: E731
            w.write_segment([ChannelObject("rec", tag, df[tag].to_numpy()[a : a + 5_000], properties=props(tag) if a == 0 else None) for tag in df.columns[1:]])
    return path


def comtrade_recording(path: Path, first_s: float, seconds: float, seed: int = 0, rate_hz: float = 10.0) -> Path:
    """The same recording as :func:`recording`, as a 1999 COMTRADE ``.cfg`` + BINARY32 ``.dat``
    (values × 1000 as raw integers, a = 0.001), the start in UTC (a plant in UTC would write it so;
    here the plant is in Vienna: the start is written an hour later), with a digital channel."""
    from datetime import datetime, timedelta, timezone

    from tests.ingest.comtrade_files import Analog, Recording, write_comtrade

    df = pl.read_parquet(recording(path.with_suffix(".parquet"), first_s, seconds, seed, rate_hz))
    path.with_suffix(".parquet").unlink()
    analogs = [Analog(tag, "mm" if tag[-2:] in ("XS", "XC") else "bar", np.rint(df[tag].to_numpy() * 1000).astype(np.int32), 0.001) for tag in df.columns[1:]]
    local = datetime.fromtimestamp(START_US / 1e6 + first_s, timezone.utc) + timedelta(hours=1)
    rec = Recording(analogs, [("PUMP ON", np.ones(df.height, dtype=np.int64))], rate_hz=rate_hz, start=local.strftime("%d/%m/%Y,%H:%M:%S.%f"))
    return write_comtrade(path, rec, "BINARY32")


@pytest.fixture
def wide10(tmp_path):
    return write_plant(tmp_path, "wide10.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None, sample_rate_hz=10.0, max_gap_s=0.25)


@pytest.fixture
def small(monkeypatch):
    monkeypatch.setattr(flows.ingest.formats, "BATCH_SAMPLES", SMALL["BATCH_SAMPLES"])
    monkeypatch.setattr(flows.ingest.staging, "DAY_FILE_MAX_ROWS", SMALL["DAY_FILE_MAX_ROWS"])
    monkeypatch.setattr(flows.ingest.staging, "BUFFER_ROWS", SMALL["BUFFER_ROWS"])


def _files(wh: Path) -> dict[str, bytes]:
    return {str(p.relative_to(wh)): p.read_bytes() for p in sorted((wh / "lake").rglob("*")) if p.is_file()}


def test_a_long_recording_goes_to_hour_files_equal_to_the_whole_file(wide10, tmp_path, small):
    rec = recording(tmp_path / "rec.parquet", 22 * 3600, 5 * 3600)  # 22:00 to 03:00 next day: 180,000 rows
    wh = tmp_path / "wh"
    report = ingest(wide10, rec, wh)
    folders = sorted(p.name for p in (wh / "lake" / "sensors" / "valve_id=V017").iterdir())
    assert folders == ["date=2025-03-01", "date=2025-03-02"]
    names = [sorted(p.name for p in (wh / "lake" / "sensors" / "valve_id=V017" / f).iterdir()) for f in folders]
    assert names == [["part-h22.parquet", "part-h23.parquet"], ["part-h00.parquet", "part-h01.parquet", "part-h02.parquet"]]
    whole = process_export(pl.read_parquet(rec), load_plant_config(wide10), first_line=1)
    assert_frame_equal(lake(wh), pl.concat([p.frame for p in whole.partitions]))
    assert report.rows_written == report.rows_added == 180_000 and report.partitions_written == 2
    for f in (wh / "lake").rglob("*.parquet"):  # each file holds its own hour only
        t = pl.read_parquet(f)["timestamp_utc"]
        assert t.dt.hour().n_unique() == 1 and f.name == f"part-h{t.dt.hour()[0]:02d}.parquet"


def test_a_late_file_rewrites_only_the_hours_it_touches(wide10, tmp_path, small):
    wh = tmp_path / "wh"
    ingest(wide10, recording(tmp_path / "day.parquet", 0, 4 * 3600), wh)
    before = {p.name: p.stat().st_ino for p in (wh / "lake").rglob("*.parquet")}
    late = recording(tmp_path / "late.parquet", 3600 + 600, 1200, seed=7)  # 01:10–01:30, other values
    report = ingest(wide10, late, wh, force=False)
    after = {p.name: p.stat().st_ino for p in (wh / "lake").rglob("*.parquet")}
    assert sorted(after) == ["part-h00.parquet", "part-h01.parquet", "part-h02.parquet", "part-h03.parquet"]
    assert [n for n in after if after[n] != before[n]] == ["part-h01.parquet"]
    assert report.lake_conflicts == 12_000 and report.rows_added == 0  # "last": the late file wins
    got = lake(wh).filter(pl.col("timestamp_utc").dt.hour() == 1)
    assert got.height == 36_000 and got["p1_pa"].slice(6000, 12_000).equals((pl.read_parquet(late)["MILL1.V017.P1"] * 1e5).cast(pl.Float32).alias("p1_pa"))


def test_a_day_file_that_outgrows_its_limit_switches_to_hour_files(wide10, tmp_path, small):
    wh = tmp_path / "wh"
    ingest(wide10, recording(tmp_path / "a.parquet", 0, 1800), wh)  # 18,000 rows: the day file
    assert [p.name for p in (wh / "lake").rglob("*.parquet")] == ["part-0.parquet"]
    ingest(wide10, recording(tmp_path / "b.parquet", 1800, 3 * 3600), wh)
    assert sorted(p.name for p in (wh / "lake").rglob("*.parquet")) == ["part-h00.parquet", "part-h01.parquet", "part-h02.parquet", "part-h03.parquet"]
    assert lake(wh).height == 18_000 + 108_000
    assert lake(wh)["timestamp_utc"].is_sorted() and lake(wh)["timestamp_utc"].n_unique() == 126_000
    # the day file lay in one hour (00:00-00:30): it became part-h00 as it was (a hard link), then
    # took the second file's rows of that hour; the lake is the one of both files in one run
    both = tmp_path / "wh_both"
    ingest(wide10, [tmp_path / "a.parquet", tmp_path / "b.parquet"], both)
    assert_frame_equal(lake(wh), lake(both))
    assert not list((wh / "lake").rglob(".*.tmp"))


def test_a_day_file_within_one_hour_becomes_that_hour_file_unread(wide10, tmp_path, small):
    """The first hour of a recording, alone in its day file, is staged as its hour file by a hard
    link when the next hour arrives: the same bytes, not read or written again."""
    wh = tmp_path / "wh"
    ingest(wide10, recording(tmp_path / "a.parquet", 3600, 1200), wh)  # 01:00-01:20
    day_file = next((wh / "lake").rglob("part-0.parquet"))
    before = day_file.read_bytes()
    ingest(wide10, recording(tmp_path / "b.parquet", 2 * 3600, 2400), wh)  # 02:00-02:40: 24,000 rows, over the limit
    assert sorted(p.name for p in day_file.parent.iterdir()) == ["part-h01.parquet", "part-h02.parquet"]
    assert (day_file.parent / "part-h01.parquet").read_bytes() == before


CHILD = textwrap.dedent(
    """
    import json, os, signal, sys
    sys.path.insert(0, {root!r})
    import flows.common.lake, flows.ingest.formats, flows.ingest.staging
    from flows.ingest.flow import run_ingest
    small, kill_at, warm = json.loads(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    for k, v in small.items():
        setattr(flows.ingest.formats if k == "BATCH_SAMPLES" else flows.ingest.staging, k, v)
    def hwm():  # VmHWM: ru_maxrss would carry pytest's own peak over fork + exec
        return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
    run_ingest(sys.argv[4], [warm], sys.argv[6])  # imports, compiled kernels, first allocations
    base = hwm()
    real, calls = flows.common.lake._commit, []
    def commit(tmp, path):
        calls.append(path)
        if len(calls) == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(tmp, path)
    flows.common.lake._commit = commit
    run_ingest(sys.argv[4], [sys.argv[5]], sys.argv[6])
    print(json.dumps({{"growth_mb": (hwm() - base) / 1024}}))
    """
)


def _child(config: Path, path: Path, wh: Path, warm: Path, small: dict, kill_at: int = 0) -> subprocess.CompletedProcess:
    script = CHILD.format(root=str(ROOT))
    env = dict(os.environ, POLARS_MAX_THREADS="1", PREFECT_SERVER_ANALYTICS_ENABLED="false")
    return subprocess.run([sys.executable, "-c", script, json.dumps(small), str(kill_at), str(warm), str(config), str(path), str(wh)], capture_output=True, text=True, env=env)


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".parquet", ".tdms", ".cfg"])
def test_memory_does_not_grow_with_the_file(wide10, tmp_path, suffix):
    """A file of 360,000 rows (2.16 M samples, 360 batches, 10 h at 10 Hz; COMTRADE 400,000 rows
    in batches of 60,000 samples) ingests in a few tens of MB above the interpreter; taken whole,
    the same file needs more, by more than its samples as float64 (360,000 rows: 13–20 MB
    streamed, 54–74 MB whole).
    Wide Parquet read by record batches; TDMS by slices of every channel (that its lake is the one
    of the same data as CSV: ``tests/archive/test_recorder_formats.py``); COMTRADE binary records
    a batch at a time (``tests/ingest/test_comtrade.py``)."""
    make = {".parquet": recording, ".tdms": tdms_recording, ".cfg": comtrade_recording}[suffix]
    warm = make(tmp_path / f"warm{suffix}", 0, 600)
    rows, small = (360_000, SMALL) if suffix != ".cfg" else (400_000, {**SMALL, "BATCH_SAMPLES": 60_000})
    # COMTRADE: 400,000 rows, the whole file 110–132 MB against 16–22 MB streamed
    big = make(tmp_path / f"big{suffix}", 86_400, rows / 10)
    streamed = _child(wide10, big, tmp_path / "wh_stream", warm, small)
    assert streamed.returncode == 0, streamed.stderr
    whole = _child(wide10, big, tmp_path / "wh_whole", warm, {**SMALL, "BATCH_SAMPLES": 10**9, "DAY_FILE_MAX_ROWS": 10**9, "BUFFER_ROWS": 10**9})
    assert whole.returncode == 0, whole.stderr
    grow_stream = json.loads(streamed.stdout.splitlines()[-1])["growth_mb"]
    grow_whole = json.loads(whole.stdout.splitlines()[-1])["growth_mb"]
    print(f"{suffix}: peak growth streamed {grow_stream:.1f} MB, whole {grow_whole:.1f} MB")
    assert grow_stream < 60, (grow_stream, grow_whole)
    samples_mb = rows * 6 * 8 / 2**20  # the file's samples as float64, which a whole read holds at once
    assert grow_whole - grow_stream > samples_mb, (grow_stream, grow_whole, samples_mb)
    assert_frame_equal(lake(tmp_path / "wh_stream"), lake(tmp_path / "wh_whole"))


@pytest.fixture(scope="module")
def clean_continuous(tmp_path_factory):
    """A half-hour day file, a 3-hour recording that turns it into hour files, and the lake of
    one uninterrupted run of both: shared by the kill points."""
    d = tmp_path_factory.mktemp("clean_continuous")
    config = write_plant(d, "wide10.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None, sample_rate_hz=10.0, max_gap_s=0.25)
    first = recording(d / "first.parquet", 0, 1800)
    rec = recording(d / "rec.parquet", 1800, 3 * 3600, seed=3)
    clean = d / "clean"
    ingest(config, first, clean)
    done = _child(config, rec, clean, first, SMALL)  # the warm-up file is already in the manifest: skipped
    assert done.returncode == 0, done.stderr
    return config, first, rec, clean


@pytest.mark.slow
@pytest.mark.xdist_group("continuous_kill")  # one worker computes the shared clean lake once
@pytest.mark.parametrize("kill_at", [1, 3])
def test_kill_9_during_a_continuous_ingest_then_rerun_gives_the_identical_lake(clean_continuous, tmp_path, kill_at):
    """SIGKILL while the staged files are put in place, in a day that switches from its day file
    to hour files: readers see the old day; a rerun gives the lake of one clean run, byte for byte."""
    config, first, rec, clean = clean_continuous
    wh = tmp_path / "wh"
    ingest(config, first, wh)
    old = lake(wh)
    killed = _child(config, rec, wh, first, SMALL, kill_at=kill_at)
    assert killed.returncode == -signal.SIGKILL
    assert list((wh / "lake").rglob("part-0.parquet"))  # the switch did not commit: the day file is the day
    assert_frame_equal(lake(wh), old)
    assert table(wh, "ingest_manifest").height == 1
    again = _child(config, rec, wh, first, SMALL)
    assert again.returncode == 0, again.stderr
    assert_frame_equal(lake(wh), lake(clean))
    assert _files(wh) == _files(clean)
    assert not list((wh / "lake").rglob("*.tmp"))

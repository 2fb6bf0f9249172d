"""Continuous recordings: back-to-back segments, recorder-style files, failures that leave no
partial file, memory that does not grow with the length."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap
from concurrent.futures.process import BrokenProcessPool
from datetime import timedelta
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import tomli_w

from flows.common.errors import ValvemonError
from flows.simulate import archive
from flows.simulate.archive import DEFAULT_COMMISSIONED, ArchivePlan, generate_plant_config, resolve_scenarios, write_archive
from schemas.plant_config import plant_config_to_dict

# two minutes from 05:59 on the commissioning day: two 60 s segments, split into hour files at 06:00
START = DEFAULT_COMMISSIONED + timedelta(hours=5, minutes=59)
PLAN = ArchivePlan(START, START + timedelta(minutes=2), continuous=True, file_s=3600.0)
US = 1_000_000


def _write(out: Path, workers: int = 0, plan: ArchivePlan = PLAN):
    config = generate_plant_config("C1", 2, "wide")
    scenarios = resolve_scenarios(config, None, {"V001": "wear", "V002": "broken_edge:1r@5.99"})
    return config, write_archive(config, out, plan, scenarios, seed=4, file_format="parquet", workers=workers)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("continuous")
    return out, *_write(out)


def test_plan_segments_are_clock_aligned_and_back_to_back():
    odd = ArchivePlan(START + timedelta(seconds=30.5), START + timedelta(minutes=3), continuous=True, segment_s=60)
    (first, n), = odd.recordings()
    segs = list(odd.segments(first, n))
    assert [m for _, m in segs] == [29_500, 60_000, 60_000]
    assert all(a + m * 1000 == b for (a, m), (b, _) in zip(segs, segs[1:]))
    assert all(a % (60 * US) == 0 for a, _ in segs[1:]) and odd.n_segments() == 3
    # a snapshot window no longer than a segment stays one segment, a longer one is cut
    snap = ArchivePlan(START, START + timedelta(days=1), windows_per_day=4, window_s=150)
    assert [m for _, m in snap.segments(next(snap.recordings())[0], snap.n_samples)] == [60_000, 60_000, 30_000]
    assert snap.n_segments() == 4 * 3 and snap.valve_seconds() == 4 * 150


def test_recording_is_back_to_back_across_the_file_boundary(recording):
    out, config, summary = recording
    names = [p.name for p in summary.files]
    assert names == ["C1_20250101T055900.parquet", "C1_20250101T060000.parquet"]
    assert sorted(p.name for p in (out / "exports").iterdir()) == names
    df = pl.concat([pl.read_parquet(p) for p in summary.files])
    t = df["timestamp"].dt.epoch("us").to_numpy()
    assert t[0] == int(START.timestamp() * US) and t.size == 120_000
    assert np.all(np.diff(t) == 1000)  # uniform 1 kHz steps, no gap or overlap at the cut
    for v in ("V001", "V002"):
        xc = df[f"C1.{v}.XC"].to_numpy()  # mm
        p1 = df[f"C1.{v}.P1"].to_numpy()  # bar
        jump = np.abs(np.diff(xc))
        # no jump where the segments (and files) meet: at most the largest step within (a
        # restart at rest would jump by tens of mm and several bar)
        assert jump[59_999] <= jump.max() and jump.max() < 0.5
        assert abs(p1[60_000] - p1[59_999]) < 5.0
        for seg in (xc[:60_000], xc[60_000:]):
            assert np.ptp(seg) > 50.0  # the cylinder moves in both segments


def test_truth_per_segment_and_wear_progresses(recording):
    out, _, _ = recording
    truth = pl.read_parquet(out / "truth.parquet")
    assert truth.height == 2 * 2 * 4
    starts = truth["window_start"].unique().sort()
    assert [s.isoformat() for s in starts] == ["2025-01-01T05:59:00+00:00", "2025-01-01T06:00:00+00:00"]
    assert (truth["window_end"] - truth["window_start"]).unique().to_list() == [timedelta(seconds=60)]
    s1 = truth.filter(valve_id="V001", edge="s1").sort("window_start")["underlap_m"].to_list()
    assert s1[1] > s1[0]  # wear goes on along the recording
    broken = truth.filter(valve_id="V002", edge="1r").sort("window_start")["broken"].to_list()
    assert broken == [False, True]  # the edge breaks at 5.99 h: the segment from 06:00 has it


def test_conditions_vary_along_the_recording():
    """Supply level, load and moves are drawn per segment: over 20 minutes the measured supply
    level wanders (bounded), the load takes several levels."""
    from flows.simulate.simulator import simulate_measured

    config = generate_plant_config("C1", 1, "wide")
    runs = archive.make_valve_runs(config, {"V001": "healthy"}, 0)
    p = runs[0].params
    carry, means = None, []
    for k in range(20):
        t0 = int(START.timestamp() * US) + k * 60 * US
        m, carry = simulate_measured(p, [p.nominal_condition], [("V001", t0)], 60_000, 0, carry)
        means.append(m["ps"][0].mean())
    means = np.array(means) / 1e5
    assert np.ptp(means) > 1.0 and np.all(np.abs(means - 200.0) < 15.0)


@pytest.mark.slow
def test_same_bytes_with_and_without_workers(recording, tmp_path):
    """Deterministic, and the segments chain through worker processes as they do in-process."""
    out, _, summary = recording
    _, again = _write(tmp_path, workers=1)
    assert [p.name for p in again.files] == [p.name for p in summary.files]
    for a, b in zip(summary.files, again.files):
        assert a.read_bytes() == b.read_bytes()
    assert (out / "truth.parquet").read_bytes() == (tmp_path / "truth.parquet").read_bytes()


@pytest.mark.parametrize(
    "failure, raised, match",
    [
        (ValvemonError("simulation of valve V001 diverged"), ValvemonError, "V001 diverged"),
        (KeyboardInterrupt(), KeyboardInterrupt, None),
        (BrokenProcessPool("killed"), ValvemonError, "worker process died simulating V001, V002 from 2025-01-01T06:00:00Z"),
    ],
)
def test_a_failure_leaves_no_partial_file(tmp_path, monkeypatch, failure, raised, match):
    real = archive.simulate_measured
    calls = []

    def failing(*args):
        calls.append(1)
        if len(calls) == 2:  # the first file is open and half written
            raise failure
        return real(*args)

    monkeypatch.setattr(archive, "simulate_measured", failing)
    with pytest.raises(raised, match=match):
        _write(tmp_path)
    assert len(calls) == 2
    assert list((tmp_path / "exports").iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exports", "plant.toml"]


def test_cli_divergence_is_one_line_and_no_partial_file(tmp_path, monkeypatch, capsys):
    """A plant sampled at 50 Hz: 10 ms RK4 steps are far beyond the stable step, the simulation
    diverges in the first segment. One line naming the valve and the instant; no file left."""
    from flows.cli import main

    config = generate_plant_config("BAD", 1, "long")
    config = dataclasses.replace(config, export=dataclasses.replace(config.export, sample_rate_hz=50.0, max_gap_s=0.1))
    cfg = tmp_path / "plant.toml"
    cfg.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    out = tmp_path / "arch"
    argv = ["valvemon", "simulate", "--config", str(cfg), "--out", str(out), "--hours", "0:1", "--window-s", "300", "--quiet"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as exc:
        main()
    err = capsys.readouterr().err
    assert exc.value.code == 1
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("valvemon: error: simulation of valve V001 diverged at 2025-01-01T00:00:00"), err
    assert "segment starting 2025-01-01T00:00:00Z" in err
    assert list((out / "exports").iterdir()) == [] and not list(out.glob("truth*"))


@pytest.mark.slow
def test_memory_does_not_grow_with_the_length(tmp_path):
    """Peak RSS of a child writing 2 and 20 minutes of a continuous recording (one valve, wide
    Parquet, 10-minute files): the longer one holds no more than a segment at a time."""
    script = textwrap.dedent(
        """
        import resource, sys
        from datetime import timedelta
        from pathlib import Path
        from flows.simulate.archive import DEFAULT_COMMISSIONED, ArchivePlan, generate_plant_config, resolve_scenarios, write_archive
        minutes = float(sys.argv[2])
        config = generate_plant_config("M1", 1, "wide")
        plan = ArchivePlan(DEFAULT_COMMISSIONED, DEFAULT_COMMISSIONED + timedelta(minutes=minutes), continuous=True, file_s=600.0)
        write_archive(config, Path(sys.argv[1]), plan, resolve_scenarios(config, "wear", {}), file_format="parquet")
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        """
    )
    rss = {}
    for minutes in (2, 20):
        r = subprocess.run([sys.executable, "-c", script, str(tmp_path / f"m{minutes}"), str(minutes)],
                           capture_output=True, text=True, timeout=600, cwd=Path(__file__).resolve().parents[2])  # fmt: skip
        assert r.returncode == 0, r.stderr
        rss[minutes] = int(r.stdout.split()[-1]) / 1024  # MB
    assert len(list((tmp_path / "m20" / "exports").iterdir())) == 2
    assert rss[20] < rss[2] + 40, rss  # 10x the data; one segment's worth of headroom


def test_snapshot_windows_split_at_file_boundaries(tmp_path):
    """15 s windows every 50 s in 1-minute files: the window from 00:00:50 is cut at 00:01:00,
    every file holds only its own minute, no sample is lost or repeated."""
    config = generate_plant_config("F1", 1, "wide")
    plan = ArchivePlan(DEFAULT_COMMISSIONED, DEFAULT_COMMISSIONED + timedelta(minutes=2), windows_per_day=1728, window_s=15, file_s=60.0)
    summary = write_archive(config, tmp_path, plan, resolve_scenarios(config, None, {}), file_format="parquet")
    assert [p.name for p in summary.files] == ["F1_20250101T000000.parquet", "F1_20250101T000100.parquet"]
    t0 = int(DEFAULT_COMMISSIONED.timestamp() * US)
    seen = []
    for p in summary.files:
        t = pl.read_parquet(p)["timestamp"].dt.epoch("us").to_numpy() - t0
        assert np.unique(t // (60 * US)).size == 1
        seen.append(t)
    t = np.concatenate(seen)
    expected = np.concatenate([s * US + np.arange(15_000) * 1000 for s in (0, 50, 100)])
    assert np.array_equal(t, expected)

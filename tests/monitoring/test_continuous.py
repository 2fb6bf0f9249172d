"""Continuous recordings (back-to-back 1 kHz samples for minutes to hours) are cut into windows
by the clock (``[monitor] window_s``, transforms.windows), fitted as accurately as the study's
snapshots, and the same windows come out however the lake is read; snapshot archives give the
same fits as before the rule (docs/monitoring.md, "Continuous recordings")."""

from __future__ import annotations

import dataclasses
from datetime import timedelta

import numpy as np
import polars as pl
import pytest

import flows.monitor.flow as fm
from flows.common.warehouse_db import connect, query_frame
from flows.ingest.flow import run_ingest
from flows.monitor.flow import run_monitor
from flows.simulate.archive import DEFAULT_COMMISSIONED, SimulateRequest, run_simulate
from model import TABLE1, condition_arrays, condition_at, wear
from model.params import EDGES
from schemas.plant_config import DEFAULT_WINDOW_ROWS, DEFAULT_WINDOW_S
from transforms.monitor import monitor

from .sim_lake import START, simulated_lake, table1_params
from .test_accuracy import ALPHA_TOL, HOURS, NOMINAL, STUDY_TRAJECTORY, X_TOL

X_MAX = TABLE1.geometry.x_max_m


def test_continuous_recording_is_cut_into_accurate_windows():
    """A 20-min recording of a worn valve (8,000 h, its own manufacturing scatter) against the
    nominal characteristic: 20 windows of a minute, each within the study's bounds (α̂ 2 %,
    x̂ 0.5 % of x_max; measured on 6 valves: ≤ 0.02 % and ≤ 0.02 %, bench/window_length.py)."""
    scenario = wear(scatter_seed=3)
    hours = np.array([8000.0])
    xu, al = condition_arrays(scenario, hours)
    lake = simulated_lake(condition_at(scenario, hours), 3, duration_s=1200.0)
    points = {}
    # every row, and every 10th row of a window (the default [monitor] window_rows)
    for rows in (None, DEFAULT_WINDOW_ROWS):
        params = dataclasses.replace(table1_params(), window_s=DEFAULT_WINDOW_S, window_rows=rows)
        res = monitor(lake, params, {"V1": NOMINAL}, leakage={"V1": NOMINAL})
        w = res.windows
        assert w.height == 20
        assert w["window_start"].to_list() == [START + timedelta(minutes=k) for k in range(20)]
        assert ((w["window_end"] - w["window_start"]).dt.total_milliseconds() == 59_999).all()
        fits = res.fits
        assert fits.height == 20 * 4 and (fits["status"] == "ok").all()
        nom = TABLE1.nominal_condition
        i = np.array([EDGES.index(e) for e in fits["edge"]])
        alpha_err = fits["alpha_hat"].to_numpy() / (al[0, i] / np.array(nom.alpha)[i]) - 1
        x_err = fits["x_hat_m"].to_numpy() - (xu[0, i] - np.array(nom.underlap_m)[i])
        assert np.abs(alpha_err).max() < ALPHA_TOL and np.abs(x_err).max() < X_TOL
        # the state is the same all along: the windows agree with each other far inside the
        # condition bounds' scatter floors (α 0.02, x̂ 0.30 % of x_max)
        per_edge = fits.group_by("edge").agg(pl.col("alpha_hat").std().alias("sa"), (pl.col("x_hat_m").std() / X_MAX * 100).alias("sx"))
        assert (per_edge["sa"] < 0.002).all() and (per_edge["sx"] < 0.03).all()
        points[rows] = fits["n_points"].to_numpy()
    # a tenth of the rows, about a tenth of the points, each window still far above the 500 the fit needs
    assert np.all(np.abs(points[DEFAULT_WINDOW_ROWS] * 10 - points[None]) <= 0.02 * points[None])
    assert points[DEFAULT_WINDOW_ROWS].min() > 1000


def test_snapshot_fits_unchanged_by_the_window_length():
    """The study's 10 s snapshots, moved to straddle a minute (and so a clock cut of the default
    length): every snapshot is still one window and its fits equal those of whole runs
    (``window_s=None``, the rule before windows were cut by the clock) to 1e-9."""
    lake = simulated_lake(condition_at(wear(scatter_seed=2), HOURS), 2, trajectory=STUDY_TRAJECTORY)
    lake = lake.with_columns(pl.col("timestamp_utc") + timedelta(seconds=55))
    fits = {}
    for length in (None, DEFAULT_WINDOW_S):
        params = dataclasses.replace(table1_params(), window_s=length)
        res = monitor(lake, params, {"V1": NOMINAL}, leakage={"V1": NOMINAL})
        assert res.windows.height == HOURS.size
        fits[length] = res.fits
    a, b = fits[None], fits[DEFAULT_WINDOW_S]
    assert a.select(pl.exclude(pl.Float64)).equals(b.select(pl.exclude(pl.Float64)))
    assert (a["status"] == "ok").all()
    for c in [c for c, t in a.schema.items() if t == pl.Float64]:
        np.testing.assert_allclose(b[c].to_numpy(), a[c].to_numpy(), rtol=1e-9, atol=0, equal_nan=True, err_msg=c)


def test_commissioning_baseline_ignores_the_window_length():
    """Step 4a pools a commissioning recording's points: cut or not, the same baseline."""
    from transforms.monitor import commissioning_baseline

    lake = simulated_lake(condition_at(wear(scatter_seed=4), np.array([0.0])), 4, duration_s=150.0)
    fitted = [commissioning_baseline(lake, dataclasses.replace(table1_params(), window_s=w), NOMINAL) for w in (None, 60.0)]
    for e in EDGES:
        np.testing.assert_array_equal(fitted[0][e].characteristic.values_m2, fitted[1][e].characteristic.values_m2)


# --------------------------------------------------------------------------------------------
# through the flows: the same windows however the lake is read
# --------------------------------------------------------------------------------------------

FITS = "SELECT * EXCLUDE (monitored_at) FROM edge_fits ORDER BY valve_id, window_start, edge"


def _table(wh, sql: str) -> pl.DataFrame:
    with connect(wh) as con:
        return query_frame(con, sql)


def _assert_same_fits(got: pl.DataFrame, ref: pl.DataFrame) -> None:
    """Same rows and keys; floats to 1e-12 (``operating_hours`` differs in the last bit
    between frame lengths: polars divides in SIMD blocks)."""
    assert got.select(pl.exclude(pl.Float64)).equals(ref.select(pl.exclude(pl.Float64)))
    for c in [c for c, t in ref.schema.items() if t == pl.Float64]:
        np.testing.assert_allclose(got[c].to_numpy(), ref[c].to_numpy(), rtol=1e-12, atol=0, equal_nan=True, err_msg=c)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """One valve recording 2 × 600 s back to back from 00:00:17.3 (not on the minute): 1.2 M rows,
    ingested."""
    root = tmp_path_factory.mktemp("continuous")
    sim = root / "sim"
    run_simulate(SimulateRequest(out=sim, n_valves=1, days=0.0138, windows_per_day=144, window_s=600.0, format="parquet",
                                 seed=4, workers=0), show_progress=False)  # fmt: skip
    for f in sorted((sim / "exports").glob("*.parquet")):
        pl.read_parquet(f).with_columns(pl.col("timestamp") + pl.duration(milliseconds=17_300)).write_parquet(f)
    wh = root / "wh"
    run_ingest(sim / "plant.toml", [sim / "exports"], wh)
    return sim / "plant.toml", wh


@pytest.mark.slow
def test_continuous_recording_through_the_flows(recording, monkeypatch):
    """``valvemon monitor`` cuts the 20-min recording into 21 windows on the minute (the first
    42.7 s and the last 17.3 s are remainders, fitted or recorded with their status); spans with
    borders inside windows (what backfill units and the nightly run read) and small chunks give
    the very same rows."""
    config, wh = recording
    t0 = DEFAULT_COMMISSIONED + timedelta(seconds=17.3)
    reports = run_monitor(config, wh)
    assert reports[0].windows == 21 and reports[0].rows_read == 1_200_000
    whole = _table(wh, FITS)
    starts = sorted(set(whole["window_start"].to_list()))
    assert starts == [t0] + [DEFAULT_COMMISSIONED + timedelta(minutes=k) for k in range(1, 21)]
    assert whole.height == 21 * 4
    # full minutes are fitted; but 00:10, which holds the junction of the simulator's two 600 s
    # slots (each its own simulation: the state jumps there, the derivatives across it are junk)
    full = whole.filter(pl.col("window_start").is_between(starts[1], starts[-2]) & (pl.col("window_start") != starts[10]))
    assert full.height == 18 * 4 and (full["status"] == "ok").all()
    remainders = whole.filter(pl.col("window_start").is_in([starts[0], starts[-1]]))
    assert remainders.height == 2 * 4 and set(remainders["status"]) <= {"ok", "too_few_points", "too_little_coverage", "no_points"}
    # two spans split inside the 00:07 window: each window is fitted in the span it starts in
    with connect(wh) as con:
        con.execute("UPDATE edge_fits SET alpha_hat = -1")
    split = DEFAULT_COMMISSIONED + timedelta(minutes=7, seconds=30)
    first = run_monitor(config, wh, end=split)
    second = run_monitor(config, wh, start=split)
    assert first[0].windows == 8 and second[0].windows == 13
    _assert_same_fits(_table(wh, FITS), whole)
    # chunks of two minutes (a day holding a recording is read in spans): the same rows
    monkeypatch.setattr(fm, "CHUNK_ROWS", 100_000)
    monkeypatch.setattr(fm, "CHUNK_SPAN_S", 120.0)
    chunks = list(fm.lake_chunks(wh, "V001", 0.003, None, None, columns=("p1_pa",), window_s=60.0))
    t = pl.concat(chunks)["timestamp_utc"]
    assert len(chunks) >= 10 and t.len() == 1_200_000 and (t.diff().drop_nulls().dt.total_microseconds() > 0).all()
    assert all(c["timestamp_utc"][0] == t0 or c["timestamp_utc"][0].second == 0 for c in chunks)  # cut at window starts
    run_monitor(config, wh)
    _assert_same_fits(_table(wh, FITS), whole)

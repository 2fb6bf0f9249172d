"""The plant's output in the lake's canonical frame, and its hidden effects acting where they should."""

from dataclasses import replace
from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl
import pytest

from . import (COLUMNS, NAMEPLATE, Effects, Load, Trajectory, effect, manufactured, noisy_end, plant_grade, simulate,
               simulate_windows, sparse, to_lake_frame, without_noise)
from .scenarios import LIBRARY, OUTSIDE, draw_load, draw_trajectory
from .sensors import first_order_lag

START = datetime(2025, 3, 1, 23, 59, 59, 999_000, tzinfo=timezone.utc)
QUIET = without_noise(NAMEPLATE)


def test_lake_frame_is_the_canonical_sensor_frame():
    recs = simulate_windows(NAMEPLATE, 2, 3, duration_s=0.5)
    lake = to_lake_frame(recs, "V7", START)
    assert lake.columns == list(COLUMNS)
    assert lake.schema["timestamp_utc"] == pl.Datetime("us", "UTC") and lake.schema["date"] == pl.Date
    assert all(lake.schema[c] == pl.Float32 for c in COLUMNS[3:])
    assert lake.height == 1000 and (lake["valve_id"] == "V7").all()
    t = lake["timestamp_utc"]
    assert t[0] == START and t[500] == START + timedelta(hours=1)
    assert (t.diff().drop_nulls().dt.total_microseconds().to_numpy()[:499] == 1000).all()
    assert lake["date"].unique().sort().to_list() == [START.date(), (START + timedelta(days=1)).date()]
    np.testing.assert_array_equal(lake["p1_pa"].to_numpy()[:500], recs[0].p1.astype(np.float32))
    with pytest.raises(ValueError, match="timezone"):
        to_lake_frame(recs, "V7", START.replace(tzinfo=None))


def test_loads_step_every_one_to_four_seconds_and_ramp_continuously():
    op = NAMEPLATE.operation
    load = draw_load(op, 600.0, np.random.default_rng(1))
    t = np.arange(0, 600, 1e-3)
    f = load.at(t)
    assert np.abs(f).max() <= op.load_max_n and np.abs(np.diff(f)).max() < op.load_max_n * 2 / 0.1 * 1e-3 + 1e-9
    starts = load.t_s[1::2]
    gaps = np.diff(starts) - (load.t_s[2::2][:-1] - starts[:-1])
    assert gaps.min() >= 1.0 and gaps.max() <= 4.0 and 120 < starts.size < 600


def test_every_effect_has_a_name_and_switches_on_alone():
    for name in LIBRARY + OUTSIDE:
        assert effect(name).active == [name]
    assert effect("pressure_sensor_gain", 1.05, channel="p2").p2_gain == 1.05
    with pytest.raises(ValueError, match="unknown effect"):
        effect("cavitation")


def _still(effects, n=1500):
    """The cylinder held still at X = 0.3 m in closed loop under no load, with ``effects``."""
    return simulate(QUIET, n / 1000, 0, effects=effects, load=Load.constant(0.0), trajectory=Trajectory.hold(0.3),
                    supply=(200e5, 0.0, 0.0, 225.0, 0.0, 0.5e5))


def test_sensor_effects_act_on_the_records_only():
    clean = _still(None)
    fx = Effects(p1_gain=1.05, p2_offset_pa=2e5, spool_sensor_offset_m=10e-6)
    rec = _still(fx)
    np.testing.assert_allclose(rec.true["p1"], clean.true["p1"], atol=1e-3)
    np.testing.assert_allclose(rec.p1, 1.05 * clean.p1, rtol=1e-12)
    np.testing.assert_allclose(rec.p2, clean.p2 + 2e5, rtol=1e-12)
    # at rest the spool sits where the flows balance; the transducer reads 10 um more, and the
    # controller commands the reading (the valve's inner loop regulates it)
    np.testing.assert_allclose(rec.true["x"], clean.true["x"], atol=1e-10)
    np.testing.assert_allclose(rec.x_spool, clean.x_spool + 10e-6, atol=1e-10)
    np.testing.assert_allclose(rec.true["x_ref"], clean.true["x_ref"] + 10e-6, atol=1e-10)


def test_leakage_is_fed_by_the_valve_at_standstill():
    """At rest the valve must supply the leakage: q1 = q_i into chamber 1, q2 = q_i - q_e out of chamber 2."""
    K_i, K_e = 2e-12, 1e-12
    rec = _still(Effects(internal_leakage_m3_s_pa=K_i, external_leakage_m3_s_pa=K_e))
    T = rec.true
    qi, qe = K_i * (T["p1"] - T["p2"]), K_e * T["p2"]
    assert np.abs(qi).min() > 1e-5  # ~0.02 L/s across the piston
    np.testing.assert_allclose(T["q1"][-100:], qi[-100:], rtol=1e-3)
    np.testing.assert_allclose(T["q2"][-100:], (qi - qe)[-100:], rtol=1e-3)


def test_transmitter_extra_lag_slows_one_channel():
    plant = replace(QUIET, sensors=replace(QUIET.sensors, skew_samples=0))
    traj = Trajectory.moves(0.3, [(0.1, 0.6, 0.45)])
    a = simulate(plant, 1.0, 0, load=Load.constant(0.0), trajectory=traj)
    b = simulate(plant, 1.0, 0, load=Load.constant(0.0), trajectory=traj, effects=effect("transmitter_lag", 2e-3, channel="p1"))
    np.testing.assert_array_equal(a.p2, b.p2)
    p1 = b.true["p1"]
    err = {tau: np.abs(b.p1 - first_order_lag(p1, 1e-3, tau)).max() for tau in (1e-3, 3e-3)}
    assert err[3e-3] < 0.05 * err[1e-3], err  # the p1 reading now lags 1 + 2 ms


def test_a_recording_in_segments_is_one_continuous_run():
    whole = simulate(QUIET, 3.0, 9)
    cut = simulate(QUIET, 3.0, 9, segment_s=0.7)
    assert np.ptp(whole.true["X"]) > 0.05
    for sig, tol in (("p1", 0.02e5), ("p2", 0.02e5), ("x_spool", 0.05e-6), ("x_cyl", 1e-6)):
        np.testing.assert_allclose(getattr(cut, sig), getattr(whole, sig), rtol=0, atol=tol, err_msg=sig)


def test_manufactured_valve_scatters_per_edge_and_misstates_beta():
    a, b = manufactured(NAMEPLATE, 1), manufactured(NAMEPLATE, 2)
    assert a == manufactured(NAMEPLATE, 1) and a != b
    assert a.fluid.bulk_modulus_pa == pytest.approx(1.5e9 * 1.025)
    xu = np.array([e.underlap_m for e in a.valve.edges])
    al = np.array([e.alpha for e in a.valve.edges])
    assert np.all(np.abs(xu - 40e-6) < 20e-6) and len(set(xu)) == 4
    assert np.all(np.abs(al / 0.675 - 1) < 0.12) and len(set(al)) == 4


def test_plant_grade_positions_carry_a_plants_noise_in_its_steps():
    """The noisy end records the spool at 0.2 % of x_max (7 um) and the cylinder at 10 um in 5 um
    steps; per-plant draws stay inside what plants record."""
    rec = simulate(noisy_end(NAMEPLATE), 1.0, 3)
    ds, dc = rec.x_spool - rec.true["x"], rec.x_cyl - rec.true["X"]
    assert 6.3e-6 < ds.std() < 7.7e-6 and 10.0e-6 < dc.std() < 11.6e-6  # + the step's own 5/sqrt(12) um
    np.testing.assert_allclose(rec.x_cyl / 5e-6, np.round(rec.x_cyl / 5e-6), atol=1e-6)
    for seed in range(20):
        s = plant_grade(NAMEPLATE, seed).sensors
        assert 0.5e-3 * 3.5e-3 <= s.x_spool.noise <= 3.0e-3 * 3.5e-3 and s.x_spool.step == 8e-3 / 2**16
        assert 1e-6 <= s.x_cyl.noise <= 20e-6 and s.x_cyl.step in {k * 1e-6 for k in range(1, 6)}
        assert s.p1 == NAMEPLATE.sensors.p1


def test_a_sparse_valve_dwells_two_to_ten_seconds_between_moves():
    op = sparse(NAMEPLATE).operation
    t0, T, _, _ = draw_trajectory(op, 600.0, np.random.default_rng(5)).arrays()
    dwell = t0[1:] - (t0 + T)[:-1]
    assert 40 < dwell.size < 150 and dwell.min() >= 2.0 and dwell.max() <= 10.0
    assert 0.5 <= t0[0] <= 3.0

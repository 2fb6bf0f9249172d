"""transforms.discrepancy: records, residuals, the load estimate, the selection and the gaps."""

import ast
from dataclasses import replace
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from hypothesis import given
from hypothesis import strategies as st

import transforms.discrepancy as td
from model import TABLE1, measure, simulate_windows
from model.effects import Effects, equation_terms
from transforms.discrepancy import (
    DiscrepancySettings,
    GapAccumulator,
    Record,
    block_stats,
    demean_by_group,
    estimate_load,
    forward_select,
    interval_edges,
    interval_residuals,
    normalised_gap,
    prepare_record,
    split_records,
)
from transforms.discrepancy.load import LoadEstimate, friction_within, interval_load, motion_mismatch, step_filter
from transforms.discrepancy.residuals import triangular_force_balance
from transforms.discrepancy.rows import tapered

from .simdata import simulate_lake


def test_transforms_discrepancy_does_no_io_and_no_orchestration():
    """transforms/discrepancy (the pipeline included) may use the model's replay, never flows, Prefect or DuckDB."""
    for path in Path(td.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                assert node.module.split(".")[0] not in {"flows", "prefect", "duckdb"}, (path.name, node.module)
            if isinstance(node, ast.Import):
                for a in node.names:
                    assert a.name.split(".")[0] not in {"flows", "prefect", "duckdb"}, (path.name, a.name)


def test_split_records_cuts_at_gaps_and_lengths():
    lake = simulate_lake(None, n_windows=3, window_s=3.0, seed=0)
    s = DiscrepancySettings(min_record_s=1.5, max_record_s=2.0)
    recs = split_records(lake, s)
    assert len(recs) == 3 and all(r.n == 2000 for r in recs)  # the 1 s rest of each window is too short
    recs = split_records(lake, DiscrepancySettings(min_record_s=1.0, max_record_s=2.0))
    assert [r.n for r in recs] == [2000, 1000] * 3
    assert recs[1].start_us - recs[0].start_us == 2_000_000
    assert len(split_records(lake, DiscrepancySettings(max_records=2, min_record_s=1.0, max_record_s=2.0))) == 2
    assert split_records(lake.head(0), s) == []
    with pytest.raises(ValueError):
        split_records(pl.concat([lake, lake.with_columns(pl.lit("V2").alias("valve_id"))]), s)


def test_step_filter_ignores_quadratics_and_measures_jumps():
    t = np.arange(400.0)
    f = 3.0 + 0.5 * t - 0.002 * t**2
    j = step_filter(f, 40)
    assert np.nanmax(np.abs(j)) < 1e-8
    g = f + np.where(t >= 200, 1000.0, 0.0)
    j = step_filter(g, 40)
    assert np.nanargmax(np.abs(j)) == 199 and j[199] == pytest.approx(1000.0, rel=1e-9)


def _exact_record(seed=7, effects=None, seconds=10.0):
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], seconds, seed=seed, effects=effects)
    raw = {"ps": res.ps_pa[0], "pr": res.pr_pa[0], "p1": res.p1_pa[0], "p2": res.p2_pa[0], "x": res.x_m[0], "X": res.X_m[0]}
    return res, prepare_record(Record("V", 0, 0, 1e-3, raw), DiscrepancySettings())


def _rolling_force(load_of_t, rng=None):
    """The force balance F̂_l of seed 1's exact record (the cylinder runs over 2.98–5.22 s) with the
    load ``load_of_t(t)`` [N], a 600 kg mass and a 3 kN·s/m friction mismatch and 30 N of noise
    (from ``rng``, default ``default_rng(3)``): (settings, t, v, a, load, f), ``a`` the acceleration
    over ±L samples as the force balance averages it."""
    _, rec = _exact_record(seed=1)
    s = DiscrepancySettings()
    t = np.arange(rec.n) * 1e-3
    L = s.interval_samples
    a = np.full(rec.n, np.nan)
    a[L:-L] = (rec.raw["X"][2 * L:] - 2 * rec.raw["X"][L:-L] + rec.raw["X"][:-2 * L]) / (L * 1e-3) ** 2
    v = rec.sg["v"]
    load = load_of_t(t)
    rng = np.random.default_rng(3) if rng is None else rng
    return s, t, v, a, load, load + 600.0 * a + 3000.0 * v + 30.0 * rng.normal(size=rec.n)


def test_integrated_residuals_vanish_on_exact_states_and_show_a_hidden_leak():
    s = DiscrepancySettings()
    for fx, expect_zero in ((None, True), (Effects(internal_leakage_m3_s_pa=2e-12), False)):
        res, rec = _exact_record(effects=fx)
        terms = equation_terms({"x": rec.raw["x"], "p1": rec.raw["p1"], "p2": rec.raw["p2"], "ps": rec.raw["ps"], "pr": rec.raw["pr"], "X": rec.raw["X"], "v": res.vX_m_s[0]}, TABLE1, None, None, 1e4)
        e = interval_edges(rec.n - 10, 20, 10)
        ir = interval_residuals(terms, rec.raw["X"], TABLE1.cylinder.A1, TABLE1.cylinder.A2, 1e-3, e, s.interval_smoothing)
        ok = np.isfinite(ir.r1)
        leak = 2e-12 * np.abs(res.p1_pa[0] - res.p2_pa[0]).mean()
        if expect_zero:
            assert np.sqrt(np.mean(ir.r1[ok] ** 2)) < 0.01 * leak  # integration error only
            assert np.sqrt(np.mean(ir.r2[ok] ** 2)) < 0.01 * leak
        else:  # r1 = K_i (p1 - p2) averaged over the interval, r2 = -r1
            assert np.mean(ir.r1[ok]) == pytest.approx(-leak, rel=0.05)
            np.testing.assert_allclose(ir.r2[ok], -ir.r1[ok], rtol=0.05, atol=0.02 * leak)


def test_triangular_force_balance_is_the_load_and_steps_are_found():
    res, rec = _exact_record(seed=1)
    terms = equation_terms({"x": rec.raw["x"], "p1": rec.raw["p1"], "p2": rec.raw["p2"], "ps": rec.raw["ps"], "pr": rec.raw["pr"], "X": rec.raw["X"], "v": res.vX_m_s[0]}, TABLE1, None, None, 1e4)
    f = triangular_force_balance(terms["force"], rec.raw["X"], terms["mass"], 1e-3, 20)
    # moving over the whole triangle (no sticking inside it), no load step inside it
    moving = np.convolve(np.abs(res.vX_m_s[0]) > 0.01, np.ones(41), "same") == 41
    F = res.F_l_n[0]
    flat = moving & (np.convolve(np.diff(F, prepend=F[0]) != 0, np.ones(41), "same") == 0) & np.isfinite(f)
    assert np.max(np.abs(f[flat] - F[flat])) < 60.0  # N, against a load of ±15 kN
    est = estimate_load(f, rec.sg["v"], DiscrepancySettings())
    true_steps = np.flatnonzero(np.diff(F)) + 1
    moving_steps = [k for k in true_steps if abs(res.vX_m_s[0][k]) > 0.03]
    for k in moving_steps:
        assert np.min(np.abs(est.steps - k)) <= 3


def test_force_balance_average_keeps_ramps_and_every_valid_sample():
    """The force balance's average over shifts (:func:`box_within`) is exact on a load linear in
    time, keeps every valid sample (narrower windows at a run's ends, nothing across a gap), leaves
    the other samples as they are, and divides white noise's variance by the window."""
    from transforms.discrepancy.load import box_within

    n = 400
    ok = np.ones(n, bool)
    ok[:25] = ok[150:170] = ok[-25:] = False
    ramp = 3.0 * np.arange(n) - 200.0
    out = box_within(ramp, ok, 10)
    np.testing.assert_allclose(out, ramp, atol=1e-9)
    spike = np.where(np.arange(n) == 149, 1e6, 0.0)  # the last sample before a gap
    out = box_within(spike, ok, 10)
    assert out[149] == 1e6 and out[148] == pytest.approx(1e6 / 3) and out[139] == pytest.approx(1e6 / 21)
    assert np.all(out[170:] == 0.0) and out[160] == 0.0 and out[138] == 0.0
    rng = np.random.default_rng(0)
    z = rng.normal(0.0, 1.0, 200_000)
    inner = box_within(z, np.ones(z.size, bool), 10)[100:-100]
    assert np.var(inner) == pytest.approx(1 / 21, rel=0.03)


def test_mass_mismatch_is_not_read_light_from_a_noisy_position():
    """The force balance holds −m ε where its acceleration holds +ε (the same second difference of
    X's noise), so plain least squares reads the mass mismatch short by m·s²/(s² + Var a); the
    corrected fit (:func:`motion_mismatch` with ``noise``) reads it within its scatter; the noise
    power of a second difference over ±20 samples is 6 per unit, 118/441 averaged over 21 shifts."""
    from transforms.discrepancy.load import motion_mismatch, second_difference_energy

    assert second_difference_energy(20, 0) == pytest.approx(6.0)
    assert second_difference_energy(20, 10) == pytest.approx(118 / 441)
    rng = np.random.default_rng(7)
    n, m, dm, dv = 200_000, 6000.0, 300.0, 2.0e4
    v = 0.05 * np.sin(np.arange(n) / 300.0)
    a = 0.2 * np.cos(np.arange(n) / 97.0)
    s = 0.1  # the acceleration's noise [m/s²], a third of its RMS
    eps = rng.normal(0.0, s, n)
    f = 1500.0 + dv * v + dm * a - m * eps
    ok = np.ones(n, bool)
    plain = motion_mismatch(f, np.full(n, 1500.0), ok, (v, a + eps))
    fixed = motion_mismatch(f, np.full(n, 1500.0), ok, (v, a + eps), (np.full(n, s * s), m))
    assert plain[1] == pytest.approx(dm - (m + dm) * s * s / (s * s + 0.02), rel=0.02)  # ~ −1.5 t
    assert fixed[1] == pytest.approx(dm, abs=60.0) and fixed[0] == pytest.approx(dv, rel=0.05)


def test_load_follows_ramps_and_keeps_mass_and_friction_apart():
    """A rolling force (ramps to new levels, unseen by the step filter) is followed piecewise
    linearly, bending at the ramps' corners, where one constant per segment leaves it; a mass and a
    friction mismatch, which act on the acceleration and the velocity, stay separable from that load
    (what the regression eliminates, :func:`load_projector`); a piecewise-constant load keeps one
    constant per segment."""
    from transforms.discrepancy.load import load_projector, project_out

    rng = np.random.default_rng(3)
    s, t, v, a, ramp, f = _rolling_force(lambda t: np.interp(t, [0.0, 2.0, 2.3, 5.0, 5.35, 8.0, 8.1], [1500.0, 1500.0, -2500.0, -2500.0, 4000.0, 4000.0, 0.0]), rng)
    est = estimate_load(f, v, s, accel=a, dt=1e-3)
    assert est.knot_samples == 100  # ramps of 1.5-6.5 kN
    knots = np.concatenate(est.corners)
    for corner in (2000, 5000, 8000, 8100):  # the corners seen while moving, within 10 samples
        assert np.min(np.abs(knots - corner)) <= 10, (corner, knots)
    assert knots.size < 40, knots  # the ends of the segments and their gaps, and the corners (the 0.1 s grid: ~90)
    ok = est.valid
    err = np.sqrt(np.mean((est.load[ok] - ramp[ok]) ** 2))
    const = estimate_load(f, v, s)  # one constant per segment
    assert err < 30.0 and err < 0.05 * np.sqrt(np.mean((const.load[ok] - ramp[ok]) ** 2)), err  # N (noise 30 N; knots every 0.1 s: ~35-250 N)
    flat = estimate_load(np.where(t < 5.0, 1500.0, -2500.0) + 600.0 * a + 30.0 * rng.normal(size=t.size), v, s, accel=a, dt=1e-3)
    assert flat.knot_samples == 0
    # eliminating the load (rows every 20 samples, as the motion rows) leaves the mass and friction
    rows = np.flatnonzero(ok & np.isfinite(a) & (np.abs(v) > s.v_move_m_s))[::20]
    group = est.segment[rows]
    proj = load_projector(group, rows.astype(float), {int(g): est.knots(int(g)) for g in np.unique(group)})
    X = project_out(np.column_stack([a[rows], v[rows]]), proj)
    coef = np.linalg.lstsq(X, project_out(f[rows], proj), rcond=None)[0]
    assert coef[0] == pytest.approx(600.0, rel=0.05) and coef[1] == pytest.approx(3000.0, rel=0.03), coef  # knots every 0.1 s: 10 %, 25 %
    kn = est.knots(int(group[0]))
    pwl = np.where(group == group[0], np.interp(rows, kn, np.cos(np.arange(kn.size))), 0.0)  # piecewise linear on its knots
    assert np.max(np.abs(project_out(pwl, proj))) < 1e-9
    # a step added inside a segment (the calibration's split) gives each side the corners on its side, between its new ends
    g = int(np.argmax([k.size for k in est.corners]))
    kn = est.knots(g)
    k = int((kn[0] + kn[-1]) / 2)
    split = est.with_added_step(k, s.step_guard_samples)
    for side in (g, g + 1):
        idx = np.flatnonzero(split.valid & (split.segment == side))
        kside = split.knots(side)
        assert kside[0] == idx[0] and kside[-1] == idx[-1], (kside, idx[[0, -1]])
        assert np.all(np.isin(kside[1:-1], kn)) and np.all((kside[1:-1] < k) if side == g else (kside[1:-1] > k))


def test_load_follows_a_gentle_ramp():
    """A rolling force that moves 700 N over 0.3 s while the cylinder runs (reference plant seed 1
    has such ramps) leaves one constant per segment ~150 N: more than 3x the noise, so the load
    follows it, and the corner pass with the wider filter finds its corners, which the ±0.05 s
    filter does not tell from the noise (1.4 N/ms, under its 3 N/ms floor)."""
    s, _, v, a, ramp, f = _rolling_force(lambda t: np.interp(t, [3.5, 3.8], [1500.0, 2200.0]))  # within the cylinder's run

    def error(settings):
        est = estimate_load(f, v, settings, accel=a, dt=1e-3)
        return est, np.sqrt(np.mean((est.load[est.usable] - ramp[est.usable]) ** 2))

    est, err = error(s)
    assert est.knot_samples == 100
    knots = np.concatenate(est.corners)
    for corner in (3500, 3800):
        assert np.min(np.abs(knots - corner)) <= 15, (corner, knots)
    assert err < 20.0, err  # N (noise 30 N)
    assert error(replace(s, corner_coarse_factor=1.0))[1] > 100.0  # the ±0.05 s filter alone: ~230 N
    # the grid's floor of before (250 N) refuses it; the corner fit's own ratio (corners_pay) does not
    assert error(replace(s, ramp_min_n=250.0, corner_ratio=np.inf))[0].knot_samples == 0
    assert error(replace(s, ramp_min_n=250.0))[1] < 20.0


def test_load_follows_one_small_ramp_at_the_start_of_a_move():
    """A rolling force that moves 400 N over 0.5 s from the start of a move and is constant
    otherwise (reference plant seed 1, window 0, with commissioning, had a 260 N one there): one
    constant per segment leaves only 1.7x the residual of the 0.1 s grid, under ``ramp_ratio``, so
    the grid kept the constant, ~150 N off over the move (on that plant the replay was 0.5 mm off
    over the ramp's 0.5 s piece). The load on the ramp's corners leaves more than ``corner_ratio``
    less than the constant (:func:`corners_pay`) and is kept: ~7 N off."""
    from transforms.discrepancy.load import _grid_knots, _ramp_fit

    s, _, v, a, ramp, f = _rolling_force(lambda t: 1500.0 + np.interp(t, [3.0, 3.5], [0.0, 400.0]))  # from the start of the run
    est = estimate_load(f, v, s, accel=a, dt=1e-3)
    u = est.usable
    n_seg = len(est.steps) + 1
    const = _ramp_fit(f, u, est.segment, [np.zeros(0)] * n_seg, (v, a))[0]  # one constant per segment, with the motion columns
    grid = _ramp_fit(f, est.valid, est.segment, _grid_knots(est.valid, est.segment, n_seg, 100), (v, a))[1]  # knots every 0.1 s
    assert _ramp_fit(f, est.valid, est.segment, [np.zeros(0)] * n_seg, (v, a))[1] < s.ramp_ratio * grid  # the grid alone keeps the constant
    assert np.sqrt(np.mean((const[u] - ramp[u]) ** 2)) > 120.0  # N
    assert np.sqrt(np.mean((est.load[u] - ramp[u]) ** 2)) < 12.0, est.corners  # N (noise 30 N)


def test_a_ramp_under_both_corner_filters_gets_its_knots_one_at_a_time():
    """A rolling force that ramps 3 kN over 0.15 s, then 200 N over 0.4 s late in the cylinder's
    run: the filters find the steep ramp's corners, not the gentle one's (its slope change,
    500 N/s, is under both thresholds), and the velocity column takes what the load misses, 3,584
    N·s/m for the record's 3,000 (what the mechanical replay takes as friction). The knots that
    :func:`transforms.discrepancy.load.missed_knot` adds, one at a time where the joint fit's
    residual holds most, give the friction and the mass back within 1 % and the force the replay
    takes (load, friction and mass) within ~3 N; the knots the regression eliminates the load on
    stay the filters'."""
    from transforms.discrepancy.load import motion_mismatch

    s, _, v, a, ramp, f = _rolling_force(lambda t: np.interp(t, [3.2, 3.35, 4.4, 4.8], [1500.0, -1500.0, -1500.0, -1300.0]))

    def estimate(settings):
        est = estimate_load(f, v, settings, accel=a, dt=1e-3)
        u = est.usable
        dv, dm = motion_mismatch(f, est.load, u, (v, a))
        force = est.load + dv * v + dm * a - (ramp + 600.0 * a + 3000.0 * v)
        return est, dv, dm, np.sqrt(np.mean(force[u] ** 2))

    est, dv, dm, err = estimate(s)
    off, dv_off, _, err_off = estimate(replace(s, knot_rss_share=np.inf))  # the filters alone
    assert dv == pytest.approx(3000.0, rel=0.01) and dm == pytest.approx(600.0, rel=0.01), (dv, dm)
    assert err < 6.0, err  # N (noise 30 N)
    assert dv_off > 3400.0 and err_off > 15.0, (dv_off, err_off)
    assert len(est.corners) == len(off.corners) and all(np.array_equal(x, y) for x, y in zip(est.corners, off.corners))


def test_the_block_reduced_ramp_fit_is_the_least_squares_of_the_whole_rows():
    """load._ramp_fit reduces each block of rows by a QR before its least squares (an orthogonal
    transform): the same solution as the dense least squares of the hat-function design with its
    smoothing rows, to rounding (3 segments, one a constant, a gap the smoothing bridges, the
    motion columns; blocks that straddle segments)."""
    from transforms.discrepancy.load import RAMP_FIT_BLOCK, SMOOTHING, _grid_knots, _ramp_fit, hat_basis

    rng = np.random.default_rng(7)
    n = 9 * RAMP_FIT_BLOCK + 17
    t = np.arange(n)
    segment = (t >= 700).astype(np.int64) + (t >= 1700)
    valid = (rng.random(n) > 0.1) & ~((t >= 1000) & (t < 1400))
    v, a = np.sin(t / 300.0), np.cos(t / 170.0)
    f = 40.0 * np.cumsum(rng.normal(size=n)) / np.sqrt(n) * 30 + 800.0 * v - 300.0 * a + rng.normal(size=n) * 50.0
    knots = _grid_knots(valid, segment, 3, 100)
    knots[2] = np.zeros(0)
    load, rms, cm = _ramp_fit(f, valid, segment, knots, (v, a))
    idx = np.flatnonzero(valid)
    cols = [hat_basis(kn if kn.size else np.zeros(1), idx) * (segment[idx] == s)[:, None] for s, kn in enumerate(knots)]
    X = np.hstack(cols + [np.column_stack([v, a])[idx]])
    D = np.zeros((0, X.shape[1]))
    o = 0
    for kn in knots:
        for i in range(max(kn.size - 2, 0)):
            row = np.zeros(X.shape[1])
            row[o + i:o + i + 3] = (1.0, -2.0, 1.0)
            D = np.vstack([D, SMOOTHING * row])
        o += max(kn.size, 1)
    c = np.linalg.lstsq(np.vstack([X, D]), np.r_[f[idx], np.zeros(D.shape[0])], rcond=None)[0]
    k = X.shape[1] - 2
    dense = np.concatenate([hat_basis(kn, np.flatnonzero(segment == s)) @ c[sum(max(q.size, 1) for q in knots[:s]):][:kn.size] if kn.size > 1
                            else np.full(np.sum(segment == s), c[k - 1]) for s, kn in enumerate(knots)])
    np.testing.assert_allclose(load, dense, rtol=0, atol=1e-9 * np.max(np.abs(dense)))
    np.testing.assert_allclose(cm, c[k:], rtol=1e-9)
    assert rms == pytest.approx(np.sqrt(np.mean((f[idx] - X @ c) ** 2)), rel=1e-12)
    assert np.ptp(load[:700]) > 100.0  # the grid follows the drift: not a constant fit


def test_a_replay_holds_a_ramp_at_its_mean_over_the_interval_and_a_step_from_its_sample():
    # model.replay holds F_l between samples: a ramp within a segment is held at the mean of the
    # interval's ends (the ramp's own mean over it), a step between segments from the sample it
    # starts at (the level before it over the interval before), the last sample as it is
    seg = np.repeat([0, 1], [5, 3])
    load = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 7.0, 7.0, 7.0])
    est = LoadEstimate(seg, np.array([5]), np.array([20.0, 7.0]), load, np.full((1, 2), -1), np.ones(8, bool), np.ones(8, bool), knot_samples=2)
    np.testing.assert_array_equal(interval_load(est), [5.0, 15.0, 25.0, 35.0, 40.0, 7.0, 7.0, 7.0])
    # one constant per segment: as held before
    flat = replace(est, load=np.repeat([20.0, 7.0], [5, 3]), knot_samples=0)
    np.testing.assert_array_equal(interval_load(flat), flat.load)


def test_a_friction_mismatch_beyond_the_replays_limit_goes_into_the_load_where_the_load_can_follow_it():
    # a long slow move whose speed is nearly linear between the load's knots: the velocity column
    # and the load's slopes trade; the excess over the limit goes into the load along the part of
    # v_X its basis follows, so the force the replay takes (load + limited friction times v_X) moves
    # only by the excess times what the basis cannot follow
    n = 3000
    t = np.arange(n, dtype=float)
    knots = np.array([0.0, 1000.0, 2000.0, 2999.0])
    v = 0.05 + 0.1 * np.interp(t, knots, [0.0, 1.0, 0.6, 0.2]) + 0.004 * np.sin(2 * np.pi * t / 700)
    load = np.interp(t, knots, [-5000.0, -4000.0, -4500.0, 800.0])
    seg = np.zeros(n, dtype=int)
    est = LoadEstimate(seg, np.zeros(0, int), np.array([-4000.0]), load, np.zeros((0, 2), int), np.ones(n, bool), np.ones(n, bool),
                       knot_samples=100, corners=(knots,), friction_mismatch=-2620.0)
    out = friction_within(est, v, 1000.0, 3000.0)
    assert out.friction_mismatch == -1000.0
    along = (out.load - load) / -1620.0
    np.testing.assert_allclose(along, np.interp(t, knots, np.linalg.lstsq(
        np.column_stack([np.interp(t, knots, np.eye(4)[i]) for i in range(4)]), v, rcond=None)[0]), atol=1e-12)
    moved = (out.load + out.friction_mismatch * v) - (load + est.friction_mismatch * v)
    np.testing.assert_allclose(moved, 1620.0 * (v - along), atol=1e-9)
    assert np.sqrt(np.mean((v - along) ** 2)) < 0.003  # m/s: the sine the knots cannot follow, of v_X's ~0.1
    # a friction change (20 % of d_v = 100 kN s/m) gives the load at most load_limit: most of it
    # stays in the force balance, where the replay shows it
    change = friction_within(replace(est, friction_mismatch=-20000.0), v, 1000.0, 3000.0)
    assert change.friction_mismatch == -17000.0
    np.testing.assert_allclose(change.load, load - 3000.0 * along, atol=1e-9)
    # within the limit, or one constant per segment: as it is
    np.testing.assert_array_equal(friction_within(replace(est, friction_mismatch=-900.0), v, 1000.0, 3000.0).load, load)
    flat = replace(est, knot_samples=0, corners=())
    np.testing.assert_array_equal(friction_within(flat, v, 1000.0, 3000.0).load, load)
    assert friction_within(flat, v, 1000.0, 3000.0).friction_mismatch == -2620.0


def test_the_friction_and_mass_mismatch_are_what_the_load_leaves_along_velocity_and_acceleration():
    """The force balance of a model whose viscous friction is 3 kN·s/m short and mass 600 kg
    short, with a ramping load: what the estimated load leaves along v_X and the acceleration is
    the 3 kN·s/m and the 600 kg, as with the true load; the mechanical replay's friction and mass
    are moved by them (``rows._mechanical_model``, up to ``mechanical_friction_rel`` and
    ``mechanical_mass_rel``)."""
    s, _, v, a, ramp, f = _rolling_force(lambda t: np.interp(t, [3.5, 3.8], [1500.0, 2200.0]))
    est = estimate_load(f, v, s, accel=a, dt=1e-3)
    for load, rel in ((est.load, 0.03), (ramp, 0.01)):
        dv, dm = motion_mismatch(f, load, est.usable, (v, a))
        assert dv == pytest.approx(3000.0, rel=rel)
        assert dm == pytest.approx(600.0, rel=rel)
    assert motion_mismatch(f, ramp, np.zeros(f.size, dtype=bool), (v, a)) == (0.0, 0.0)  # nothing at speed


@given(st.floats(-1000.0, 1000.0), st.floats(-1000.0, 1000.0), st.floats(1.0, 500.0))
def test_the_replay_takes_a_small_mass_mismatch_whole_and_a_large_one_not_at_all(x, y, limit):
    """``rows.tapered``: within ±limit as it is; never more than the limit nor against its sign;
    nothing beyond twice the limit (a mass change stays whole in the gap); continuous (a change of
    the mismatch never moves the replayed mass by more)."""
    t = tapered(x, limit)
    if abs(x) <= limit:
        assert t == x
    assert abs(t) <= min(abs(x), limit) and t * x >= 0.0
    if abs(x) >= 2.0 * limit:
        assert t == 0.0
    assert abs(tapered(y, limit) - t) <= abs(y - x) + 1e-9


def test_demean_by_group():
    v = np.array([1.0, 3.0, 10.0, 14.0, 5.0])
    g = np.array([0, 0, 1, 1, 2])
    np.testing.assert_allclose(demean_by_group(v, g), [-1, 1, -2, 2, 0])
    M = np.column_stack([v, 2 * v])
    np.testing.assert_allclose(demean_by_group(M, g)[:, 1], 2 * demean_by_group(v, g))


def _synthetic(theta, n_blocks=30, n=200, seed=0, noise=1.0):
    rng = np.random.default_rng(seed)
    Phi = rng.normal(size=(n_blocks * n, 4))
    Phi[:, 3] = Phi[:, 2] + 0.3 * rng.normal(size=n_blocks * n)  # a correlated decoy
    y = Phi @ np.asarray(theta, float) + noise * rng.normal(size=n_blocks * n)
    return block_stats(y, Phi, np.repeat(np.arange(n_blocks), n))


def test_forward_select_names_the_true_column_and_nothing_on_noise():
    kw = dict(max_effects=3, min_t_stat=4.0, min_relative_gain=0.02, min_z=5.0)
    sel = forward_select(_synthetic([0, 0, 0.5, 0]), [0, 1, 2, 3], **kw)
    assert [c.column for c in sel.named] == [2]
    assert sel.final_theta[0] == pytest.approx(0.5, abs=0.05)
    lo, hi = sel.named[0].interval(sel.n_blocks, 0.95)
    assert lo < 0.5 < hi
    sel = forward_select(_synthetic([0.4, 0, 0, 0.6], seed=1), [0, 1, 2, 3], **kw)
    assert [c.column for c in sel.named] == [3, 0]
    for seed in range(5):
        assert forward_select(_synthetic([0, 0, 0, 0], seed=seed), [0, 1, 2, 3], **kw).named == []
    # a physical sign constraint: a negative coefficient is not named
    sel = forward_select(_synthetic([0, -0.5, 0, 0], seed=2), [0, 1, 2, 3], positive=frozenset({1}), **kw)
    assert sel.named == [] and sel.first_step[1].theta < 0


def test_gap_accumulator_and_normalised_gap():
    acc = GapAccumulator()
    regions = {"all": np.array([True, True, True, False]), "standstill": np.array([True, False, False, False])}
    acc.add("p1", np.array([1e5, -1e5, 1e5, np.nan]), regions)
    acc.add("p2", np.array([0.0, 0.0, 0.0, 0.0]), regions)
    acc.add("X", np.array([1e-3, 1e-3, -1e-3, 1e-3]), regions)
    assert acc.rms("p1") == pytest.approx(1e5)
    assert acc.rms("X", "standstill") == pytest.approx(1e-3)
    assert acc.gap() == pytest.approx(np.sqrt(2 / 3))
    assert normalised_gap({"p1": 0.0, "p2": 0.0, "X": 3e-3}) == pytest.approx(np.sqrt(3.0))
    assert {(r["signal"], r["region"]) for r in acc.rows()} == {(s, r) for s in ("p1", "p2", "X") for r in regions}


@pytest.mark.parametrize("seed", [0, 1])
def test_the_mechanical_noise_floor_is_what_the_noise_leaves_through_the_replay(seed):
    """On the exact model with its true load, the mechanical replay's gap is the recorded noise's:
    the floor (fresh noise of the estimated RMS replayed again) is within 1.5x of it, ten times
    the X channel's 1 um (the pressures' 0.05 bar integrated twice), and the same window recorded
    without noise replays within a tenth of it."""
    from dataclasses import replace

    from transforms.discrepancy.rows import _gaps, noise_floors, prepare_records

    s, cond, fx = DiscrepancySettings(), TABLE1.nominal_condition, Effects()
    key = (TABLE1, cond, fx)
    res = simulate_windows(TABLE1, [cond], 10.0, seed=seed)
    m = measure(res, TABLE1.sensors, np.random.default_rng([seed, 99]))
    names = ("ps", "pr", "p1", "p2", "x", "X")
    recorded = Record("V", 0, 0, 1e-3, {k: np.asarray(v[0], float) for k, v in zip(names, (m.ps, m.pr, m.p1, m.p2, m.x_spool, m.x_cyl))})
    noise_free = Record("V", 0, 0, 1e-3, {k: np.asarray(v[0], float) for k, v in zip(names, (res.ps_pa, res.pr_pa, res.p1_pa, res.p2_pa, res.x_m, res.X_m))})
    p = prepare_records([recorded], TABLE1, cond, s)[0]
    # the true load, and so the model's own friction and mass (nothing left along v_X or the acceleration: rows._mechanical_model);
    # its segments its own steps, which the replay takes at their samples (load.interval_load)
    true_load = np.asarray(res.F_l_n[0], float)
    segment = np.concatenate([[0], np.cumsum(np.diff(true_load) != 0)])
    p.loads[key] = replace(p.base_load, load=true_load, segment=segment, hold_until=0, friction_mismatch=0.0, mass_mismatch=0.0)
    floor = noise_floors([p], TABLE1, cond, fx, s)["mechanical"]
    gaps = {kind: _gaps([q], TABLE1, cond, fx, s, set())[0].split_gap("mechanical")
            for kind, q in (("recorded", p), ("noise-free", replace(p, rec=prepare_record(noise_free, s))))}
    x_noise = TABLE1.sensors.x_cyl.noise_std / 1e-3
    assert floor > 8.0 * x_noise, floor  # ~12 um against 1 um
    assert floor / 1.5 < gaps["recorded"] < 1.5 * floor, (gaps, floor)  # seeds 0-7: 0.74-1.15x
    assert gaps["noise-free"] < 0.1 * floor, (gaps, floor)  # integration alone: 0.1-0.5 um


@pytest.mark.parametrize("seed", [0, 1])
def test_the_hydraulic_replay_is_driven_by_the_smoothed_position(seed):
    """The hydraulic replay moves the cylinder at the slope of its position between samples. Driven
    by the recorded X, the channel's 1 um of noise is ~1.4 mm/s of velocity noise, and fresh noise
    of that size moved the replayed pressures by 0.028-0.033 bar RMS (seeds 0-3), two thirds of the
    pressure noise the gap is judged against; the exact model's hydraulic gap was 1.23-1.28x its
    floor. Driven by the Savitzky-Golay position: 0.009-0.010 bar and 1.08-1.13x."""
    from transforms.discrepancy.rows import _hydraulic_replay, _replay_starts, hydraulic_gap, noise_floors, prepare_records

    s, cond, fx = DiscrepancySettings(), TABLE1.nominal_condition, Effects()
    res = simulate_windows(TABLE1, [cond], 10.0, seed=seed)
    m = measure(res, TABLE1.sensors, np.random.default_rng([seed, 99]))
    names = ("ps", "pr", "p1", "p2", "x", "X")
    raw = {k: np.asarray(v[0], float) for k, v in zip(names, (m.ps, m.pr, m.p1, m.p2, m.x_spool, m.x_cyl))}
    noisier = dict(raw, X=raw["X"] + np.random.default_rng([seed, 5]).normal(0.0, TABLE1.sensors.x_cyl.noise_std, raw["X"].size))
    p, q = (prepare_records([Record("V", 0, 0, 1e-3, r)], TABLE1, cond, s)[0] for r in (raw, noisier))
    floor = noise_floors([p], TABLE1, cond, fx, s)["hydraulic"]
    assert hydraulic_gap([p], TABLE1, cond, fx, s) < 1.18 * floor  # the recorded X: 1.23-1.28x
    h = s.savgol_window // 2
    moved = np.concatenate([(a - b)[h:-h] for a, b in zip(*(_hydraulic_replay(r, TABLE1, cond, fx, _replay_starts(r, fx, s), 0.0) for r in (q, p)))])
    moved_rms = float(np.sqrt(np.nanmean(moved ** 2)))
    assert moved_rms < 0.4 * floor * 1e5, (moved_rms, floor)  # the recorded X: 0.55-0.66x the floor


@pytest.mark.parametrize("reconstruct", [False, True])
def test_the_hydraulic_floor_holds_what_plant_grade_positions_leave(reconstruct):
    """The exact model recorded as plants record positions (spool 7 um, cylinder 10 um in 5 um
    steps; pressures 0.05 bar): the hydraulic gap lies within 1.5x its floor, which holds what
    every channel's noise leaves through the replay (gap 0.166, floor 0.217); the pressures' own
    noise would be a floor of 0.05 bar, a third of the gap. Reconstructed positions leave less
    of it (gap 0.112, floor 0.128)."""
    from dataclasses import replace

    from transforms.discrepancy.rows import hydraulic_gap, noise_floors, prepare_records

    s, cond, fx = DiscrepancySettings(reconstruct_spool=reconstruct, reconstruct_cylinder=reconstruct), TABLE1.nominal_condition, Effects()
    sensors = replace(TABLE1.sensors, x_spool=replace(TABLE1.sensors.x_spool, noise_std=7e-6),
                      x_cyl=replace(TABLE1.sensors.x_cyl, noise_std=10e-6, step=5e-6))
    res = simulate_windows(TABLE1, [cond], 10.0, seed=3)
    m = measure(res, sensors, np.random.default_rng([3, 99]))
    names = ("ps", "pr", "p1", "p2", "x", "X", "x_ref")
    raw = {k: np.asarray(v[0], float) for k, v in zip(names, (m.ps, m.pr, m.p1, m.p2, m.x_spool, m.x_cyl, m.x_ref))}
    p = prepare_records([Record("V", 0, 0, 1e-3, raw)], TABLE1, cond, s)
    floor, gap = noise_floors(p, TABLE1, cond, fx, s)["hydraulic"], hydraulic_gap(p, TABLE1, cond, fx, s)
    assert floor > (0.1 if not reconstruct else 0.07), floor
    assert floor / 1.5 < gap < 1.5 * floor, (gap, floor)


def test_the_mechanical_replay_is_not_judged_through_a_load_step():
    """The robustness study's ``model/`` plant of seed 4, window 1: near the end of a move the load
    steps 11.2 -> 8.1 -> 0 kN, 36 ms apart, which the estimate reads as one step (its step filter
    keeps peaks ``step_half_width`` apart). Within ``step_guard_samples`` of a step the estimate's
    levels hold no sample: the mechanical replay restarts at the guard's end and is not judged
    within it. While it replayed through, the 3.1 kN for 36 ms put X 1 mm off for the rest of its
    0.5 s piece, and the true model's mechanical gap was 21x its noise floor (0.23 mm; now 1.4x)."""
    from tests.discrepancy.simdata import perturbed_plant, study_conditions
    from transforms.discrepancy.rows import _gaps, _mechanical_restarts, noise_floors, prepare_records

    s, fx = DiscrepancySettings(), Effects()
    plant = study_conditions(perturbed_plant(4, clip=2.0, stream=17017)[0])
    cond = plant.nominal_condition
    recs = split_records(simulate_lake(None, n_windows=2, seed=104, params=plant), s)[1:]
    p = prepare_records(recs, plant, cond, s)
    est = p[0].base_load
    assert np.any((est.steps > 9640) & (est.steps < 9700)), est.steps
    judged, starts = _mechanical_restarts(p[0].rec, s, est)
    g = s.step_guard_samples
    for k in est.steps:
        assert not judged[max(0, k - g):k + g].any()
        assert k + g in starts or k + g >= p[0].rec.n - s.savgol_window // 2 - 1
    gap = _gaps(p, plant, cond, fx, s, set())[0].split_gap("mechanical")
    floor = noise_floors(p, plant, cond, fx, s)["mechanical"]
    assert gap < 3.0 * floor, (gap, floor)


def test_operating_regions_partition_motion():
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 5.0, seed=0)
    m = measure(res, TABLE1.sensors, np.random.default_rng(0))
    rec = prepare_record(Record("V", 0, 0, 1e-3, {"ps": m.ps[0], "pr": m.pr[0], "p1": m.p1[0], "p2": m.p2[0], "x": m.x_spool[0], "X": m.x_cyl[0]}), DiscrepancySettings())
    reg = td.operating_regions(rec.sg["v"], rec.sg["p1"], rec.sg["p2"], rec.sg["ps"], DiscrepancySettings())
    motion = reg["extending"].astype(int) + reg["retracting"] + reg["standstill"]
    assert np.array_equal(motion, reg["all"].astype(int))
    level = reg["pressure_low"].astype(int) + reg["pressure_mid"] + reg["pressure_high"]
    assert np.array_equal(level, reg["all"].astype(int))
    assert reg["extending"].any() and reg["retracting"].any() and reg["standstill"].any()


def test_each_pressure_channel_is_aligned_for_its_own_delay_and_a_lagging_one_is_reported():
    """p1 recorded 3 samples late, p2, ps and pr 1 sample late (exact model, Table 1): the delays
    are found per channel, the supply and return take the shared one, the records aligned for
    them show none left, and p1's extra 2 samples are the finding (which channel, how many ms)."""
    from transforms.discrepancy.alignment import align_records, pressure_delays, shifted
    from transforms.discrepancy.rows import prepare_records

    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 4.0, seed=3)
    m = measure(res, TABLE1.sensors, np.random.default_rng(3))
    late = {"ps": 1, "pr": 1, "p1": 3, "p2": 1}
    raw = {c: np.concatenate([np.full(k, getattr(m, c)[0][0]), getattr(m, c)[0][:-k]]) for c, k in late.items()}
    rec = Record("V", 0, 3_999_000, 1e-3, {**raw, "x": m.x_spool[0], "X": m.x_cyl[0]})
    s, cond = DiscrepancySettings(), TABLE1.nominal_condition
    # shifting by per-channel delays takes each channel its own number of samples later
    sh = shifted(rec, late)
    assert sh.n == rec.n - 3 and sh.end_us == rec.end_us - 3000
    assert np.array_equal(sh.raw["p1"], rec.raw["p1"][3:]) and np.array_equal(sh.raw["p2"], rec.raw["p2"][1:-2])
    assert np.array_equal(sh.raw["X"], rec.raw["X"][:-3])
    d = pressure_delays(prepare_records([rec], TABLE1, cond, s), TABLE1, cond, s)
    assert d.samples == {"p1": 3, "p2": 1} and d.shared == 1 and d.of("ps") == d.of("pr") == 1
    assert d.lagging == ["p1"] and abs(d.fine["p1"] - d.fine["p2"] - 2.0) < 0.3
    assert "the p1 transmitter lags the other pressures by 2" in d.finding()
    aligned, d1 = align_records([rec], TABLE1, cond, s)
    assert d1.samples == d.samples and aligned[0].n == rec.n - 3
    again = pressure_delays(prepare_records(aligned, TABLE1, cond, s), TABLE1, cond, s)
    assert again.samples == {"p1": 0, "p2": 0} and again.finding() == ""


@pytest.mark.parametrize("others_s", [0.0, 1e-3])
def test_a_first_order_lag_on_one_transmitter_is_taken_out_as_a_lag_not_as_whole_samples(others_s):
    """p1's transmitter 2 ms slower than the others' (first-order lags, Tustin: their delay at low
    frequency is exactly τ; the others' 0 or 1 ms), every pressure one sample late (exact model,
    Table 1): p1 prefers whole samples more than p2, but its lag taken out on p2's shift fits
    better than any; τ reads 2 ms and the others' lag (from the second-order term) theirs; the
    records aligned so show neither lag nor delay left, and the finding names the lag."""
    from scipy.signal import lfilter

    from transforms.discrepancy.alignment import align_records, pressure_delays
    from transforms.discrepancy.rows import prepare_records

    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 4.0, seed=3)
    m = measure(res, TABLE1.sensors, np.random.default_rng(3))
    dt, extra = 1e-3, 2e-3

    def lag(u, tau):
        if tau == 0.0:
            return u
        k = dt / (2.0 * tau + dt)
        return lfilter([k, k], [1.0, (dt - 2.0 * tau) / (dt + 2.0 * tau)], u - u[0]) + u[0]

    lagged = {c: lag(getattr(m, c)[0], others_s + (extra if c == "p1" else 0.0)) for c in ("ps", "pr", "p1", "p2")}
    raw = {c: np.r_[v[0], v[:-1]] for c, v in lagged.items()}
    rec = Record("V", 0, 3_999_000, dt, {**raw, "x": m.x_spool[0], "X": m.x_cyl[0]})
    s, cond = DiscrepancySettings(), TABLE1.nominal_condition
    d = pressure_delays(prepare_records([rec], TABLE1, cond, s), TABLE1, cond, s)
    shared = 1 + int(round(others_s / dt))
    assert d.samples == {"p1": shared, "p2": shared} and d.lagging == ["p1"], (d.samples, d.lag_s)
    assert abs(d.lag_s["p1"] - extra) < 0.1 * extra, d.lag_s
    assert abs(-d.second_s2["p1"] / d.lag_s["p1"] - others_s) < 0.25e-3, d.second_s2
    assert d.lag_sse["p1"] < d.sse["p1"][int(np.argmin(d.sse["p1"]))]  # better than any whole samples
    assert f"a first-order lag of {d.lag_s['p1'] * 1e3:.2g} ms taken out" in d.finding(), d.finding()
    aligned, _ = align_records([rec], TABLE1, cond, s)
    h = s.savgol_window // 2
    assert aligned[0].n == rec.n - shared - 2 * h and aligned[0].start_us == h * 1000
    again = pressure_delays(prepare_records(aligned, TABLE1, cond, s), TABLE1, cond, s)
    assert again.samples == {"p1": 0, "p2": 0} and again.finding() == "", (again.samples, again.lag_s)


def test_tent_products_from_prefix_sums_are_those_of_the_tent_matrix():
    """load.missed_knot scores every candidate knot c between knots a and b by products with its
    tent (0 at a and b, 1 at c, zero outside the segment); _TentProducts makes them from one prefix
    and one suffix sum: the same as the dense tent matrix's products to rounding."""
    from transforms.discrepancy.load import _TentProducts

    rng = np.random.default_rng(3)
    sub = np.sort(rng.choice(np.arange(100, 900), 400, replace=False)).astype(float)
    inside = rng.random(sub.size) > 0.2
    a, b = 90.0, 905.0
    cands = sub[20:-20:7]
    T = np.where(sub[:, None] <= cands[None, :], (sub[:, None] - a) / (cands - a), (b - sub[:, None]) / (b - cands)) * inside[:, None]
    tent = _TentProducts(sub, inside, a, b, cands)
    y, Y = rng.normal(size=sub.size), rng.normal(size=(sub.size, 5))
    assert np.all(np.abs(tent.dot(y) - y @ T) <= 1e-12 * (np.abs(y) @ np.abs(T)))  # to rounding of the sums' size
    assert np.all(np.abs(tent.dot(Y) - (Y.T @ T).T) <= 1e-12 * (np.abs(Y.T) @ np.abs(T)).T)
    np.testing.assert_allclose(tent.dot_self(), np.einsum("ij,ij->j", T, T), rtol=1e-12)

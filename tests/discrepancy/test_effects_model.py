"""model.effects and model.replay: the library's switchable terms, their neutral defaults, and the
replay on recorded inputs."""

import importlib
import math
from pathlib import Path

import numpy as np
import pytest

from model import TABLE1, measure, rhs, simulate_windows
from model.effects import (
    EFFECT_LIBRARY,
    EFFECT_NAMES,
    P_ATM_PA,
    Effects,
    effective_bulk_modulus,
    equation_terms,
    library_entry,
    pressure_readings,
    sensor_readings,
    supply_valve_pressure_kernel,
    true_signals,
    valve_flows,
)
from model.replay import DRIVE_HYDRAULIC, DRIVE_MECHANICAL, replay
from schemas.fields import DISCREPANCY_EFFECTS

SPEC = Path(__file__).resolve().parents[3] / "shared" / "spec" / "interfaces.md"
STATE = np.array([1.2e-3, 0.01, 0.3, 0.1, 50e5, 150e5])
INPUTS = np.array([1.3e-3, 1000.0, 200e5, 0.5e5])


def test_effect_names_are_the_specified_ones():
    assert EFFECT_NAMES == DISCREPANCY_EFFECTS
    assert {s.name for s in EFFECT_LIBRARY} == set(EFFECT_NAMES)
    assert len({s.key for s in EFFECT_LIBRARY}) == len(EFFECT_LIBRARY) == 11
    if SPEC.exists():
        text = SPEC.read_text()
        for name in EFFECT_NAMES:
            assert f"`{name}`" in text


def test_neutral_effects_reproduce_the_base_model_bit_for_bit():
    conds = [TABLE1.nominal_condition, TABLE1.nominal_condition.with_edge("1r", underlap_m=4.5e-4, alpha=1.6)]
    a = simulate_windows(TABLE1, conds, 3.0, seed=5)
    b = simulate_windows(TABLE1, conds, 3.0, seed=5, effects=Effects())
    for name in ("x_m", "X_m", "vX_m_s", "p1_pa", "p2_pa", "dp1_dt_pa_s", "x_ref_m"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(rhs(0.0, STATE, INPUTS, TABLE1), rhs(0.0, STATE, INPUTS, TABLE1, effects=Effects()))
    assert a.effects is None and Effects().is_neutral


def test_chamber_terms_enter_the_rhs_as_documented():
    c, beta = TABLE1.cylinder, TABLE1.fluid.bulk_modulus_pa
    V1 = c.v01_m3 + c.A1 * STATE[2]
    V2 = c.v02_m3 - c.A2 * STATE[2]
    base = rhs(0.0, STATE, INPUTS, TABLE1)
    Ki, Ke = 3e-12, 2e-12
    d = rhs(0.0, STATE, INPUTS, TABLE1, effects=Effects(internal_leakage_m3_s_pa=Ki, external_leakage_m3_s_pa=Ke))
    qi = Ki * (STATE[4] - STATE[5])
    assert d[4] - base[4] == pytest.approx(-beta / V1 * qi, rel=1e-9)
    assert d[5] - base[5] == pytest.approx(beta / V2 * (qi - Ke * STATE[5]), rel=1e-9)
    eps = 0.01
    d = rhs(0.0, STATE, INPUTS, TABLE1, effects=Effects(air_fraction=eps))
    be1 = float(effective_bulk_modulus(STATE[4], beta, eps))
    assert d[4] == pytest.approx(base[4] * be1 / beta, rel=1e-9)
    # 1 % air: about 23 % softer at 30 bar, 2 % at 150 bar; no air: beta
    assert float(effective_bulk_modulus(30e5, beta, 0.01)) / beta == pytest.approx(0.77, abs=0.01)
    assert float(effective_bulk_modulus(150e5, beta, 0.01)) / beta == pytest.approx(0.98, abs=0.01)
    assert float(effective_bulk_modulus(30e5, beta, 0.0)) == beta
    # motion terms: mass and viscous friction
    d = rhs(0.0, STATE, INPUTS, TABLE1, effects=Effects(delta_viscous_friction_n_s_m=1e4))
    assert d[3] - base[3] == pytest.approx(-1e4 * STATE[3] / c.mass_kg, rel=1e-9)


def test_supply_line_pressure_solves_its_equation():
    k = math.sqrt(2 / 870.0)
    for R, p1, p2 in ((1e11, 50e5, 150e5), (5e11, 20e5, 190e5), (1e11, 210e5, 150e5)):
        pv = supply_valve_pressure_kernel(200e5, p1, p2, 0.675 * 3e-5, 0.675 * 1e-6, k, 1e4, R)
        q = k * (0.675 * 3e-5 * np.sign(pv - p1) * np.sqrt(abs(pv - p1)) + 0.675 * 1e-6 * np.sign(pv - p2) * np.sqrt(abs(pv - p2)))
        assert pv - 200e5 + R * q * abs(q) == pytest.approx(0.0, abs=1e-2)
    assert supply_valve_pressure_kernel(200e5, 50e5, 150e5, 1e-5, 1e-6, k, 1e4, 0.0) == 200e5


def test_sensor_maps_are_inverse_and_measure_applies_them():
    fx = Effects(spool_sensor_offset_m=5e-6, p1_sensor_offset_pa=1e5, p2_sensor_gain=0.98)
    x, p1, p2 = np.array([1e-3, -2e-3]), np.array([40e5, 60e5]), np.array([150e5, 120e5])
    back = true_signals(*sensor_readings(x, p1, p2, fx), fx)
    for a, b in zip(back, (x, p1, p2)):
        np.testing.assert_allclose(a, b, rtol=1e-12)
    np.testing.assert_array_equal(np.array(pressure_readings(p1, p2, fx)), np.array(sensor_readings(x, p1, p2, fx)[1:]))
    np.testing.assert_allclose(pressure_readings(p1, p2, fx)[0], p1 + 1e5, rtol=1e-15)
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 1.0, seed=2, effects=fx)
    sensors = TABLE1.sensors.__class__(
        **{f: (getattr(TABLE1.sensors, f).__class__(0.0, 0.0, -1e9, 1e9) if f != "sample_rate_hz" else 1000.0) for f in TABLE1.sensors.__dataclass_fields__}
    )
    m = measure(res, sensors, np.random.default_rng(0))
    np.testing.assert_allclose(m.x_spool, res.x_m + 5e-6, atol=1e-15)
    np.testing.assert_allclose(m.p1, res.p1_pa + 1e5, rtol=1e-12)
    np.testing.assert_allclose(m.p2, 0.98 * res.p2_pa, rtol=1e-12)


def test_spool_offset_moves_the_spool_in_closed_loop():
    """The valve's inner loop regulates the reading x + delta_x: the true spool rests delta_x
    lower, the reading where the base model's spool rests."""
    base = simulate_windows(TABLE1, [TABLE1.nominal_condition], 0.3, seed=1)
    off = simulate_windows(TABLE1, [TABLE1.nominal_condition], 0.3, seed=1, effects=Effects(spool_sensor_offset_m=1e-5))
    assert off.x_m[0, 0] == pytest.approx(base.x_m[0, 0], abs=1e-12)  # the same physical rest state
    assert off.x_ref_m[0, 0] == pytest.approx(base.x_ref_m[0, 0] + 1e-5, abs=1e-9)


def test_rest_state_with_leakage_is_a_rest_state():
    fx = Effects(internal_leakage_m3_s_pa=2e-12, supply_resistance_pa_s2_m6=1e11)
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 0.2, seed=3, effects=fx)
    # no start-up transient: the first samples stay within a few mbar and nanometres
    assert abs(res.p1_pa[0, 50] - res.p1_pa[0, 0]) < 5e3
    assert abs(res.dp1_dt_pa_s[0, 0]) < 1e4 and abs(res.dp2_dt_pa_s[0, 0]) < 1e4


def test_equation_terms_close_the_chamber_balance_on_exact_states():
    fx = Effects(internal_leakage_m3_s_pa=1e-12, external_leakage_m3_s_pa=1e-12, air_fraction=3e-3)
    res = simulate_windows(TABLE1, [TABLE1.nominal_condition], 2.0, seed=4, effects=fx)
    sig = {"x": res.x_m[0], "p1": res.p1_pa[0], "p2": res.p2_pa[0], "ps": res.ps_pa[0], "pr": res.pr_pa[0], "X": res.X_m[0], "v": res.vX_m_s[0]}
    t = equation_terms(sig, TABLE1, None, fx, reg_band_pa=1e4)
    c = TABLE1.cylinder
    r1 = t["q1"] - c.A1 * res.vX_m_s[0] - t["ql1"] - t["c1"] * res.dp1_dt_pa_s[0]
    r2 = c.A2 * res.vX_m_s[0] - t["q2"] - t["ql2"] - t["c2"] * res.dp2_dt_pa_s[0]
    scale = np.max(np.abs(t["q1"]))
    assert np.max(np.abs(r1)) < 1e-9 * scale and np.max(np.abs(r2)) < 1e-9 * scale


@pytest.mark.parametrize("key,value", [(None, 0.0), ("internal_leakage", 2e-12), ("entrained_air", 5e-3), ("supply_line_resistance", 1e11), ("spool_sensor_offset", 1e-5), ("load_mass_change", 900.0)])
def test_replay_on_true_inputs_reproduces_the_simulator(key, value):
    fx = None if key is None else library_entry(key).effects(value)
    r = simulate_windows(TABLE1, [TABLE1.nominal_condition], 10.0, seed=3, effects=fx)
    st = [[r.X_m[0, 0], r.vX_m_s[0, 0], r.p1_pa[0, 0], r.p2_pa[0, 0]]]
    rep = replay(TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0], r.F_l_n[0], [0], st, effects=fx)
    assert np.max(np.abs(rep.X_m - r.X_m[0])) < 1e-6  # 1 µm over 10 s, open loop
    assert np.max(np.abs(rep.p1_pa - r.p1_pa[0])) < 0.02e5
    assert np.max(np.abs(rep.p2_pa - r.p2_pa[0])) < 0.02e5


def test_replay_restarts_and_rejects_bad_arguments():
    r = simulate_windows(TABLE1, [TABLE1.nominal_condition], 2.0, seed=1)
    idx = [100, 1000]
    st = [[r.X_m[0, k], r.vX_m_s[0, k], r.p1_pa[0, k], r.p2_pa[0, k]] for k in idx]
    rep = replay(TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0], r.F_l_n[0], idx, st)
    assert np.all(np.isnan(rep.p1_pa[:100])) and rep.p1_pa[1000] == r.p1_pa[0, 1000]
    with pytest.raises(ValueError):
        replay(TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0], r.F_l_n[0], [1000, 100], st)
    with pytest.raises(ValueError):
        replay(TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0], r.F_l_n[0], [0], [st[0], st[1]])


def test_a_replay_continued_from_the_last_ones_state_is_that_replay_bit_for_bit(monkeypatch):
    """A replay that restarts at k on the exact state the last replay passed through at k, on the
    same inputs from k on, is copied from that replay (model.replay._LastReplay): the same numbers
    as integrating it, bit for bit. A load that differs after k, or a state one ulp off, is integrated."""
    mr = importlib.import_module("model.replay")  # the package's ``replay`` is the function
    r = simulate_windows(TABLE1, [TABLE1.nominal_condition], 2.0, seed=1)
    args = (TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0])
    first = replay(*args, r.F_l_n[0], [0], [[r.X_m[0, 0], r.vX_m_s[0, 0], r.p1_pa[0, 0], r.p2_pa[0, 0]]])
    k = 700
    at_k = np.array([first.X_m[k], first.vX_m_s[k], first.p1_pa[k], first.p2_pa[k]])
    load = r.F_l_n[0].copy()
    load[:k] += 500.0  # before k: not an input of a replay from k
    calls = []
    kernel = mr._replay_kernel
    monkeypatch.setattr(mr, "_replay_kernel", lambda *a: calls.append(a[4][0]) or kernel(*a))
    copied = replay(*args, load, [k], [at_k])
    assert calls == []
    monkeypatch.setattr(mr, "_LAST", mr._LastReplay())  # nothing to continue from
    fresh = replay(*args, load, [k], [at_k])
    assert calls == [k]
    for a, b in zip((copied.X_m, copied.vX_m_s, copied.p1_pa, copied.p2_pa), (fresh.X_m, fresh.vX_m_s, fresh.p1_pa, fresh.p2_pa)):
        assert np.all(np.isnan(a[:k])) and np.all(np.isnan(b[:k])) and a[k:].tobytes() == b[k:].tobytes()
    assert np.max(np.abs(copied.X_m[k:] - first.X_m[k:])) == 0.0
    later = load.copy()
    later[k + 10] += 1.0
    off = at_k.copy()
    off[2] = np.nextafter(off[2], np.inf)
    replay(*args, later, [k], [at_k])
    replay(*args, load, [k], [off])
    assert calls == [k, k, k]


def test_valve_flows_with_supply_line_use_the_valve_pressure():
    x = np.array([2e-3, 2.5e-3])
    p1, p2, ps, pr = np.array([60e5, 70e5]), np.array([120e5, 110e5]), 200e5, 0.5e5
    q1, q2, psv = valve_flows(x, p1, p2, ps, pr, TABLE1, None, Effects(supply_resistance_pa_s2_m6=1e11))
    q1b, q2b, psvb = valve_flows(x, p1, p2, psv, pr, TABLE1, None, None)
    np.testing.assert_allclose(q1, q1b, rtol=1e-12)
    assert np.all(psv < ps) and np.all(psvb == psv)
    assert P_ATM_PA == pytest.approx(1.013e5)


@pytest.mark.parametrize("key,value", [(None, 0.0), ("entrained_air", 5e-3)])
def test_split_replays_on_true_signals_reproduce_the_simulator(key, value):
    """The hydraulic replay (p1, p2 on the true cylinder motion: no load, mass or friction given)
    and the mechanical one (X on the true pressures: no flow model) reproduce the simulator."""
    fx = None if key is None else library_entry(key).effects(value)
    r = simulate_windows(TABLE1, [TABLE1.nominal_condition], 10.0, seed=3, effects=fx)
    st = [[r.X_m[0, 0], r.vX_m_s[0, 0], r.p1_pa[0, 0], r.p2_pa[0, 0]]]
    args = (TABLE1, r.x_m[0], r.ps_pa[0], r.pr_pa[0])
    hyd = replay(*args, np.zeros(r.n_samples), [0], st, effects=fx, drive=DRIVE_HYDRAULIC, given=r.X_m[0])
    np.testing.assert_array_equal(hyd.X_m, r.X_m[0])
    assert np.max(np.abs(hyd.p1_pa - r.p1_pa[0])) < 0.05e5 and np.max(np.abs(hyd.p2_pa - r.p2_pa[0])) < 0.05e5
    # the mechanical replay integrates the force twice, open loop: restart it every 0.5 s
    idx = np.arange(0, r.n_samples - 1, 500)
    sts = [[r.X_m[0, k], r.vX_m_s[0, k], r.p1_pa[0, k], r.p2_pa[0, k]] for k in idx]
    mech = replay(*args, r.F_l_n[0], idx, sts, effects=fx, drive=DRIVE_MECHANICAL, given=[r.p1_pa[0], r.p2_pa[0]])
    np.testing.assert_array_equal(mech.p1_pa, r.p1_pa[0])
    assert np.max(np.abs(mech.X_m - r.X_m[0])) < 5e-6
    # and a wrong mass shows in the mechanical replay only
    wrong = replay(*args, r.F_l_n[0], idx, sts, effects=library_entry("load_mass_change").effects(600.0), drive=DRIVE_MECHANICAL,
                   given=[r.p1_pa[0], r.p2_pa[0]])
    assert np.max(np.abs(wrong.X_m - r.X_m[0])) > 20e-6

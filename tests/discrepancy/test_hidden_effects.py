"""The workflow on data with a hidden effect: every library effect is switched on in the
simulator (in-process), the valve's windows are recorded through the sensor models and handed
to :func:`transforms.discrepancy.pipeline.diagnose`, which is not told what (if anything) is hidden.

* clear magnitudes (the library's typical ones; mass and air doubled so the replay gap stands
  well clear of the noise floor), two windows: the right effect is named first, its parameter is recovered
  within 2 % (and inside its interval or within 2 % of it), and adding it shrinks the normalised
  replay gap at least 3x;
* hard magnitudes (at most one grid step, 3.3x, above the detection limits of docs/discrepancy.md,
  which hold for four windows; here on two, other seeds than the sweep's): still named first,
  parameter within 20 %;
* a tenth of those limits (four windows): nothing wrong is named;
* no hidden effect: nothing is named.
"""

from dataclasses import replace

import numpy as np
import pytest

from model import TABLE1
from model.condition import manufactured
from model.effects import Effects, library_entry
from transforms.discrepancy import DiscrepancySettings, prepare_record, split_records
from transforms.discrepancy.pipeline import diagnose, fit_condition, monitoring_bias

from .simdata import simulate_lake

SETTINGS = DiscrepancySettings()

CLEAR = [
    ("internal_leakage", 2e-12),
    ("external_leakage", 2e-12),
    ("entrained_air", 1e-2),
    ("spool_sensor_offset", 1e-5),
    ("pressure_sensor_offset[p1]", 2e5),
    ("pressure_sensor_offset[p2]", -2e5),
    ("pressure_sensor_gain[p1]", 1.03),
    ("pressure_sensor_gain[p2]", 0.97),
    ("supply_line_resistance", 1e11),
    ("friction_change", 2e4),
    ("load_mass_change", 1200.0),
]

HARD = [
    ("internal_leakage", 6e-14),
    ("external_leakage", 2e-14),
    ("entrained_air", 5e-3),
    ("spool_sensor_offset", -1e-6),
    ("pressure_sensor_offset[p1]", 6e3),
    ("pressure_sensor_offset[p2]", -2e4),
    ("pressure_sensor_gain[p1]", 0.997),
    ("pressure_sensor_gain[p2]", 1.0003),
    ("supply_line_resistance", 1e10),
    ("friction_change", -200.0),
    ("load_mass_change", -600.0),
]


def _diagnose(effects, seed, n_windows=4, **kw):
    lake = simulate_lake(effects, n_windows=n_windows, seed=seed)
    return diagnose(split_records(lake, SETTINGS), TABLE1, settings=SETTINGS, monitoring=False, **kw)


@pytest.mark.parametrize("key,value", CLEAR, ids=[k for k, _ in CLEAR])
def test_clear_effect_is_named_recovered_and_shrinks_the_gap(key, value):
    spec = library_entry(key)
    d = _diagnose(spec.effects(value), seed=21, n_windows=2)  # error <= 0.13 %, gap shrunk >= 5.1x (four windows: the same, at twice the cost)
    assert d.named, f"nothing named; candidates {d.candidates[:3]}"
    first = d.named[0]
    assert first.spec.key == key
    mag = abs(value - spec.neutral)
    assert abs(first.value - value) <= 0.02 * mag
    assert first.ci_low - 0.02 * mag <= value <= first.ci_high + 0.02 * mag
    assert first.gap_after * 3.0 <= first.gap_before, (first.gap_before, first.gap_after)
    assert len(d.named) == 1  # nothing else named on top
    assert d.stage_effects[-1] == spec.effects(first.value)


@pytest.mark.parametrize("key,value", HARD, ids=[k for k, _ in HARD])
def test_small_effect_is_still_named_first(key, value):
    """The documented detection limit's claim on two windows instead of its four, at most one grid
    step above the limit."""
    spec = library_entry(key)
    assert abs(value - spec.neutral) <= 10.0 / 3.0 * LIMITS[key] * 1.0001
    d = _diagnose(spec.effects(value), seed=33, n_windows=2)  # error <= 1.6 % (four windows: <= 5.2 %, at twice the cost)
    assert d.named and d.named[0].spec.key == key, [(c["effect"], c["variant"], c["significant"]) for c in d.candidates[:3]]
    assert abs(d.named[0].value - value) <= 0.2 * abs(value - spec.neutral)


@pytest.mark.parametrize("seed", [40, 41])
def test_no_hidden_effect_names_nothing(seed):
    d = _diagnose(None, seed=seed)
    assert d.named == []
    assert d.stage_gaps[0] < 0.2  # the replay of an exact model sits near the noise floor
    assert all(not c["significant"] for c in d.candidates)


def test_gaps_and_residuals_are_reported_per_region_and_stage():
    d = _diagnose(Effects(external_leakage_m3_s_pa=1e-12), seed=5, n_windows=2)
    regions = {r["region"] for r in d.gap_rows}
    assert regions == {"all", "extending", "retracting", "standstill", "pressure_low", "pressure_mid", "pressure_high"}
    assert {r["stage"] for r in d.gap_rows} == {0, 1}
    eqs = {(r["stage"], r["equation"]) for r in d.residual_rows}
    assert eqs == {(s, e) for s in (0, 1) for e in ("chamber1", "chamber2", "motion")}
    # the leak shows in chamber 2's residual, and adding it removes it
    r = {(x["stage"], x["equation"], x["region"]): x for x in d.residual_rows}
    assert r[(1, "chamber2", "standstill")]["rms"] < 0.5 * r[(0, "chamber2", "standstill")]["rms"]
    assert len(d.traces) == 1 and set(d.traces[0].replayed) == {f"stage{k}_{s}" for k in (0, 1) for s in ("p1", "p2", "X")}


def test_monitoring_bias_is_removed_when_the_effect_is_accounted_for():
    """Step 4: a p1 transmitter offset biases the 1r edge's α̂ (its Eq. 7 pressure drop is
    p1 − p_r); with the fitted offset accounted for the estimates return to those of the same
    valve without the effect."""
    fx = Effects(p1_sensor_offset_pa=2e5)
    lake = simulate_lake(fx, n_windows=3, seed=8)
    recs = [prepare_record(r, SETTINGS) for r in split_records(lake, SETTINGS)]
    d = diagnose(recs, TABLE1, settings=SETTINGS, monitoring=True)
    assert d.named[0].spec.key == "pressure_sensor_offset[p1]"
    mon = {m["edge"]: m for m in d.monitoring}
    clean = {m["edge"]: m for m in monitoring_bias([prepare_record(r, SETTINGS) for r in split_records(simulate_lake(None, n_windows=3, seed=8), SETTINGS)], TABLE1, None, Effects())}
    assert abs(mon["1r"]["alpha_hat_recorded"] - clean["1r"]["alpha_hat_recorded"]) > 0.01  # biased by > 1 %
    for e in ("s1", "1r", "s2", "2r"):
        assert mon[e]["alpha_hat_corrected"] == pytest.approx(clean[e]["alpha_hat_recorded"], abs=2e-3)
        assert mon[e]["x_hat_m_corrected"] == pytest.approx(clean[e]["x_hat_m_recorded"], abs=2e-6)


def test_flow_effects_are_accounted_for_in_eq7():
    """Leakage is added to the chamber flow of each Eq. 7 point: internal leakage biases x̂ of
    s2 by tens of µm, accounted for it is gone."""
    fx = Effects(internal_leakage_m3_s_pa=2e-12)
    recs = [prepare_record(r, SETTINGS) for r in split_records(simulate_lake(fx, n_windows=3, seed=9), SETTINGS)]
    clean = [prepare_record(r, SETTINGS) for r in split_records(simulate_lake(None, n_windows=3, seed=9), SETTINGS)]
    biased = {m["edge"]: m for m in monitoring_bias(recs, TABLE1, None, fx)}
    ref = {m["edge"]: m for m in monitoring_bias(clean, TABLE1, None, Effects())}
    assert abs(biased["s2"]["x_hat_m_recorded"] - ref["s2"]["x_hat_m_recorded"]) > 20e-6
    for e in ("s1", "1r", "s2", "2r"):
        assert biased[e]["x_hat_m_corrected"] == pytest.approx(ref[e]["x_hat_m_recorded"], abs=5e-6)


def test_commissioning_condition_is_fitted_and_later_effects_found():
    """A valve with manufacturing scatter (α ± 3 %, underlap ± 5 µm per edge): against its design
    the model disagrees by bars; fitted on commissioning windows, the condition is recovered
    and a later hidden effect is named, not the scatter."""
    cond = manufactured(TABLE1.nominal_condition, 17)
    plant = replace(TABLE1, nominal_condition=cond)
    com = simulate_lake(None, n_windows=3, seed=50, params=plant)
    fit = fit_condition(split_records(com, SETTINGS), TABLE1, settings=SETTINGS)
    np.testing.assert_allclose(fit.condition.alpha, cond.alpha, rtol=2e-3)
    np.testing.assert_allclose(fit.condition.underlap_m, cond.underlap_m, atol=0.3e-6)
    assert fit.gap_design > 0.5 and fit.gap_fitted < 0.1
    later = simulate_lake(Effects(external_leakage_m3_s_pa=5e-13), n_windows=3, seed=51, params=plant)
    d = diagnose(split_records(later, SETTINGS), TABLE1, fit.condition, SETTINGS, monitoring=False)
    assert [n.spec.key for n in d.named] == ["external_leakage"]
    assert d.named[0].value == pytest.approx(5e-13, rel=0.05)


# docs/discrepancy.md, "Detection limits" (bench/discrepancy_limits.py --seeds 10 --windows 4)
LIMITS = {
    "internal_leakage": 2e-14,
    "external_leakage": 6e-15,
    "entrained_air": 1.5e-3,
    "spool_sensor_offset": 3e-7,
    "pressure_sensor_offset[p1]": 2e3,
    "pressure_sensor_offset[p2]": 6e3,
    "pressure_sensor_gain[p1]": 9e-4,
    "pressure_sensor_gain[p2]": 3e-4,
    "supply_line_resistance": 3e9,
    "friction_change": 200.0,
    "load_mass_change": 180.0,
}


def test_limits_table_matches_the_docs():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "discrepancy.md").read_text()
    section = doc.split("## Detection limits", 1)[1]
    for key in LIMITS:
        assert f"| {key} |" in section, key


@pytest.mark.slow
@pytest.mark.parametrize("key", list(LIMITS))
def test_a_tenth_of_the_documented_limit_names_nothing_wrong(key):
    """Four windows as the sweep, other seeds than its (70 and 71 in turn over the effects): at a
    tenth of the documented limit nothing wrong is named (nothing, or the effect itself). Above
    the limit, test_small_effect_is_still_named_first (two windows, within 3.3x of it)."""
    spec = library_entry(key)
    d = _diagnose(spec.effects(spec.neutral + 0.1 * LIMITS[key]), seed=70 + list(LIMITS).index(key) % 2)
    assert all(n.spec.key == key for n in d.named), [(n.spec.key, n.value) for n in d.named]

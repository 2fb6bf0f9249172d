"""The discrepancy workflow on plants that are not its own model (issue 17): the base model's
uncertain parameters are nuisances with priors, calibrated with the effects; verdicts are
``named`` / ``ambiguous`` / ``none``.

The true plant of these tests has every scatter nuisance (α and underlap per edge, β, V01, V02,
d_v, d_c, d_s, mass) off its nominal value by z ~ N(0, 1) prior σ (clipped to ±1.5σ), drawn from a
seed the robustness study (bench/discrepancy_robustness.py) does not use, and Eq. 3's edge shape or
one of issue 16's other valve families; the workflow is given the nominal design data only.
"""

from dataclasses import replace

import numpy as np
import pytest

from model import TABLE1
from model.effects import Effects, library_entry
from model.params import GEOMETRY_FAMILIES
from transforms.discrepancy import DiscrepancySettings, split_records
from transforms.discrepancy.calibration import calibrate
from transforms.discrepancy.nuisance import NUISANCES, SCATTER, NuisancePriors, apply_nuisances, nuisance_sigmas, nuisance_values
from transforms.discrepancy.pipeline import _project_out, diagnose

from .simdata import simulate_lake

SETTINGS = DiscrepancySettings()
PRIORS = NuisancePriors()
NOM = TABLE1.nominal_condition


def perturbed_plant(seed: int, clip: float = 1.5, family: str = "eq3"):
    rng = np.random.default_rng([seed, 4242])
    z = np.zeros(len(NUISANCES))
    z[:len(SCATTER)] = np.clip(rng.normal(size=len(SCATTER)), -clip, clip)
    plant, cond = apply_nuisances(TABLE1, NOM, nuisance_values(TABLE1, NOM) + nuisance_sigmas(TABLE1, NOM, PRIORS) * z)
    return replace(plant, nominal_condition=cond, geometry=GEOMETRY_FAMILIES[family]), z


PLANT, Z_TRUE = perturbed_plant(31)


def _records(effects, seed, n_windows=2, plant=PLANT):
    return split_records(simulate_lake(effects, n_windows=n_windows, seed=seed, params=plant), SETTINGS)


# --- fast -------------------------------------------------------------------------------------


def test_nuisance_values_round_trip_and_priors():
    v = nuisance_values(TABLE1, NOM)
    p, c = apply_nuisances(TABLE1, NOM, v)
    assert p == TABLE1 and c == NOM
    sig = nuisance_sigmas(TABLE1, NOM, PRIORS)
    assert sig[NUISANCES.index("underlap_s1")] == 5e-6
    assert sig[NUISANCES.index("bulk_modulus")] == pytest.approx(0.07 * 1.5e9)
    assert sig[NUISANCES.index("d_s")] == pytest.approx(0.3 * 6e3)
    assert NuisancePriors.exact().is_exact and not PRIORS.is_exact
    with pytest.raises(ValueError, match="friction_rel"):
        NuisancePriors(friction_rel=-0.1)
    # physical range kept: d_s >= d_c, volumes and mass positive
    w = v.copy()
    w[NUISANCES.index("d_s")] = 0.0
    w[NUISANCES.index("mass")] = -5.0
    p, _ = apply_nuisances(TABLE1, NOM, w)
    assert p.cylinder.d_s_n >= p.cylinder.d_c_n and p.cylinder.mass_kg > 0


def test_edge_shape_nuisances_span_the_valve_families():
    """Eq. 3 with the clearance nuisance at −2σ (R − r → 0) is the sharp-edged law, and the land
    leakage nuisance at +2σ is worn lands leaking 3× (model.params.GEOMETRY_FAMILIES); a valve
    configured sharp-edged has no edge-shape nuisance."""
    from model.area import valve_areas

    v, sig = nuisance_values(TABLE1, NOM), nuisance_sigmas(TABLE1, NOM, PRIORS)
    i_c, i_l = NUISANCES.index("clearance"), NUISANCES.index("land_leakage")
    x = np.linspace(-3e-3, 3e-3, 2001)
    near = np.abs(x) < 3e-4
    eq3 = np.asarray(valve_areas(x, TABLE1.geometry, NOM))

    def areas(i, dz):
        w = v.copy()
        w[i] += dz * sig[i]
        plant, cond = apply_nuisances(TABLE1, NOM, w)
        return np.asarray(valve_areas(x, plant.geometry, cond))

    sharp, worn3 = (np.asarray(valve_areas(x, GEOMETRY_FAMILIES[f], NOM)) for f in ("sharp", "worn3"))
    err = np.abs(areas(i_c, -2.0) - sharp)
    assert np.max(err) < 0.03 * np.max(sharp)  # π h² cos φ of Eq. 3's open branch, at full opening
    assert np.max(err[:, near]) < 0.1 * np.min(np.abs(eq3[:, near] - sharp[:, near]))  # the intercept is gone
    np.testing.assert_allclose(areas(i_l, 2.0), worn3, rtol=1e-12)
    sharp = replace(TABLE1, geometry=GEOMETRY_FAMILIES["sharp"])
    assert np.all(nuisance_sigmas(sharp, NOM, PRIORS)[[i_c, i_l]] == 0.0)
    assert np.all(sig[[i_c, i_l]] > 0.0)

def test_project_out_removes_what_the_nuisances_explain():
    rng = np.random.default_rng(0)
    N = rng.normal(size=(400, 3)) * 30.0  # strong data: the ridge hardly matters
    inside = N @ np.array([1.0, -2.0, 0.5])
    outside = rng.normal(size=400)
    a, b = _project_out(N, inside, outside)
    assert np.linalg.norm(a) < 1e-2 * np.linalg.norm(inside)
    assert np.linalg.norm(b) > 0.9 * np.linalg.norm(outside)


def test_calibration_recovers_the_perturbed_plant_and_closes_the_gap():
    recs = _records(None, seed=301)
    cal = calibrate(recs, TABLE1, NOM, PRIORS, SETTINGS)
    z = np.array([r["z"] for r in cal.table()])
    assert np.max(np.abs(z - Z_TRUE)) < 0.3, np.round(z - Z_TRUE, 2)  # the breakaway force from the replay included
    assert cal.gap_nominal > 1.0
    exact = diagnose(recs, PLANT, PLANT.nominal_condition, SETTINGS, monitoring=False).gap_before
    assert cal.gap_calibrated <= 2.0 * exact, (cal.gap_calibrated, exact)


# --- without a commissioning window (slow: one diagnosis per effect) ---------------------------

TYPICAL = [(s.key, s.neutral + (-s.typical if s.neutral == 1.0 else s.typical)) for s in
           __import__("model.effects", fromlist=["EFFECT_LIBRARY"]).EFFECT_LIBRARY if s.key != "friction_change"]
"""Every library effect at its typical magnitude except friction_change: its typical 20 kN·s/m is 20 % of
d_v, inside the 30 % datasheet tolerance, so without a reference it is not an effect but scatter
(docs/discrepancy.md, "Where the line lies"); it is tested at 100 kN·s/m below."""


@pytest.mark.slow
@pytest.mark.parametrize("key,value", TYPICAL + [("friction_change", 1.0e5)], ids=[k for k, _ in TYPICAL] + ["friction_change"])
def test_typical_effect_named_or_honestly_ambiguous_without_commissioning(key, value):
    spec = library_entry(key)
    d = diagnose(_records(spec.effects(value), seed=302), TABLE1, None, SETTINGS, monitoring=False, priors=PRIORS)
    v = d.verdict
    assert v.verdict in ("named", "ambiguous"), (v.verdict, v.reason)
    if v.verdict == "named":
        assert v.effect.key == key, (v.effect.key, v.reason)
    else:
        assert v.effect.key == key or key in v.alternative_keys, (v.effect.key, v.alternatives)
    if v.effect.key == key and spec.name not in ("load_mass_change", "friction_change", "spool_sensor_offset"):
        assert abs(v.value - value) <= 0.2 * abs(value - spec.neutral), (v.value, value)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [303, 304])
def test_clean_perturbed_valve_is_none(seed):
    d = diagnose(_records(None, seed=seed), TABLE1, None, SETTINGS, monitoring=False, priors=PRIORS)
    assert d.verdict.verdict == "none", d.verdict.reason
    assert d.gap_before < 0.5 * d.gap_nominal


@pytest.mark.slow
def test_spool_offset_is_never_another_effect():
    d = diagnose(_records(Effects(spool_sensor_offset_m=15e-6), seed=305), TABLE1, None, SETTINGS, monitoring=False, priors=PRIORS)
    v = d.verdict
    assert v.verdict in ("named", "ambiguous") and v.effect.key == "spool_sensor_offset", (v.verdict, v.reason)
    if v.verdict == "ambiguous":
        assert any("underlap" in a for a in v.alternatives), v.alternatives


# --- another valve family than the design data's (issue 16), without a commissioning window ----

SHARP_AS_EQ3 = perturbed_plant(31, family="sharp")[0]
"""A sharp-edged spool configured as Eq. 3 (no clearance intercept: 55-109 µm of opening near zero)."""
SHARP_DESIGN = replace(TABLE1, geometry=GEOMETRY_FAMILIES["sharp"])
"""The sharp-edged valve's design data as its plant configuration names it (``area_law = "sharp"``)."""
WORN3 = perturbed_plant(31, family="worn3")[0]
"""Eq. 3 lands worn in service to 3× Eq. 3's leakage; the configuration still says Eq. 3."""


@pytest.mark.slow
@pytest.mark.parametrize("plant", [SHARP_AS_EQ3, WORN3], ids=["sharp", "worn3"])
def test_clean_valve_of_another_family_is_none(plant):
    d = diagnose(_records(None, seed=306, plant=plant), TABLE1, None, SETTINGS, monitoring=False, priors=PRIORS)
    assert d.verdict.verdict == "none", d.verdict.reason
    assert d.gap_before < 0.5 * d.gap_nominal


@pytest.mark.slow
@pytest.mark.parametrize("plant,design,key,value", [(WORN3, TABLE1, "internal_leakage", 2e-12),
                                                    (SHARP_AS_EQ3, SHARP_DESIGN, "pressure_sensor_offset[p1]", 2e5)],
                         ids=["worn3-internal_leakage", "sharp_configured-p1_offset"])
def test_effect_on_another_family_is_named_or_honestly_ambiguous(plant, design, key, value):
    d = diagnose(_records(library_entry(key).effects(value), seed=307, plant=plant), design, None, SETTINGS, monitoring=False, priors=PRIORS)
    v = d.verdict
    assert v.verdict in ("named", "ambiguous"), (v.verdict, v.reason)
    assert v.effect.key == key or (v.verdict == "ambiguous" and key in v.alternative_keys), (v.effect.key, v.alternatives)
    if v.effect.key == key:
        assert abs(v.value - value) <= 0.2 * abs(value), (v.value, value)

# --- with a commissioning window ---------------------------------------------------------------

CLEAR_GAP = [  # the gap-shrink magnitudes of test_hidden_effects.CLEAR (mass and air doubled)
    ("internal_leakage", 2e-12), ("external_leakage", 2e-12), ("entrained_air", 1e-2), ("spool_sensor_offset", 1e-5),
    ("pressure_sensor_offset[p1]", 2e5), ("pressure_sensor_offset[p2]", -2e5), ("pressure_sensor_gain[p1]", 1.03),
    ("pressure_sensor_gain[p2]", 0.97), ("supply_line_resistance", 1e11), ("friction_change", 2e4), ("load_mass_change", 1200.0),
]


@pytest.fixture(scope="module")
def commissioned():
    cal = calibrate(_records(None, seed=310), TABLE1, NOM, PRIORS, SETTINGS)
    return cal.plant, cal.condition


@pytest.mark.slow
def test_commissioned_model_gap_is_near_the_noise_floor(commissioned):
    recs = _records(None, seed=311)
    calibrated = diagnose(recs, *commissioned, SETTINGS, monitoring=False)
    exact = diagnose(recs, PLANT, PLANT.nominal_condition, SETTINGS, monitoring=False)
    assert not calibrated.named
    assert calibrated.gap_before <= 2.0 * exact.gap_before, (calibrated.gap_before, exact.gap_before)


@pytest.mark.slow
@pytest.mark.parametrize("key,value", CLEAR_GAP, ids=[k for k, _ in CLEAR_GAP])
def test_commissioned_effect_is_named_and_shrinks_the_gap(commissioned, key, value):
    d = diagnose(_records(library_entry(key).effects(value), seed=312), *commissioned, SETTINGS, monitoring=False)
    assert d.named and d.named[0].spec.key == key, [(n.spec.key, n.value) for n in d.named]
    assert d.named[0].gap_after * 3.0 <= d.named[0].gap_before, (d.named[0].gap_before, d.named[0].gap_after)

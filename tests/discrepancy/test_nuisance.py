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
from transforms.discrepancy.calibration import _split_gains, calibrate
from transforms.discrepancy.corrected import corrected_lstsq
from transforms.discrepancy.gaps import GapAccumulator
from transforms.discrepancy.load import LoadEstimate
from transforms.discrepancy.nuisance import NUISANCES, NuisancePriors, apply_nuisances, nuisance_sigmas, nuisance_values
from transforms.discrepancy.pipeline import _project_out, diagnose
from transforms.discrepancy.verdict import (CANDIDATE_REPLAY_FLOOR, FAR_BEYOND_FLOOR, Verdict, acting_gap, beyond_selection, confirmed, far_beyond_the_floor,
                                           gap_to_replay, replay_closes, strongest_candidate, whole_replay_refutes)

from .simdata import perturbed_plant, simulate_lake, study_conditions

SETTINGS = DiscrepancySettings()
PRIORS = NuisancePriors()
NOM = TABLE1.nominal_condition


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


def test_corrected_least_squares_undoes_a_noisy_regressors_attenuation():
    # m a = F with the acceleration recorded with noise of variance s2: least squares reads m
    # short by m s2 / (var a + s2) (errors in variables, 20 % here); subtracting the noise's
    # expected part k (m0 + x)² with k = n s2 from the sum of squares gives back m
    rng = np.random.default_rng(7)
    n, m, s2 = 200_000, 6000.0, 0.25
    a = rng.normal(0.0, 1.0, n)
    a_rec = a + rng.normal(0.0, np.sqrt(s2), n)
    f = m * a + rng.normal(0.0, 50.0, n)
    m0 = 5000.0
    A, b = -a_rec[:, None], -(f - m0 * a_rec)  # the residual f - (m0 + x) a_rec and its column
    plain, _ = corrected_lstsq(A, b, np.array([1.0]), 0.0, m0)
    fixed, obj = corrected_lstsq(A, b, np.array([1.0]), n * s2, m0)
    assert abs(m0 + plain[0] - m / (1 + s2)) < 0.005 * m, plain
    assert abs(m0 + fixed[0] - m) < 0.005 * m, fixed
    resid = f - (m0 + fixed[0]) * a_rec
    assert obj == pytest.approx(resid @ resid - n * s2 * (m0 + fixed[0]) ** 2)


def test_split_gains_peak_at_a_level_change_and_added_step_splits_the_segment():
    r = np.r_[np.full(10, -1.0), np.full(15, 2.0 / 3.0)]  # demeaned, level change after row 10
    g = _split_gains(r)
    assert int(np.argmax(g)) == 9 and g[9] == pytest.approx(10 * 15 / 25 * (5.0 / 3.0) ** 2)
    n = 1000
    seg = (np.arange(n) >= 600).astype(np.int64)
    est = LoadEstimate(seg, np.array([600]), np.array([1.0, 2.0]), np.where(seg, 2.0, 1.0), np.full((1, 2), -1),
                       np.ones(n, bool), np.ones(n, bool))
    new = est.with_added_step(300, guard=40)
    assert new.steps.tolist() == [300, 600] and new.levels.tolist() == [1.0, 1.0, 2.0] and new.brackets.shape == (2, 2)
    assert new.segment[299] == 0 and new.segment[300] == 1 and new.segment[600] == 2
    assert not new.usable[260:340].any() and new.usable[:260].all() and new.usable[340:].all()


def test_nuisance_jacobian_from_the_terms_it_enters_equals_differences_of_the_whole_rows():
    """calibration.jacobians evaluates a nuisance's rows from the equation terms it enters only
    (TERMS_OF): that must be the same arithmetic as central differences of the whole residual
    rows, bit for bit, whatever the effects (sensor gains and offsets move every term)."""
    from transforms.discrepancy.calibration import Z_STEP, NuisanceModel, _residuals, jacobians
    from transforms.discrepancy.rows import _rows, prepare_records

    prepared = prepare_records(_records(None, seed=305, n_windows=1), TABLE1, NOM, SETTINGS)
    nm = NuisanceModel.of(TABLE1, NOM, PRIORS)
    z = 0.5 * np.random.default_rng(5).normal(size=len(nm.active))  # within the clipping
    rows0 = _rows(prepared, *nm.model(np.zeros(len(nm.active))), Effects(), SETTINGS)
    fx = Effects(p1_sensor_gain=1.02, p2_sensor_offset_pa=3e4, air_fraction=0.01, delta_mass_kg=50.0)
    r, Jz, _ = jacobians(prepared, nm, z, fx, [], rows0, SETTINGS)
    assert np.array_equal(r, _residuals(prepared, nm, z, fx, rows0, SETTINGS), equal_nan=True)
    for j in range(len(nm.active)):
        zp, zm = z.copy(), z.copy()
        zp[j] += Z_STEP
        zm[j] -= Z_STEP
        col = (_residuals(prepared, nm, zp, fx, rows0, SETTINGS) - _residuals(prepared, nm, zm, fx, rows0, SETTINGS)) / (2 * Z_STEP)
        assert np.any(col != 0.0) and np.array_equal(Jz[:, j], col, equal_nan=True), nm.names()[j]


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
    if not d.named:  # a reading of the nuisance verdict carries the gap where it acts, replayed with its joint fit
        kind = acting_gap(v.effect)
        assert v.gap_kind == kind and v.floor == d.noise_floors[kind], (v.gap_kind, v.floor, d.noise_floors)
        assert np.isfinite(v.acting_before) and np.isfinite(v.acting_after), (v.acting_before, v.acting_after)
        if v.verdict == "named":  # confirmed by the replay
            assert confirmed(v.acting_before, v.acting_after, v.floor), (v.acting_before, v.acting_after, v.floor)



def test_nothing_found_with_a_gap_far_beyond_its_floor_is_unexplained():
    # the reference plant's seed 5 with commissioning (the study's commands with --first-seed 3):
    # a typical friction change, which the equations' selection did not see, replayed X 4.05 mm off
    # (355x its floor of 0.0114 mm) and was reported `none`; the clean valves' split gaps reach 7.7x
    # (test_clean_valve_of_another_family_is_none[sharp]: a load step the estimate did not find)
    from transforms.discrepancy import GapAccumulator

    n = 1000
    moving = np.r_[np.ones(n // 2, bool), np.zeros(n // 2, bool)]
    regions = {"all": np.ones(n, bool), "extending": moving, "standstill": ~moving}
    floors = {"hydraulic": 0.050, "mechanical": 0.0114}

    def acc(x_mm: float):
        a = GapAccumulator()
        a.add("p1_hydraulic", np.full(n, 0.064e5), regions)
        a.add("p2_hydraulic", np.full(n, 0.064e5), regions)
        a.add("X_mechanical", np.where(moving, np.sqrt(2.0) * x_mm * 1e-3, 0.0), regions)
        return a

    v = far_beyond_the_floor(None, False, acc(4.05), floors)
    assert (v.verdict, v.effect, v.gap_kind, v.floor) == ("unexplained", None, "mechanical", 0.0114), v
    assert v.gap_before == v.gap_after == pytest.approx(4.05) and "the motion (Eq. 5, X)" in v.where and "region extending" in v.where, v.where
    assert "355× its noise floor" in v.reason, v.reason
    candidates = [{"effect": "friction_change", "variant": "", "parameter_name": "delta_d_v", "parameter_unit": "N*s/m", "linear_value": 19870.0,
                   "z": 75.4, "relative_gain": 0.705, "t_stat": 3.454},
                  {"effect": "entrained_air", "variant": "", "parameter_name": "air_fraction", "parameter_unit": "-", "linear_value": 1e-4,
                   "z": 0.3, "relative_gain": 0.0, "t_stat": -0.2}]
    hint = strongest_candidate(candidates, 4.0)
    assert hint == ("the equations' strongest candidate, friction_change delta_d_v=1.99e+04 N*s/m (z = 75), takes 70% of their residual "
                    "at t = 3.5 (a name needs t ≥ 4)"), hint
    assert far_beyond_the_floor(None, False, acc(4.05), floors, hint).reason.endswith("; " + hint)
    assert strongest_candidate(candidates[1:], 4.0) == strongest_candidate([], 4.0) == ""  # nothing reduced the residual
    none = Verdict("none", 0.9, None, float("nan"), nuisances=[{"name": "d_v"}], scores=[{"key": "friction_change"}])
    v = far_beyond_the_floor(none, False, acc(4.05), floors)
    assert v.verdict == "unexplained" and v.nuisances == none.nuisances and v.scores == none.scores
    assert far_beyond_the_floor(none, False, acc(7.7 * floors["mechanical"]), floors) is none  # the sharp-edged clean valve
    # below the line, a named effect, or what the model taken as exact named: as it is
    below = 0.99 * FAR_BEYOND_FLOOR * floors["mechanical"]
    assert far_beyond_the_floor(None, False, acc(below), floors) is None
    assert far_beyond_the_floor(none, False, acc(below), floors) is none
    assert far_beyond_the_floor(None, True, acc(4.05), floors) is None
    named = replace(none, verdict="named", effect=library_entry("friction_change"), value=2e4)
    assert far_beyond_the_floor(named, False, acc(4.05), floors) is named


def test_a_gap_far_beyond_its_floor_that_the_strongest_candidate_closes_is_ambiguous():
    # the reference plant's seed 4 with commissioning: a typical 600 kg mass change, which the
    # equations' selection did not name (t = 2.1 across the 1 s blocks), left the mechanical gap at
    # 0.101 mm, 8.9x its floor, and was `none`; the mass candidate fitted, 597 kg, replays it at
    # 0.0117 mm. Seed 5's friction change: 4.05 -> 0.0131 mm with 19,800 N s/m (t = 3.5)
    mass, leak = library_entry("load_mass_change"), library_entry("internal_leakage")
    none = Verdict("none", 0.9, None, float("nan"), nuisances=[{"name": "mass"}])
    v = replay_closes(none, False, mass, 597.0, 2.1, 0.0114, 0.101, 0.0117, 0.35, 0.34)
    assert (v.verdict, v.effect, v.value, v.alternative_keys) == ("ambiguous", mass, 597.0, []), v
    assert v.alternatives == ["an effect outside the library"] and v.nuisances == none.nuisances
    assert (v.gap_kind, v.acting_before, v.acting_after, v.floor, v.gap_before, v.gap_after) == ("mechanical", 0.101, 0.0117, 0.0114, 0.35, 0.34)
    assert v.confidence == pytest.approx(0.982, abs=1e-3)  # Phi(2.1): the equations' own evidence
    assert "8.86× its noise floor" in v.reason and "closes it in the replay to 0.0117 (1.0× the floor, what lay above the floor 38.1× less)" in v.reason, v.reason
    assert replay_closes(None, False, mass, 597.0, 2.1, 0.0114, 0.101, 0.0117, 0.35, 0.34).verdict == "ambiguous"  # the model taken as exact
    assert "nothing above the floor" in replay_closes(none, False, mass, 597.0, 2.1, 0.0114, 0.101, 0.011, 0.35, 0.34).reason
    # what lies above the floor shrunk less than 3x (0.1004 -> 0.0347 mm), below the line, or something found: as it is
    assert replay_closes(none, False, mass, 597.0, 2.1, 0.0114, 0.101, 3.2 * 0.0114, 0.35, 0.34) is none
    assert replay_closes(none, False, mass, 597.0, 2.1, 0.0114, 0.99 * CANDIDATE_REPLAY_FLOOR * 0.0114, 0.0117, 0.35, 0.34) is none
    assert replay_closes(None, True, mass, 597.0, 2.1, 0.0114, 0.101, 0.0117, 0.35, 0.34) is None
    named = replace(none, verdict="named", effect=leak, value=1e-12)
    assert replay_closes(named, False, mass, 597.0, 2.1, 0.0114, 0.101, 0.0117, 0.35, 0.34) is named


def test_a_gap_far_off_that_the_candidate_all_but_closes_is_ambiguous_though_above_twice_the_floor():
    # the reference plant at the noisy end (spool reconstructed), seed 5 with commissioning: the
    # clean valve's mechanical gap is 2.86x its floor there (the load estimate at 10 um); a typical
    # friction change left 2.85 mm, 53x its floor 0.0534, and the friction candidate the equations
    # did not name (t = 3.0), fitted at 16,250 N s/m, replays it at 0.111 mm: 2.08x the floor, but
    # 29x less above it. Closing to twice the floor refused it (`unexplained`)
    friction = library_entry("friction_change")
    none = Verdict("none", 0.9, None, float("nan"))
    v = replay_closes(none, False, friction, 16250.0, 3.03, 0.0534, 2.85, 0.111, 0.54, 0.26)
    assert (v.verdict, v.effect, v.alternatives) == ("ambiguous", friction, ["an effect outside the library"]), v
    assert "2.1× the floor, what lay above the floor 29.3× less" in v.reason, v.reason
    # the wrong candidates the study brought there: a friction change for a pressure-dependent
    # friction (6.1x -> 6.3x) or for a mass change (6.8x -> 6.81x) shrink nothing
    assert replay_closes(none, False, friction, 1e4, 1.9, 0.0534, 6.1 * 0.0534, 6.3 * 0.0534, 0.5, 0.5) is none
    assert replay_closes(none, False, friction, 1e4, 1.6, 0.0534, 6.8 * 0.0534, 6.81 * 0.0534, 0.5, 0.5) is none


def test_the_strongest_candidate_is_replayed_on_its_own_gap_even_where_the_other_lies_farther():
    # a valve dwelling between moves, calibrated on a busy commissioning window (reference plant,
    # seed 1, the noisy end): the motion replays 18.9x its floor, the chambers 6.2x theirs; the
    # equations' strongest candidate, a typical supply line, acts on the chambers
    acc = GapAccumulator()
    for signal, err in (("p1_hydraulic", 1.694e5), ("p2_hydraulic", 1.694e5), ("X_mechanical", 1.191e-3)):
        acc.add(signal, np.full(4, err), {"all": np.ones(4, bool)})
    floors = {"hydraulic": 0.272, "mechanical": 0.063}
    supply, friction = library_entry("supply_line_resistance"), library_entry("friction_change")
    assert gap_to_replay(supply, acc, floors) == "hydraulic"
    assert gap_to_replay(friction, acc, floors) == "mechanical"
    assert gap_to_replay(supply, acc, {"hydraulic": 1.694 / (0.99 * CANDIDATE_REPLAY_FLOOR), "mechanical": 0.063}) is None
    assert gap_to_replay(supply, acc, {"hydraulic": 0.0, "mechanical": 0.063}) is None  # no floor, nothing to judge against


def test_the_gap_where_a_reading_acts_decides_against_the_whole_replay():
    # the reference plant without commissioning, two windows (the study's gaps; the floors 0.03 and
    # 0.05 mm are set here, so that a gap widened beyond twice its floor is refuted): seed 2's true
    # 600 kg mass read 551 kg, the whole gap 0.114 -> 0.141 but the mechanical 0.0709 -> 0.0713 mm
    # (it was refuted, `none`); seed 0's true 3 % p1 gain narrowed the hydraulic gap 0.0767 -> 0.0649
    assert not whole_replay_refutes("mechanical", 0.114, 0.141, 0.0709, 0.0713, 0.03)
    assert whole_replay_refutes("mechanical", 0.114, 0.141, 0.0709, 0.0760, 0.03)  # the mechanical gap widened 7 %, beyond 2x its floor
    assert not whole_replay_refutes("hydraulic", 0.192, 0.224, 0.0767, 0.0649, 0.05)
    assert whole_replay_refutes("hydraulic", 0.192, 0.224, 0.0767, 0.0760, 0.05)  # narrowed < 5 %
    assert not whole_replay_refutes("mechanical", 0.25, 0.4, 0.07, 0.09, 0.03)  # above the noise gap the whole replay does not arbitrate
    # at the noisy end (seed 2): the true mass read 672 kg moved the mechanical gap 0.0601 -> 0.0994
    # mm, within 2x its floor of 0.091: what the replay would confirm it does not refute
    assert not whole_replay_refutes("mechanical", 0.189, 0.32, 0.0601, 0.0994, 0.091)
    assert whole_replay_refutes("mechanical", 0.189, 0.32, 0.0601, 0.19, 0.091)
    # seed 0's true 3 % p2 gain: the selection's weak internal leak (t 4.1) left the hydraulic gap at
    # 0.229 -> 0.204 (`unexplained`); the nuisance verdict on the other candidates reads the p2 gain
    # 1.0306 at 13 sigma, the p2 offset its rival, and its replay shrinks that gap to 0.0652
    leak, gain, offset = (library_entry(k) for k in ("internal_leakage", "pressure_sensor_gain[p2]", "pressure_sensor_offset[p2]"))
    unexp = Verdict("unexplained", 0.999, leak, 9.6e-14, alternatives=["internal_leakage K_i=9.6e-14 m3/(s*Pa) (not confirmed)"],
                    gap_before=0.229, gap_after=0.204, gap_kind="hydraulic", floor=0.050)
    reading = Verdict("ambiguous", 0.999, gain, 1.0306, alternatives=["the base model with alpha_s2 +3.4σ", "pressure_sensor_offset[p2] 5.1e+05 Pa"],
                      alternative_keys=[offset.key], reason="the data fit either ...", gap_kind="hydraulic", floor=0.050,
                      acting_before=0.229, acting_after=0.0652)
    v = beyond_selection(unexp, reading)
    assert (v.verdict, v.effect, v.alternative_keys) == ("ambiguous", gain, [offset.key]), v
    assert v.alternatives[-1] == unexp.alternatives[0] and "internal_leakage" in v.reason and "0.229 → 0.0652" in v.reason, v.reason
    assert beyond_selection(unexp, replace(reading, verdict="named")).verdict == "ambiguous"  # the equations' selection pointed elsewhere
    assert beyond_selection(unexp, replace(reading, acting_after=0.2)) is unexp  # a reading that does not close the gap either
    assert beyond_selection(unexp, replace(reading, verdict="none")) is unexp


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
    """... and a sharp-edged valve configured as Eq. 3 is recognised as sharp-edged (its radial
    clearance calibrates to ~0) and diagnosed with that law."""
    d = diagnose(_records(None, seed=306, plant=plant), TABLE1, None, SETTINGS, monitoring=False, priors=PRIORS)
    assert d.verdict.verdict == "none", d.verdict.reason
    assert d.gap_before < 0.5 * d.gap_nominal
    assert d.verdict.reason.startswith("the edges are sharp") == (plant is SHARP_AS_EQ3), d.verdict.reason
    assert (d.model[0].geometry.area_law == "sharp") == (plant is SHARP_AS_EQ3)


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


@pytest.mark.slow
def test_a_commissioning_window_shows_sharp_edges_as_the_diagnosis_does():
    """A sharp-edged valve configured as Eq. 3, commissioned: its radial clearance calibrates below
    ``SHARP_CLEARANCE`` of Eq. 3's, so the commissioning model has the sharp-edged law, as the
    diagnosis without one switches to it. Kept at Eq. 3 with the clearance near 0 (the sharp law
    only to ~1 % at larger openings), the diagnosis that takes it as exact named the robustness
    study's 600 kg mass change on this valve (``--family sharp --declared eq3 --commissioning yes``,
    seed 2) an external leak, with an internal leak as the other reading; now the mass is the first
    reading (503 kg)."""
    plant = study_conditions(perturbed_plant(2, clip=2.0, family="sharp", stream=17017)[0])
    cal = calibrate(_records(None, seed=5002, plant=plant), TABLE1, NOM, PRIORS, SETTINGS)
    assert cal.plant.geometry.area_law == "sharp"
    assert cal.reason.startswith("the edges are sharp") and 'configure area_law = "sharp"' in cal.reason, cal.reason
    d = diagnose(_records(library_entry("load_mass_change").effects(600.0), seed=102, plant=plant), cal.plant, cal.condition, SETTINGS,
                 monitoring=False)
    assert d.named and d.named[0].spec.key == "load_mass_change", [n.spec.key for n in d.named]
    assert abs(d.named[0].value - 600.0) < 0.25 * 600.0, d.named[0].value

# --- with a commissioning window ---------------------------------------------------------------

CLEAR_GAP = [  # the effects a commissioning calibration decides: nuisance patterns (the spool offset is the underlap
    # pattern, the mass and d_v are nuisances) and the compressibility (air against the calibrated β, V01, V02);
    # the other effects' "named first, gap shrinks ≥ 3×" on a model taken as exact is test_hidden_effects' CLEAR, same
    # magnitudes. Mass and air doubled: at 600 kg and 5e-3 they are named first here too, but raise the gap only to
    # 0.088 / 0.084 against the commissioned model's floor of 0.047, so it cannot shrink 3x (the commissioning mass is
    # right on this plant: z 1.38, true 1.34)
    ("entrained_air", 1e-2), ("spool_sensor_offset", 1e-5), ("pressure_sensor_gain[p1]", 1.03), ("friction_change", 2e4),
    ("load_mass_change", 1200.0),
]


def _study_seed0_plant():
    """The robustness study's seed-0 valve (bench/discrepancy_robustness.py ``true_plant(0)``): its
    commissioning window has a 325 N load step during a move, below what the load-step detector
    finds; before the calibration split segments this put the mass 4.4σ (530 kg) off."""
    plant, z = perturbed_plant(0, clip=2.0, stream=17017)
    return study_conditions(plant), z


MASS_BOUND_SIGMA = 0.5
"""The commissioning calibration's mass within this many prior σ (2 % of m: 60 kg) on slow moves
(measured: 0.03σ on the study's seed 0, ≤ 0.25σ on the test plant's seeds 320–325)."""


@pytest.mark.slow
@pytest.mark.parametrize("case", ["study_seed0", "test_plant"])
def test_commissioning_calibration_recovers_the_mass_on_slow_moves(case):
    plant, z_true, seed = (*_study_seed0_plant(), 5000) if case == "study_seed0" else (study_conditions(PLANT), Z_TRUE, 320)
    cal = calibrate(_records(None, seed=seed, plant=plant), TABLE1, NOM, PRIORS, SETTINGS)
    k = NUISANCES.index("mass")
    assert abs(cal.table()[k]["z"] - z_true[k]) < MASS_BOUND_SIGMA, (cal.table()[k]["z"], z_true[k])


@pytest.fixture(scope="module")
def commissioned():
    cal = calibrate(_records(None, seed=310), TABLE1, NOM, PRIORS, SETTINGS)
    return cal.plant, cal.condition


@pytest.mark.slow
@pytest.mark.xdist_group("commissioned")  # one worker calibrates the shared `commissioned` once (~12 s)
def test_commissioned_model_gap_is_near_the_noise_floor(commissioned):
    recs = _records(None, seed=311)
    calibrated = diagnose(recs, *commissioned, SETTINGS, monitoring=False)
    exact = diagnose(recs, PLANT, PLANT.nominal_condition, SETTINGS, monitoring=False)
    assert not calibrated.named
    assert calibrated.gap_before <= 2.0 * exact.gap_before, (calibrated.gap_before, exact.gap_before)


@pytest.mark.slow
@pytest.mark.xdist_group("commissioned")
@pytest.mark.parametrize("key,value", CLEAR_GAP, ids=[k for k, _ in CLEAR_GAP])
def test_commissioned_effect_is_named_and_shrinks_the_gap(commissioned, key, value):
    d = diagnose(_records(library_entry(key).effects(value), seed=312), *commissioned, SETTINGS, monitoring=False)
    assert d.named and d.named[0].spec.key == key, [(n.spec.key, n.value) for n in d.named]
    # the gap where it acts (the verdict's confirmation, verdict.confirmed); the whole gap also holds the load
    # estimate's shape: air 0.142 -> 0.048 (2.9x) with a 0.1 s grid where the constant left 144 N above X's noise
    n = d.named[0]
    assert n.acting_after * 3.0 <= n.acting_before, (n.gap_kind, n.acting_before, n.acting_after, n.gap_before, n.gap_after)


def test_each_equation_keeps_its_own_correlation_within_a_block():
    """The cylinder's noise enters chamber 1 as +A1 ΔX and chamber 2 as −A2 ΔX: pooled over the
    equations the block sums cancel and the rows looked independent (κ ~1) while each equation's
    rows were correlated; the verdict's κ is taken per equation. Rows constant within a block of
    n are correlated n-fold; white rows are κ = 1 (never below)."""
    from transforms.discrepancy.verdict import _equation_kappa

    rng = np.random.default_rng(7)
    n, blocks = 8, 50
    block = np.repeat(np.arange(blocks), n)
    u = np.repeat(rng.normal(size=blocks), n)  # the same error over a block's rows
    rw = np.r_[u, -u, rng.normal(size=blocks * n)]
    eq = np.repeat([0, 1, 2], blocks * n)
    kap = _equation_kappa(rw, np.r_[block, block, block], eq)
    assert np.allclose(kap[eq == 0], n) and np.allclose(kap[eq == 1], n)
    assert np.all(kap[eq == 2] == 1.0)
    pooled = np.bincount(block, weights=rw[:blocks * n] + rw[blocks * n:2 * blocks * n])
    assert not pooled.any()  # what the pooled ratio saw of the two chambers: nothing

"""Robustness of the discrepancy workflow on plants that are not its own model.

Every cell: a true plant whose base parameters are perturbed within realistic tolerances (α and
underlap per edge, β, V01, V02, d_v, d_c, d_s, mass; each z ~ N(0, 1) clipped to ±2σ of the
default :class:`transforms.discrepancy.nuisance.NuisancePriors`), one library effect hidden at a
magnitude (or none), simulated on other trajectories (minimum-jerk moves, slower speeds, longer
dwells), another controller (K_p 0.055, T_i 0.6 s) and a higher load-change rate than the tests
use; the workflow is given the nominal design data only, and

* ``--commissioning no``: diagnoses with the default nuisance priors (no commissioning window);
* ``--commissioning yes``: first calibrates the nuisances on a commissioning window of the same
  valve without the effect (another seed), then diagnoses against that model taken as exact.

``--family sharp|worn3|worn4`` makes the true valve one of the other valve families (sharp-edged
spool, worn lands leaking 3× or 4× Eq. 3). ``--declared nameplate`` (default) gives the workflow the
area law a plant configuration would name: the sharp-edged valve type is configured
``area_law = "sharp"``, worn lands are not configured (Eq. 3's nameplate; the workflow's edge-shape
nuisances must absorb them); ``--declared eq3`` gives every valve Eq. 3, the sharp-edged one too.

``--plant ref`` takes the true plants from the second reference plant (``tests/refplant``, written
apart from ``model/``: its own integrator, Karnopp sticking, loads ramping to a new level every
1–4 s, 1 ms transmitter lag and one sample of skew): a valve as built (``manufactured``, seed) with
the hidden effect in that package's own implementation (``--load-interval-s 1,1``: a new load level
every second); the two effects outside the library (``pressure_dependent_friction``, ``transmitter_lag`` on p1) are
added to ``--effects all``, and for them ``unexplained``, ``ambiguous`` or ``none`` are right and
any name is wrong. ``--operation sparse`` makes the diagnosed windows' valve dwell 2–10 s between
moves (``tests.refplant.sparse``; the commissioning window stays busy).

``--method before`` runs the workflow as it was before the nuisance calibration on the same cells (the design data
taken as exact; with commissioning only α and underlap fitted, ``pipeline.fit_condition``).

Outcome per run: ``named`` (the right effect named first), ``ambiguous`` (the right effect among the
verdict's readings), ``none``, ``unexplained`` (the equations pointed at an effect whose replay did
not close its gap: no name given), ``wrong`` (another effect named first, or an ambiguous verdict without
the right one); on clean data ``none`` is right, ``ambiguous`` is reported as such and ``named`` is
wrong. Parameter error: |θ̂ − θ| / |θ − neutral| where the right effect is the first reading. Every
run also keeps what the equations alone read of the hidden effect (``equations_read``: its value, z,
t and cross-validated gain in the selection's first step); the summary lists, for each library
effect missed (``none`` or ``unexplained``), that reading: whether the rows saw it at all.

    taskset -c 0,1 .venv/bin/python bench/discrepancy_robustness.py --seeds 5 --magnitudes typical --jobs 2

Prints the confusion table (markdown) and writes every run as JSON lines (``--out``).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SMALL_FACTOR = 0.2
"""The small magnitude is this fraction of the library's typical one."""


def true_plant(seed: int, family: str = "eq3"):
    from tests.discrepancy.simdata import perturbed_plant, study_conditions

    plant, z = perturbed_plant(seed, clip=2.0, family=family, stream=17017)
    return study_conditions(plant), z


REF_OUTSIDE = ("pressure_dependent_friction", "transmitter_lag")


def ref_lake(key: str | None, value, valve_seed: int, window_seed: int, n_windows: int, load_interval_s: tuple[float, float] | None = None,
             sensors: str = "quiet", operation: str = "busy"):
    """Lake rows of the reference plant's valve ``valve_seed`` (``manufactured``) over windows drawn
    from ``window_seed``, with effect ``key`` (a library key or one of ``REF_OUTSIDE``) at ``value``
    (None: its typical magnitude); ``load_interval_s`` the range of the load's intervals between
    new levels [s] (None: the plant's 1–4 s); ``sensors``: ``quiet`` (positions at 1 µm) or
    ``noisy_end`` (spool 0.2 % of x_max, cylinder 10 µm in 5 µm steps); ``operation``: ``busy`` (dwells
    0.2–0.8 s) or ``sparse`` (dwells 2–10 s, ``tests.refplant.sparse``)."""
    from datetime import datetime, timezone

    from tests.refplant import NAMEPLATE, effect, manufactured, noisy_end, simulate_windows, sparse, to_lake_frame

    fx = None
    if key is not None:
        name, _, ch = key.partition("[")
        fx = effect(name, value, channel=ch.rstrip("]") or "p1")
    plant = manufactured(NAMEPLATE, seed=valve_seed)
    if sensors == "noisy_end":
        plant = noisy_end(plant)
    if operation == "sparse":
        plant = sparse(plant)
    if load_interval_s is not None:
        plant = replace(plant, operation=replace(plant.operation, load_interval_s=tuple(load_interval_s)))
    recs = simulate_windows(plant, n_windows, window_seed, effects=fx)
    return to_lake_frame(recs, "V1", datetime(2025, 3, 1, tzinfo=timezone.utc))


def settings_for(reconstruct: str):
    """The workflow's settings with the positions ``reconstruct``-ed: ``x`` the spool, ``X`` the cylinder."""
    from transforms.discrepancy import DiscrepancySettings

    return DiscrepancySettings(reconstruct_spool="x" in reconstruct, reconstruct_cylinder="X" in reconstruct)


def design_plant(family: str, declared: str):
    """The design data the workflow is given: Table 1 with the area law the plant configuration
    declares. ``nameplate``: a sharp-edged valve type is configured ``area_law = "sharp"``, worn
    lands are not configured (wear happens in service: Eq. 3's nameplate); ``eq3``: every valve
    configured as Eq. 3, the sharp-edged one too."""
    from model import TABLE1
    from model.params import GEOMETRY_FAMILIES

    if declared == "nameplate" and GEOMETRY_FAMILIES[family].area_law == "sharp":
        return replace(TABLE1, geometry=GEOMETRY_FAMILIES[family])
    return TABLE1


def _lake(effects, seed: int, n_windows: int, plant):
    from tests.discrepancy.simdata import simulate_lake

    return simulate_lake(effects, n_windows=n_windows, seed=seed, params=plant)


@functools.lru_cache(maxsize=4)
def commissioning_condition_before(seed: int, n_windows: int, family: str = "eq3", declared: str = "nameplate"):
    """Before the nuisance calibration: only α and underlap fitted on the commissioning window."""
    from transforms.discrepancy import DiscrepancySettings, split_records
    from transforms.discrepancy.pipeline import fit_condition

    plant, _ = true_plant(seed, family)
    design = design_plant(family, declared)
    s = DiscrepancySettings()
    recs = split_records(_lake(None, 5000 + seed, n_windows, plant), s)
    return design, fit_condition(recs, design, design.nominal_condition, s).condition


@functools.lru_cache(maxsize=4)
def commissioning_model(seed: int, n_windows: int, family: str = "eq3", declared: str = "nameplate", plant_source: str = "model",
                        load_interval_s: tuple[float, float] | None = None, sensors: str = "quiet", reconstruct: str = ""):
    """The nuisances calibrated on a clean commissioning window of the seed's valve."""
    from transforms.discrepancy import split_records
    from transforms.discrepancy.calibration import calibrate
    from transforms.discrepancy.nuisance import NuisancePriors

    design = design_plant(family, declared)
    s = settings_for(reconstruct)
    if plant_source == "ref":
        recs = split_records(ref_lake(None, None, seed, 5000 + seed, n_windows, load_interval_s, sensors), s)
    else:
        plant, _ = true_plant(seed, family)
        recs = split_records(_lake(None, 5000 + seed, n_windows, plant), s)
    cal = calibrate(recs, design, design.nominal_condition, NuisancePriors(), s)
    return cal.plant, cal.condition


def run_cell(key: str, magnitude: str, commissioning: bool, seed: int, n_windows: int, method: str = "nuisance", family: str = "eq3",
             declared: str = "nameplate", plant_source: str = "model", load_interval_s: tuple[float, float] | None = None,
             sensors: str = "quiet", reconstruct: str = "", operation: str = "busy") -> dict:
    from model.effects import effect_key, library_entry
    from transforms.discrepancy import split_records
    from transforms.discrepancy.nuisance import NuisancePriors
    from transforms.discrepancy.pipeline import diagnose
    from transforms.discrepancy.verdict import above_floor, acting_gap

    t0 = time.process_time()
    design = design_plant(family, declared)
    spec = None if key in ("none",) + REF_OUTSIDE else library_entry(key)
    value = None
    effects = None
    if spec is not None:
        mag = spec.typical * (1.0 if magnitude == "typical" else SMALL_FACTOR)
        sign = -1.0 if spec.neutral == 1.0 and seed % 2 else 1.0  # gains both ways
        value = spec.neutral + sign * mag
        effects = spec.effects(value)
    s = settings_for(reconstruct)
    if plant_source == "ref":
        lake = ref_lake(None if key == "none" else key, value, seed, 100 + seed, n_windows, load_interval_s, sensors, operation)
    else:
        lake = _lake(effects, 100 + seed, n_windows, true_plant(seed, family)[0])
    recs = split_records(lake, s)
    if commissioning or method == "before":
        if not commissioning:
            cp, cc = design, design.nominal_condition
        else:
            cp, cc = (commissioning_model if method == "nuisance" else commissioning_condition_before)(seed, n_windows, family, declared,
                                                                                                    *((plant_source, load_interval_s, sensors, reconstruct) if method == "nuisance" else ()))
        d = diagnose(recs, cp, cc, s, monitoring=False)
        if d.verdict is not None:  # unexplained (or gain/offset ambiguous): the verdict decides
            v = d.verdict
            verdict, got, got_value, alts = v.verdict, (v.effect.key if v.effect else None), v.value, v.alternative_keys
        elif d.named:
            first = d.named[0]
            verdict = "ambiguous" if first.alternative is not None else "named"
            got, got_value = first.spec.key, first.value
            alts = [first.alternative.key] if first.alternative is not None else []
        else:
            verdict, got, got_value, alts = "none", None, None, []
        conf = None
    else:
        d = diagnose(recs, design, None, s, monitoring=False, priors=NuisancePriors())
        v = d.verdict
        verdict, got, got_value, alts, conf = v.verdict, (v.effect.key if v.effect else None), v.value, v.alternative_keys, v.confidence
    if key == "none" or key in REF_OUTSIDE:
        outcome = {"none": "none", "ambiguous": "ambiguous", "named": "wrong", "unexplained": "unexplained"}[verdict]
    elif verdict in ("none", "unexplained"):
        outcome = verdict
    elif got == key:
        outcome = verdict
    elif verdict == "ambiguous" and key in alts:
        outcome = "ambiguous"
    else:
        outcome = "wrong"
    # the acceptance's two gap figures: where the effect acts, the shrink from the base model to the
    # final stage (of the gap, and of what it holds above the noise, sqrt(gap² - floor²): the
    # recorded noise is independent of the replay, so the two add in squares); on the clean valve,
    # each split gap over its noise floor
    acting = acting_gap(spec) if spec is not None else None
    before_after = None
    if acting and d.verdict is not None and np.isfinite(d.verdict.acting_before):  # a reading of the nuisance verdict
        before_after = (d.verdict.acting_before, d.verdict.acting_after)
    elif acting and d.verdict is not None and d.verdict.verdict == "unexplained" and d.verdict.gap_kind == acting:
        before_after = (d.verdict.gap_before, d.verdict.gap_after)
    elif acting:  # the selection's stages
        before_after = (d.split_gaps[0][acting], d.split_gaps[-1][acting])
    shrink = before_after[0] / before_after[1] if before_after else None
    above = [above_floor(g, d.noise_floors[acting]) for g in before_after] if before_after else None
    shrink_above = above[0] / above[1] if above and above[1] > 0 else None
    over_floor = {k: d.split_gaps[0][k] / f for k, f in d.noise_floors.items()} if key == "none" else None
    # what the equations alone read of the hidden effect (its first-step selection score): where it
    # is missed, whether the rows saw it at all
    seen = None if spec is None else next(({"value": c["linear_value"], "z": c["z"], "t_stat": c["t_stat"], "relative_gain": c["relative_gain"],
                                            "significant": c["significant"]} for c in d.candidates
                                           if (c["effect"], c["variant"]) == (spec.name, spec.variant)), None)
    rel_err = None
    if spec is not None and got == key and got_value is not None and np.isfinite(got_value):
        rel_err = abs(got_value - value) / abs(value - spec.neutral)
    return {
        "effect": key, "magnitude": magnitude, "commissioning": commissioning, "seed": seed, "value": value, "method": method, "family": family, "declared": declared,
        "plant": plant_source, "sensors": sensors, "reconstruct": reconstruct, "operation": operation, "load_interval_s": load_interval_s, "pressure_delay_samples": d.pressure_delay_samples, "pressure_delays": d.pressure_delays,
        "lag_finding": d.lag_finding, "reason": d.verdict.reason if d.verdict is not None else "",
        "verdict": verdict, "got": got, "got_value": got_value, "alternatives": alts, "confidence": conf, "outcome": outcome,
        "rel_err": rel_err, "gap_nominal": d.gap_nominal, "gap_before": d.stage_gaps[0], "gap_after": d.stage_gaps[-1],
        "split_before": d.split_gaps[0], "split_after": d.split_gaps[-1], "floors": d.noise_floors,
        "acting_gap": acting, "acting_before_after": before_after, "shrink": shrink, "shrink_above_noise": shrink_above, "over_floor": over_floor,
        "equations_read": seen,
        # every candidate's first-step score: how far the false ones reach, to weigh a selection rule against
        "first_step": [{"effect": effect_key(c["effect"], c["variant"]), "z": c["z"], "t_stat": c["t_stat"],
                        "relative_gain": c["relative_gain"]} for c in d.candidates],
        "cpu_s": time.process_time() - t0,
    }


def _run(args):
    try:
        return run_cell(*args)
    except Exception as exc:  # a failed run is reported, not hidden
        key, magnitude, commissioning, seed = args[:4]
        return {"effect": key, "magnitude": magnitude, "commissioning": commissioning, "seed": seed, "outcome": "error", "error": repr(exc)}


def table(rows: list[dict]) -> str:
    groups = defaultdict(list)
    for r in rows:
        groups[(r["commissioning"], r["magnitude"], r["effect"])].append(r)
    # the clean valve of the same seed and mode: what the model leaves without the effect
    clean_gap = {(r["commissioning"], r["seed"]): r["split_before"] for r in rows if r["effect"] == "none" and r.get("split_before")}
    lines = ["| commissioning | magnitude | effect | runs | named first | ambiguous (right listed) | none | unexplained | wrong | max rel. error (named) "
             "| gap shrink where it acts (least, named or ambiguous; above the noise) | gap after / the clean valve's (largest) "
             "| clean valve: gap / noise floor (hydraulic, mechanical; largest) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (c, m, e), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "typical", kv[0][2])):
        n = len(rs)
        cnt = {o: sum(r["outcome"] == o for r in rs) for o in ("named", "ambiguous", "none", "unexplained", "wrong", "error")}
        errs = [r["rel_err"] for r in rs if r.get("rel_err") is not None and r["outcome"] == "named"]
        err = f"{max(errs):.1%}" if errs else "–"
        wrong = f"{cnt['wrong']}" + (f" (+{cnt['error']} errors)" if cnt["error"] else "")
        ok = [r for r in rs if r.get("shrink") is not None and r["outcome"] in ("named", "ambiguous")]
        above = [r["shrink_above_noise"] for r in ok if r.get("shrink_above_noise") is not None]
        shrink = f"{min(r['shrink'] for r in ok):.2g}× ({ok[0]['acting_gap']}; {min(above):.2g}×)" if ok and above else "–"
        vs_clean = [r["acting_before_after"][1] / clean_gap[(c, r["seed"])][r["acting_gap"]] for r in ok if (c, r["seed"]) in clean_gap]
        after_clean = f"{max(vs_clean):.2f}×" if vs_clean else "–"
        over = [r["over_floor"] for r in rs if r.get("over_floor")]
        clean = f"{max(o['hydraulic'] for o in over):.2g}, {max(o['mechanical'] for o in over):.2g}" if over else "–"
        lines.append(f"| {'yes' if c else 'no'} | {m if e != 'none' else '–'} | {e} | {n} | {cnt['named']} | {cnt['ambiguous']} | {cnt['none']} | {cnt['unexplained']} | {wrong} | {err} "
                     f"| {shrink} | {after_clean} | {clean} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    from model.effects import EFFECT_LIBRARY

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--windows", type=int, default=2, help="10 s windows per run")
    ap.add_argument("--magnitudes", default="typical,small")
    ap.add_argument("--commissioning", default="no,yes")
    ap.add_argument("--effects", default="all", help="all, or a comma-separated list of effect keys (none: the clean valve)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--method", default="nuisance", choices=("nuisance", "before"))
    ap.add_argument("--family", default="eq3", choices=("eq3", "sharp", "worn3", "worn4"), help="the true valve's edge shape")
    ap.add_argument("--declared", default="nameplate", choices=("nameplate", "eq3"),
                    help="the area law the workflow is given: the valve type's (sharp for the sharp family, Eq. 3 for worn lands) or Eq. 3 always")
    ap.add_argument("--plant", default="model", choices=("model", "ref"), help="the true plants: model/'s own code with perturbed parameters, or the second reference plant (tests/refplant)")
    ap.add_argument("--load-interval-s", default=None, help="with --plant ref: LOW,HIGH, the load's intervals between new levels [s] (default 1,4)")
    ap.add_argument("--sensors", default="quiet", choices=("quiet", "noisy_end"),
                    help="with --plant ref: positions recorded at 1 µm, or at the noisy end of plants (spool 0.2 %% of x_max, cylinder 10 µm in 5 µm steps)")
    ap.add_argument("--reconstruct", default="", choices=("", "x", "X", "xX"),
                    help="reconstruct the spool (x), the cylinder (X) or both before the diagnosis (settings.reconstruct_spool, reconstruct_cylinder)")
    ap.add_argument("--operation", default="busy", choices=("busy", "sparse"),
                    help="with --plant ref: the diagnosed windows' operation, dwells of 0.2-0.8 s (busy) or 2-10 s (sparse; the commissioning window stays busy)")
    ap.add_argument("--out", default="bench/discrepancy_robustness.jsonl")
    a = ap.parse_args(argv)
    keys = [s.key for s in EFFECT_LIBRARY] + (list(REF_OUTSIDE) if a.plant == "ref" else []) if a.effects == "all" else a.effects.split(",")
    mags = a.magnitudes.split(",")
    comms = [c == "yes" for c in a.commissioning.split(",")]
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    if a.load_interval_s is not None and a.plant != "ref":
        ap.error("--load-interval-s needs --plant ref")
    if a.sensors != "quiet" and a.plant != "ref":
        ap.error("--sensors needs --plant ref")
    if a.operation != "busy" and a.plant != "ref":
        ap.error("--operation needs --plant ref")
    interval = tuple(float(v) for v in a.load_interval_s.split(",")) if a.load_interval_s else None
    rest = (a.windows, a.method, a.family, a.declared, a.plant, interval, a.sensors, a.reconstruct, a.operation)
    tasks = []
    for c in comms:
        for seed in seeds:  # seed-major, so a worker reuses its commissioning calibration
            cells = ([("none", "typical")] if a.effects == "all" or "none" in keys else []) + [(k, m) for m in mags for k in keys if k != "none"]
            tasks += [(k, m, c, seed) + rest for k, m in cells]
    t0 = time.time()
    rows = []
    out = Path(a.out)
    with out.open("w") as fh, ProcessPoolExecutor(max_workers=min(a.jobs, 2)) as ex:
        for r in ex.map(_run, tasks):
            rows.append(r)
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            print(f"{r['effect']:28s} {r['magnitude']:7s} comm={r['commissioning']!s:5s} seed={r['seed']} -> {r['outcome']:9s} "
                  f"{r.get('got')} {r.get('got_value')} cpu {r.get('cpu_s', 0):.1f}s", flush=True)
    print(f"\n{len(rows)} runs, wall {time.time() - t0:.0f} s\n")
    print(table(rows))
    typ = [r for r in rows if r["magnitude"] == "typical" and r["effect"] not in ("none",) + REF_OUTSIDE]
    if typ:
        first = sum(r["outcome"] in ("named", "ambiguous") and r["got"] == r["effect"] for r in typ)
        other = sum(r["outcome"] == "ambiguous" and r["got"] != r["effect"] for r in typ)
        print(f"\ntypical magnitude: the library effect named or `ambiguous` with it first {first}/{len(typ)} = {first / len(typ):.0%}; "
              f"`ambiguous` with another reading first {other}")
        missed = [r for r in typ if r["outcome"] in ("none", "unexplained") and r.get("equations_read")]
        for r in missed:
            e = r["equations_read"]
            print(f"  missed: {r['effect']} comm={r['commissioning']} seed={r['seed']} ({r['outcome']}); the equations read "
                  f"{e['value']:.4g} (true {r['value']:.4g}) at z = {e['z']:.2g}, t = {e['t_stat']:.2g}, gain {e['relative_gain']:.1%}")
    outside = [r for r in rows if r["effect"] in REF_OUTSIDE]
    if outside:
        print(f"outside effects without a reading (`none` or `unexplained`): {sum(r['outcome'] in ('none', 'unexplained') for r in outside)}/{len(outside)}")
    eff = [r for r in rows if r["effect"] != "none"]
    wrong = sum(r["outcome"] == "wrong" for r in rows)
    clean_wrong = sum(r["outcome"] == "wrong" for r in rows if r["effect"] == "none")
    print(f"wrong names: {wrong}/{len(rows)} overall, {clean_wrong} on clean data ({len(rows) - len(eff)} clean runs)")


if __name__ == "__main__":
    main()

"""The model-discrepancy workflow without I/O: records in, a :class:`Diagnosis` out.

Steps (``docs/discrepancy.md``):

1. **where they disagree** -- every record is replayed (``model.replay``) on its recorded spool
   position, supply and return pressure and the estimated load, restarting from the measured
   state every ``replay_segment_s``; the gap to the recorded p1, p2, X is measured per signal and
   operating region (:mod:`transforms.discrepancy.gaps`). The equations' pointwise residuals
   (Savitzky–Golay derivatives) are summarised per region.
2. **name the missing effect** -- the integrated residuals of both chamber equations and the
   motion equation of the base model, and their derivatives with respect to each library
   candidate's parameter, go into the blocked-cross-validation forward selection of
   :mod:`transforms.discrepancy.selection`; the named parameters are refined by Gauss–Newton on
   the exact (not linearised) residuals, with jackknife intervals. Once something is named, the
   load is segmented again with the fitted model and the selection repeated.
3. **add it** -- the named effects are switched on one after the other, each record replayed
   again; gap before/after per effect. An effect that does not shrink the gap is not confirmed
   (dropped with the ones after it).
4. **what it did to monitoring** -- the monitoring (steps 2–4b) is run on the records as
   recorded and with the effect accounted for (:func:`monitoring_bias`).

The model is imported here and its per-sample terms are handed to the pure transforms.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from model.effects import EFFECT_LIBRARY, Effects, EffectSpec, true_signals
from model.params import PlantParams, ValveCondition
from model.simulate import DEFAULT_REG_BAND_PA
from transforms.discrepancy.corrected import capped_mass_noise, corrected_lstsq
from transforms.discrepancy.nuisance import NuisancePriors
from transforms.discrepancy.records import Record
from transforms.discrepancy.selection import SelectionResult, block_stats, cv_losses, forward_select
from transforms.discrepancy.settings import DiscrepancySettings

__all__ = [
    "ConditionFit",
    "Diagnosis",
    "NamedEffect",
    "ReplayTrace",
    "diagnose",
    "fit_condition",
    "monitoring_bias",
    "perturbed",
    "prepare_records",
]
from transforms.discrepancy.rows import (  # noqa: F401 (ReplayTrace, prepare_records, perturbed: part of this module's interface)
    FD_FRACTION,
    ReplayTrace,
    _eliminate_load,
    _equation_sigmas,
    _estimate_load,
    _gaps,
    _jacobian,
    _residual_summary,
    _Rows,
    _rows,
    mass_term_noise,
    noise_floors,
    perturbed,
    pooled_noise,
    prepare_records,
)

# --- the diagnosis ---------------------------------------------------------------------------


@dataclass(frozen=True)
class NamedEffect:
    """An effect the workflow named.

    Attributes
    ----------
    rank : int
        1 = named first.
    spec : EffectSpec
        The library entry (name, variant, parameter name and unit).
    value : float
        The fitted parameter (refined on the exact residuals). [spec.unit]
    ci_low, ci_high : float
        Its interval at the settings' level (jackknife over blocks).
    linear_value : float
        The parameter of the linearised selection step.
    relative_gain, t_stat, z : float
        The selection statistics at the step it was named.
    gap_before, gap_after : float
        Normalised gap with the effects named before it, and with it added.
    """

    rank: int
    spec: EffectSpec
    value: float
    ci_low: float
    ci_high: float
    linear_value: float
    relative_gain: float
    t_stat: float
    z: float
    gap_before: float
    gap_after: float
    alternative: EffectSpec | None = None
    """The runner-up when it was hard to tell apart (advantage t < AMBIGUITY_T), else None."""
    alternative_t: float = float("inf")
    """t statistic of this effect's blockwise advantage over the runner-up."""
    gap_kind: str = "hydraulic"
    """Where the effect acts (:func:`transforms.discrepancy.verdict.acting_gap`)."""
    acting_before: float = float("nan")
    acting_after: float = float("nan")
    """That gap (hydraulic or mechanical, ``gaps.SPLIT_GAPS``) before and after adding the effect."""
    floor: float = float("nan")
    """That gap's noise floor."""

    @property
    def confirmed(self) -> bool:
        """The replay confirms it (:func:`transforms.discrepancy.verdict.confirmed`)."""
        from transforms.discrepancy.verdict import confirmed

        return confirmed(self.acting_before, self.acting_after, self.floor)


AMBIGUITY_T = 2.0
"""Below this t statistic of its advantage over the runner-up, a named effect is reported with
the runner-up as its alternative."""


@dataclass
class Diagnosis:
    """What :func:`diagnose` found (see the module docstring for the steps)."""

    n_records: int
    records: list[tuple[int, int]]
    named: list[NamedEffect]
    candidates: list[dict]
    gap_rows: list[dict]
    residual_rows: list[dict]
    stage_effects: list[Effects]
    stage_gaps: list[float]
    traces: list[ReplayTrace] = field(default_factory=list)
    n_blocks: int = 0
    equation_sigmas: tuple[float, float, float] = (1.0, 1.0, 1.0)
    monitoring: list[dict] = field(default_factory=list)
    """Step 4 per edge (:func:`monitoring_bias`); empty if not run."""
    verdict: object = None
    """With nuisance priors: the :class:`transforms.discrepancy.verdict.Verdict` (named / ambiguous /
    none, confidence, readings, calibrated nuisances); None when the model was taken as exact."""
    gap_nominal: float = float("nan")
    """Normalised gap of the nominal (uncalibrated) base model; = stage 0 without nuisances."""
    model: tuple = ()
    """(plant, condition) of the final stage (calibrated nuisances when priors were given)."""
    noise_floors: dict = field(default_factory=dict)
    """The split gaps (hydraulic, mechanical) the recorded noise alone leaves through the replay (``rows.noise_floors``)."""
    split_gaps: list = field(default_factory=list)
    """Per stage: {hydraulic, mechanical} gap."""
    pressure_delay_samples: int = 0
    """The delay shared by the pressure channels against the positions (samples;
    :mod:`transforms.discrepancy.alignment`)."""
    pressure_delays: dict = field(default_factory=dict)
    """The delay each pressure channel (ps, pr, p1, p2) was aligned for (samples)."""
    lag_finding: str = ""
    """A chamber transmitter lagging the other pressures: which, how many ms (``PressureDelays.finding``); "" if none."""
    position_noise: dict = field(default_factory=dict)
    """The recorded positions' noise RMS over the records as they estimate it (``rows.pooled_noise``):
    ``x`` the spool, ``X`` the cylinder. [m]"""
    spool_reconstructed: int = 0
    """Records whose spool position was taken as Eq. 1's response to x_ref (``settings.reconstruct_spool``
    and the reading follows it, :func:`transforms.discrepancy.states.spool_from_reference`)."""

    @property
    def final_effects(self) -> Effects:
        return self.stage_effects[-1]

    @property
    def gap_before(self) -> float:
        return self.stage_gaps[0]

    @property
    def gap_after(self) -> float:
        return self.stage_gaps[-1]


def _refine(prepared, plant, condition, specs: list[EffectSpec], start: Effects, rows0: _Rows, w_rows: np.ndarray, settings) -> tuple[Effects, np.ndarray, np.ndarray]:
    """Gauss–Newton on the exact residuals for the parameters of ``specs`` from ``start``;
    returns the effects, the jackknife SEs and the final Jacobian."""
    from transforms.discrepancy.calibration import mass_gradient

    fx = start
    J = None
    r = None
    g = mass_gradient(None, specs)
    e2 = mass_term_noise(prepared, rows0, w_rows, settings) if np.any(g) else None
    for _ in range(settings.gauss_newton_iterations):
        y_here = _rows(prepared, plant, condition, fx, settings).y
        r = _eliminate_load(y_here, rows0)
        J = _jacobian(prepared, plant, condition, fx, specs, rows0, settings, y_here)
        ok = np.isfinite(r) & np.all(np.isfinite(J), axis=1)
        Jw = J[ok] * w_rows[ok, None]
        rw = r[ok] * w_rows[ok]
        k = capped_mass_noise(float(np.sum(e2[ok])), Jw, g) if e2 is not None else 0.0
        step, _ = corrected_lstsq(Jw, -rw, g, k, plant.cylinder.mass_kg + fx.delta_mass_kg)
        new = fx
        for spec, d in zip(specs, step):
            v = spec.value(new) + float(d)
            if spec.lower is not None and v < spec.lower:  # projected onto the physical range
                v = spec.lower
            new = replace(new, **{spec.attribute: v})
        try:
            new = Effects(**{f: getattr(new, f) for f in new.__dataclass_fields__})
        except ValueError:
            break
        small = all(abs(d) < 1e-4 * spec.typical for spec, d in zip(specs, step))
        fx = new
        if small:
            break
    y_here = _rows(prepared, plant, condition, fx, settings).y
    r = _eliminate_load(y_here, rows0)
    J = _jacobian(prepared, plant, condition, fx, specs, rows0, settings, y_here)
    st = block_stats(-r * w_rows, J * w_rows[:, None], rows0.block, _mass_noise(specs, e2, J * w_rows[:, None], r, plant.cylinder.mass_kg + fx.delta_mass_kg))
    _, _, loo = cv_losses(st, list(range(len(specs))))
    B = loo.shape[0]
    se = np.sqrt((B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0)) / st.scale if B > 1 else np.full(len(specs), np.inf)
    return fx, se, J


def _mass_noise(specs: list[EffectSpec], e2: np.ndarray | None, Jw: np.ndarray, r: np.ndarray, m0: float) -> tuple | None:
    """``block_stats``' noise correction of a mass change's column (``rows.mass_term_noise``'s
    ``e2`` per row, scaled down as ``corrected.capped_mass_noise`` caps it), or None."""
    from transforms.discrepancy.calibration import mass_gradient

    g = mass_gradient(None, specs)
    if e2 is None or not np.any(g):
        return None
    ok = np.isfinite(r) & np.all(np.isfinite(Jw), axis=1)
    k = float(np.sum(e2[ok]))
    if k <= 0.0:
        return None
    return int(np.argmax(g)), e2 * (capped_mass_noise(k, Jw[ok], g) / k), m0


def _project_out(Nw: np.ndarray, *cols: np.ndarray) -> list[np.ndarray]:
    """Each of ``cols`` (weighted rows) minus its ridge regression on the weighted nuisance
    columns Nw (z units, prior N(0, I): v − Nw (NwᵀNw + I)⁻¹ Nwᵀ v; rows with a non-finite entry
    are left as they are (block_stats drops them))."""
    ok = np.all(np.isfinite(Nw), axis=1)
    for c in cols:
        ok &= np.isfinite(c) if c.ndim == 1 else np.all(np.isfinite(c), axis=1)
    N = Nw[ok]
    H = N.T @ N + np.eye(N.shape[1])
    out = []
    for c in cols:
        c2 = np.array(c, float, copy=True)
        c2[ok] = c[ok] - N @ np.linalg.solve(H, N.T @ c[ok])
        out.append(c2)
    return out


NUISANCE_COLLINEAR = 0.05
"""A candidate whose regressor keeps less than this fraction of its norm once the nuisance
directions are projected out is not selected on the residuals (it is a nuisance pattern)."""


def _select(prepared, plant, condition, specs, settings, nuisance=None):
    """(rows, weights, forward selection, equation sigmas, patterns) against the base model
    (module docstring). With ``nuisance`` = (NuisanceModel, z) the plant and condition are the
    nuisance model at z and the residual and every candidate's regressor are first cleared of what
    the nuisances (within their priors) explain (:func:`_project_out`): a candidate is then scored
    only on what the nuisances cannot explain; ``patterns`` are the candidates the nuisances
    reproduce (nothing left to score), which the verdict weighs by their priors."""
    base = Effects()
    rows0 = _rows(prepared, plant, condition, base, settings)
    r0 = _eliminate_load(rows0.y, rows0)
    sig = _equation_sigmas(r0, rows0)
    w_rows = 1.0 / sig[rows0.eq]
    J0 = _jacobian(prepared, plant, condition, base, specs, rows0, settings, rows0.y)
    yw, Jw = -r0 * w_rows, J0 * w_rows[:, None]
    cand = list(range(len(specs)))
    from transforms.discrepancy.calibration import mass_gradient

    noise = None
    if nuisance is None and np.any(mass_gradient(None, specs)):
        noise = _mass_noise(specs, mass_term_noise(prepared, rows0, w_rows, settings), Jw, r0, plant.cylinder.mass_kg)
    if nuisance is not None:
        from transforms.discrepancy.calibration import jacobians

        nm, z = nuisance
        _, Jz, _ = jacobians(prepared, nm, z, base, [], rows0, settings, r0)
        ok = np.isfinite(yw) & np.all(np.isfinite(Jw), axis=1)
        before = np.sqrt(np.sum(Jw[ok] ** 2, axis=0))
        yw, Jw = _project_out(Jz * w_rows[:, None], yw, Jw)
        after = np.sqrt(np.sum(Jw[ok] ** 2, axis=0))
        # a candidate the nuisances reproduce (a spool offset is an underlap pattern, a mass change
        # the mass) has nothing left to select on; the verdict weighs it against the priors
        cand = [j for j in cand if after[j] > NUISANCE_COLLINEAR * before[j]]
    patterns = [specs[j] for j in range(len(specs)) if j not in cand]
    st = block_stats(yw, Jw, rows0.block, noise)
    sel: SelectionResult = forward_select(
        st, cand, max_effects=settings.max_effects, min_t_stat=settings.min_t_stat,
        min_relative_gain=settings.min_relative_gain, min_z=settings.min_z,
        positive=frozenset(j for j, spec in enumerate(specs) if spec.lower is not None),
    )
    return rows0, w_rows, sel, sig, patterns


def diagnose(records: list[Record], plant: PlantParams, condition: ValveCondition | None = None, settings: DiscrepancySettings | None = None, *, library: tuple[EffectSpec, ...] = EFFECT_LIBRARY, trace_records: int = 1, monitoring: bool = True, priors: NuisancePriors | None = None) -> Diagnosis:
    """Run steps 1–3 on ``records`` of one valve (module docstring).

    Parameters
    ----------
    records : list of Record
        From :func:`transforms.discrepancy.records.split_records`.
    plant : PlantParams
        The plant's model (its ``sensors.sample_rate_hz`` must be the records').
    condition : ValveCondition, optional
        The valve's condition; default the plant's nominal condition.
    settings : DiscrepancySettings, optional
    library : tuple of EffectSpec
        The candidates (default the whole library).
    trace_records : int
        Keep the replays of this many records (those with the largest gap before) for plots.
    monitoring : bool
        Run step 4 (:func:`monitoring_bias`) with the named effects (with none named, the
        as-recorded and corrected estimates coincide).
    priors : NuisancePriors, optional
        Tolerances of the base model's uncertain parameters (:mod:`transforms.discrepancy.nuisance`):
        they are calibrated on the records with the effects, an effect is selected only on what
        the nuisances cannot explain within their priors, and the verdict weighs an effect against
        the nuisance reading of the same data (:mod:`transforms.discrepancy.verdict`). None or
        :meth:`NuisancePriors.exact`: ``plant`` and ``condition`` are taken as exact (the method
        of before, e.g. after a commissioning calibration).
    """
    from scipy import stats as _stats

    from transforms.discrepancy.calibration import NuisanceModel, calibrate_best, calibrate_prepared, is_sharp, joint_fit, refine_breakaway, sharp_edges_reason
    from transforms.discrepancy.alignment import PRESSURES, align_prepared
    from transforms.discrepancy.transmitter import GAIN_OR_OFFSET, gain_or_offset
    from transforms.discrepancy.verdict import (acting_gap, far_beyond_the_floor, found_nothing, gap_to_replay,
                                               lagging_transmitter, replay_closes, strongest_candidate, unexplained)

    settings = settings or DiscrepancySettings()
    condition = plant.nominal_condition if condition is None else condition
    recorded = records
    records, delays, prepared = align_prepared(records, plant, condition, settings)
    prepared0 = prepared  # the loads of the nominal model
    if not prepared:
        raise ValueError("no record long enough to diagnose")
    base = Effects()
    specs = list(library)
    nominal = (plant, condition)
    nm = None if priors is None or priors.is_exact else NuisanceModel.of(plant, condition, priors)
    z_cal = None
    if nm is not None:
        # calibrate the nuisances (loads from the nominal model), then again on the loads of the
        # calibrated model, each adding the load steps the detector missed (as a commissioning
        # calibration does: a missed step reads as a mass ~500 kg off); the calibrated base model is stage 0
        z_cal = calibrate_best(prepared, nm, settings, split=True)[0].z
        if is_sharp(nm, z_cal):
            # the data show sharp edges, not the configured Eq. 3's: diagnose with that family
            sharp = replace(nominal[0], geometry=replace(nominal[0].geometry, area_law="sharp"))
            d = diagnose(recorded, sharp, nominal[1], settings, library=library, trace_records=trace_records, monitoring=monitoring, priors=priors)
            d.verdict.reason = sharp_edges_reason(nm, z_cal, "diagnosed") + "; " + d.verdict.reason
            return d
        nm = refine_breakaway(prepared, nm, z_cal, settings)
        plant, condition = nm.model(z_cal)
        prepared = prepare_records(records, plant, condition, settings)
        z_cal = calibrate_prepared(prepared, nm, settings, z0=z_cal, split=True)[0].z
        plant, condition = nm.model(z_cal)
    # step 2: the base model's residuals and the library's regressors; the load segments come
    # from the base model's motion equation, which a friction or mass change disturbs (where the
    # inertia mismatch changes fast it can pass for a load step and absorb part of the effect):
    # once effects are named, the load is segmented again with the fitted model and the
    # selection repeated (alternating between the nuisance load and the effects)
    rows0, w_rows, sel, sig, patterns = _select(prepared, plant, condition, specs, settings, None if nm is None else (nm, z_cal))
    floors = noise_floors(prepared, plant, condition, base, settings)

    def refine(named_specs, start):
        """(effects, SEs, stage model) of the named effects fitted (with the nuisances)."""
        if nm is None:
            fx, se_, _ = _refine(prepared, plant, condition, named_specs, start, rows0, w_rows, settings)
            return fx, se_, (plant, condition), None
        jf = joint_fit(prepared, nm, z_cal, named_specs, start, rows0, w_rows, settings)
        return jf.effects, jf.effect_se, nm.model(jf.z), jf

    if sel.named:
        start = base
        for cs in sel.named:
            start = perturbed(start, specs[cs.column], cs.theta)
        fitted, _, (fp, fc), _ = refine([specs[cs.column] for cs in sel.named], start)
        for p in prepared:
            p.seg = _estimate_load(p.rec, fp, fc, fitted, settings)
        if nm is not None:
            z_cal = calibrate_prepared(prepared, nm, settings, z0=z_cal, split=True)[0].z
            plant, condition = nm.model(z_cal)
        rows0, w_rows, sel, sig, patterns = _select(prepared, plant, condition, specs, settings, None if nm is None else (nm, z_cal))
    B = sel.n_blocks
    q = float(_stats.t.ppf(0.5 + settings.ci_level / 2.0, max(B - 1, 1)))
    candidates = []
    for cs in sorted(sel.first_step, key=lambda s: -s.gain):
        spec = specs[cs.column]
        candidates.append({
            "effect": spec.name, "variant": spec.variant, "parameter_name": spec.parameter_name, "parameter_unit": spec.unit,
            "linear_value": cs.theta + spec.neutral, "se": cs.se, "relative_gain": cs.relative_gain, "t_stat": cs.t_stat,
            "z": cs.z, "significant": cs.significant, "column": cs.column,
        })
    # refine the named effects jointly, replay every stage (steps 1 and 3); an effect whose
    # addition does not shrink the replay gap is not confirmed: it and the later ones are dropped
    # and the rest refined again
    named_sel = list(sel.named)
    rival_of = {cs.column: rv for cs, rv in zip(sel.named, sel.rivals)}
    # the base model's replay, and which records to keep for the plots
    acc0, kept0 = _gaps(prepared, plant, condition, base, settings, set(range(len(prepared))))
    per_rec = [
        np.nanmean((kept0[i]["p1"] - p.rec.raw["p1"]) ** 2) / 1e10 + np.nanmean((kept0[i]["p2"] - p.rec.raw["p2"]) ** 2) / 1e10
        + np.nanmean((kept0[i]["X"] - p.rec.raw["X"]) ** 2) / 1e-6
        for i, p in enumerate(prepared)
    ]
    kept_idx = set(np.argsort(per_rec)[::-1][:trace_records].tolist())
    unconfirmed: list[int] = []
    while True:
        named_specs = [specs[cs.column] for cs in named_sel]
        stage_effects = [base]
        refined, se, stage_model, final_fit = base, np.zeros(0), (plant, condition), None
        if named_specs:
            start = base
            for spec, cs in zip(named_specs, named_sel):
                start = perturbed(start, spec, cs.theta)
            refined, se, stage_model, final_fit = refine(named_specs, start)
            cur = base
            for spec in named_specs:
                cur = replace(cur, **{spec.attribute: spec.value(refined)})
                stage_effects.append(cur)
        stage_acc = [acc0]
        kept_all = [{i: kept0[i] for i in kept_idx}]
        drop = None
        for k, fx in enumerate(stage_effects[1:], start=1):
            acc, kept = _gaps(prepared, *stage_model, fx, settings, kept_idx)
            kind = acting_gap(named_specs[k - 1])
            if not acc.split_gap(kind) < stage_acc[-1].split_gap(kind):
                drop = k - 1
                break
            stage_acc.append(acc)
            kept_all.append(kept)
        if drop is None:
            break
        unconfirmed += [cs.column for cs in named_sel[drop:]]
        named_sel = named_sel[:drop]
    stage_gaps = [a.gap() for a in stage_acc]
    named = []
    for k, (spec, cs) in enumerate(zip(named_specs, named_sel)):
        val = spec.value(refined)
        rcol, rt = rival_of.get(cs.column, (None, float("inf")))
        named.append(NamedEffect(
            alternative=specs[rcol] if (rcol is not None and rt < AMBIGUITY_T) else None, alternative_t=rt,
            rank=k + 1, spec=spec, value=val, ci_low=val - q * float(se[k]), ci_high=val + q * float(se[k]),
            linear_value=cs.theta + spec.neutral, relative_gain=cs.relative_gain, t_stat=cs.t_stat, z=cs.z,
            gap_before=stage_gaps[k], gap_after=stage_gaps[k + 1], gap_kind=acting_gap(spec),
            acting_before=stage_acc[k].split_gap(acting_gap(spec)), acting_after=stage_acc[k + 1].split_gap(acting_gap(spec)),
            floor=floors[acting_gap(spec)],
        ))
    for c in candidates:
        c["unconfirmed"] = c.pop("column") in unconfirmed
    gap_rows = []
    for k, acc in enumerate(stage_acc):
        for row in acc.rows():
            gap_rows.append({"stage": k, **row})
    residual_rows = [{"stage": 0, **r} for r in _residual_summary(prepared, plant, condition, base, settings)]
    if len(stage_effects) > 1:
        residual_rows += [{"stage": len(stage_effects) - 1, **r} for r in _residual_summary(prepared, *stage_model, stage_effects[-1], settings)]
    traces = []
    for i in sorted(kept_all[0]):
        p = prepared[i]
        traces.append(ReplayTrace(
            record_index=i, start_us=p.rec.start_us, t=p.rec.t,
            measured={"p1": p.rec.raw["p1"], "p2": p.rec.raw["p2"], "X": p.rec.raw["X"]},
            replayed={f"stage{k}_{s}": kept_all[k][i][s] for k in range(len(stage_effects)) for s in ("p1", "p2", "X")},
        ))
    mon = monitoring_bias([p.rec for p in prepared], *stage_model, stage_effects[-1], settings.window_s) if monitoring else []
    verdict = None
    gap_nominal = stage_gaps[0]
    if nm is not None:
        from transforms.discrepancy.verdict import against_patterns, beyond_selection, nuisance_scores, nuisance_verdict

        if final_fit is None:
            final_fit = joint_fit(prepared, nm, z_cal, [], base, rows0, w_rows, settings, iterations=0)
        def gap_of(fx, model):
            return _gaps(prepared, *model, fx, settings, set())[0]

        verdict = nuisance_verdict(prepared, nm, final_fit, named_specs, specs, rows0, w_rows, settings, named, gap_of, stage_gaps[0], floors, stage_acc)
        if named and (not named[0].confirmed or patterns):
            base_fit = joint_fit(prepared, nm, z_cal, [], base, rows0, w_rows, settings, iterations=0)

            def judged(rest, scores=None):
                """The readings of ``rest`` against the calibrated base model, judged as where nothing was selected."""
                return nuisance_verdict(prepared, nm, base_fit, [], rest, rows0, w_rows, settings, [], gap_of, stage_gaps[0], floors, stage_acc, scores)

            if not named[0].confirmed:
                # the selection's effect does not close its gap: the other candidates' readings (verdict.beyond_selection)
                verdict = beyond_selection(verdict, judged([s for s in specs if s != named[0].spec]))
            else:
                # the candidates the selection could not score, by their priors (verdict.against_patterns)
                rest = [named[0].spec] + patterns
                scores = nuisance_scores(nm, base_fit, [], rest, rows0, w_rows, settings, prepared)
                verdict = against_patterns(verdict, scores, lambda: judged(rest, scores))
        for p, p0 in zip(prepared, prepared0):  # the same records (prepare_records keeps or drops a record by its length)
            p.loads.setdefault((*nominal, base), p0.base_load)
        gap_nominal = _gaps(prepared, *nominal, base, settings, set(), split=False)[0].gap()
    elif named and not named[0].confirmed:
        first = named[0]
        verdict = unexplained(first.spec, first.value, first.acting_before, first.acting_after, first.gap_kind, stage_acc[1], first.floor)
    if named and (verdict is None or verdict.verdict == "named") and named[0].spec.name in GAIN_OR_OFFSET:
        def alone(spec, value):
            """(value, model) of ``spec`` alone on the rows: the base model, or with the nuisances jointly."""
            if nm is None:
                return value, (plant, condition)
            fx, _, model, _ = refine([spec], perturbed(base, spec, value - spec.neutral))
            return spec.value(fx), model

        verdict = gain_or_offset(prepared, named[0], alone, settings, verdict)
    lag = delays.finding()
    if lag:  # a transmitter lagging the others: a finding of its own (aligned for, not absorbed)
        verdict = lagging_transmitter(verdict, bool(named), lag, stage_acc[0].split_gap("hydraulic"), floors["hydraulic"])
    top = max(sel.first_step, key=lambda c: c.gain, default=None)
    top_spec = specs[top.column] if top is not None else None
    kind = gap_to_replay(top_spec, stage_acc[0], floors) if top is not None else None
    if (kind is not None and found_nothing(verdict, bool(named)) and top.gain > 0.0
            and (top_spec.lower is None or top_spec.neutral + top.theta > top_spec.lower)):
        # nothing stood out, yet the gap where the equations' strongest (physical) candidate acts
        # lies far beyond its floor: that candidate, fitted (with the nuisances), replayed on that
        # gap (verdict.replay_closes)
        fx, _, model, _ = refine([top_spec], perturbed(base, top_spec, top.theta))
        acc = _gaps(prepared, *model, fx, settings, set())[0]
        verdict = replay_closes(verdict, bool(named), top_spec, top_spec.value(fx), top.t_stat, floors[kind], stage_acc[0].split_gap(kind),
                                acc.split_gap(kind), stage_gaps[0], acc.gap())
    verdict = far_beyond_the_floor(verdict, bool(named), stage_acc[0], floors, strongest_candidate(candidates, settings.min_t_stat))
    return Diagnosis(
        n_records=len(prepared), records=[(p.rec.start_us, p.rec.end_us) for p in prepared], named=named,
        candidates=candidates, gap_rows=gap_rows, residual_rows=residual_rows, stage_effects=stage_effects,
        stage_gaps=stage_gaps, traces=traces, n_blocks=B, equation_sigmas=tuple(float(s) for s in sig),
        monitoring=mon, verdict=verdict, gap_nominal=gap_nominal, model=stage_model, noise_floors=floors,
        split_gaps=[{k: a.split_gap(k) for k in ("hydraulic", "mechanical")} for a in stage_acc], pressure_delay_samples=delays.shared,
        pressure_delays={c: delays.of(c) for c in PRESSURES}, lag_finding=lag,
        position_noise=pooled_noise(prepared, ("x", "X")), spool_reconstructed=sum("x" in p.rec.pos for p in prepared),
    )


# --- step 4: what the effect did to monitoring ----------------------------------------------

NOMINAL_GRID_STEP_M = 0.05e-3
"""Knot spacing of the nominal characteristic (as ``flows.monitor.flow``)."""
SENSOR_ATTRIBUTES = ("spool_sensor_offset_m", "p1_sensor_offset_pa", "p2_sensor_offset_pa", "p1_sensor_gain", "p2_sensor_gain")
MOTION_ATTRIBUTES = ("delta_viscous_friction_n_s_m", "delta_mass_kg")


def monitor_params_for(plant: PlantParams, condition: ValveCondition, sample_period_s: float):
    """The monitoring's view (:class:`transforms.params.MonitorParams`) of the plant model."""
    from transforms.params import MonitorParams

    c, f = plant.cylinder, plant.fluid
    return MonitorParams.from_design(
        piston_diameter_m=c.piston_diameter_m, rod_diameter_m=c.rod_diameter_m, v01_m3=c.v01_m3, v02_m3=c.v02_m3,
        bulk_modulus_pa=f.bulk_modulus_pa, density_kg_m3=f.density_kg_m3, underlap_m=condition.underlap_m,
        x_max_m=plant.geometry.x_max_m, sample_period_s=sample_period_s,
    )


def nominal_baselines(plant: PlantParams, condition: ValveCondition, x_hat_bound_m: float) -> dict:
    """α·A(u) of Eq. 3 per edge for ``condition`` (the monitoring's nominal baseline)."""
    from model.area import edge_area
    from model.params import EDGES
    from transforms.characteristic import Characteristic

    g = plant.geometry
    u = np.arange(-g.x_max_m, g.x_max_m + x_hat_bound_m + NOMINAL_GRID_STEP_M / 2, NOMINAL_GRID_STEP_M)
    x_l = condition.x_l_m(g)
    out = {}
    for i, e in enumerate(EDGES):
        a = edge_area(u, condition.underlap_m[i], g.taper_angle(e), g.bore_radius_m, g.spool_radius_m, x_l[i])
        out[e] = Characteristic.from_arrays(u, condition.alpha[i] * a)
    return out


def _lake_frame(records: list[Record], effects: Effects | None = None):
    """The records as lake rows; with ``effects`` the sensor effects inverted (true x, p1, p2)."""
    import polars as pl

    frames = []
    for rec in records:
        x, p1, p2 = true_signals(rec.raw["x"], rec.raw["p1"], rec.raw["p2"], effects)
        ts = rec.start_us + np.round(np.arange(rec.n) * rec.dt * 1e6).astype(np.int64)
        frames.append(pl.DataFrame({
            "valve_id": [rec.valve_id] * rec.n,
            "timestamp_utc": pl.Series(ts).cast(pl.Datetime("us", "UTC")),
            "ps_pa": rec.raw["ps"], "pr_pa": rec.raw["pr"], "p1_pa": p1, "p2_pa": p2,
            "x_spool_m": x, "x_cyl_m": rec.raw["X"],
        }))
    return pl.concat(frames)


def _flow_corrected_points(points, records: list[Record], plant, condition, effects: Effects):
    """Eq. 7 points with the flow effects of ``effects`` accounted for: the chamber flow gets
    the leakage and entrained-air terms, the supply edges the pressure at the valve."""
    import polars as pl

    from model.effects import AIR_POLYTROPIC_EXPONENT, P_ATM_PA

    if points.height == 0:
        return points
    ts = points["timestamp_utc"].cast(pl.Datetime("us", "UTC")).to_physical().to_numpy()
    edge = points["edge"].to_numpy()
    area = points["area_m2"].to_numpy().copy()
    starts = np.array([r.start_us for r in records])
    ends = np.array([r.end_us for r in records])
    ri = np.searchsorted(starts, ts, side="right") - 1
    k = 0.5 * plant.fluid.density_kg_m3  # (ρ/2)
    c = plant.cylinder
    for r in np.unique(ri):
        if r < 0:
            continue
        rec = records[r]
        sel = (ri == r) & (ts <= ends[r])
        idx = np.round((ts[sel] - rec.start_us) * 1e-6 / rec.dt).astype(np.int64)
        _, p1, p2 = true_signals(rec.sg["x"][idx], rec.sg["p1"][idx], rec.sg["p2"][idx], effects)
        dp1 = rec.sg["dp1"][idx] / effects.p1_sensor_gain
        dp2 = rec.sg["dp2"][idx] / effects.p2_sensor_gain
        X = rec.raw["X"][idx]
        ps, pr = rec.raw["ps"][idx], rec.raw["pr"][idx]
        x_true = rec.raw["x"][idx] - effects.spool_sensor_offset_m
        V1, V2 = c.v01_m3 + c.A1 * X, c.v02_m3 - c.A2 * X

        def h(p):
            pa = np.maximum(p + P_ATM_PA, 0.1 * P_ATM_PA)
            return (P_ATM_PA / pa) ** (1.0 / AIR_POLYTROPIC_EXPONENT) / (AIR_POLYTROPIC_EXPONENT * pa)

        qi = effects.internal_leakage_m3_s_pa * (p1 - p2)
        dq1 = qi + effects.air_fraction * V1 * h(p1) * dp1
        dq2 = qi - effects.external_leakage_m3_s_pa * p2 - effects.air_fraction * V2 * h(p2) * dp2
        _, _, psv = valve_flows_for(x_true, p1, p2, ps, pr, plant, condition, effects)
        e = edge[sel]
        dp_old = np.select([e == "s1", e == "1r", e == "s2"], [ps - p1, pr - p1, p2 - ps], p2 - pr)
        dp_new = np.select([e == "s1", e == "1r", e == "s2"], [psv - p1, pr - p1, p2 - psv], p2 - pr)
        ss_old = np.sign(dp_old) * np.sqrt(np.abs(dp_old))
        ss_new = np.sign(dp_new) * np.sqrt(np.abs(dp_new))
        flow = area[sel] * ss_old / np.sqrt(k)  # the chamber flow Eq. 7 assumed through the edge
        flow = flow + np.where((e == "s1") | (e == "1r"), dq1, dq2)
        area[sel] = np.sqrt(k) * flow / ss_new
    return points.with_columns(pl.Series("area_m2", area))


def valve_flows_for(x, p1, p2, ps, pr, plant, condition, effects):
    from model.effects import valve_flows

    return valve_flows(x, p1, p2, ps, pr, plant, condition, effects, DEFAULT_REG_BAND_PA)


MONITORING_SUMMARY_COLUMNS = ("edge", "n_windows", "alpha_hat_recorded", "alpha_hat_corrected", "x_hat_m_recorded", "x_hat_m_corrected", "e_m2_recorded", "e_m2_corrected")


def monitoring_bias(records: list[Record], plant: PlantParams, condition: ValveCondition | None, effects: Effects, window_s: float | None = None) -> list[dict]:
    """Step 4: the monitoring (steps 2–4b, ``transforms.monitor``) on the records as recorded and
    with ``effects`` accounted for, against the nominal baseline of ``condition``.

    Accounting for the effects: the sensor effects are inverted on the signals before the
    monitoring runs (exact); leakage and entrained air are added to the chamber flow of each Eq. 7
    point and a supply line replaces p_s by the pressure at the valve (exact for the points
    step 3 selects); friction and mass changes do not enter Eq. 7, so they leave the estimates
    unbiased. The windows are the monitor's with length ``window_s`` (``[monitor] window_s``;
    None: whole runs), so back-to-back records of one clock window are monitored as the
    monitor does. Returns one dict per edge: the median over windows (status ``ok``) of α̂, x̂ and e,
    as recorded and corrected (:data:`MONITORING_SUMMARY_COLUMNS`)."""
    from transforms.fit import fit_windows
    from transforms.monitor import monitor, monitor_points

    condition = plant.nominal_condition if condition is None else condition
    if not records:
        return []
    vid = records[0].valve_id
    mp = replace(monitor_params_for(plant, condition, records[0].dt), window_s=window_s)
    base = {vid: nominal_baselines(plant, condition, mp.x_hat_bound_m)}
    recorded = monitor(_lake_frame(records), mp, base).fits
    sensor = any(getattr(effects, a) != getattr(Effects(), a) for a in SENSOR_ATTRIBUTES)
    res = monitor_points(_lake_frame(records, effects if sensor else None), mp)
    points = res.points
    if effects.has_flow_terms:
        points = _flow_corrected_points(points, records, plant, condition, effects)
    corrected = fit_windows(points, base, {vid: mp}, windows=res.windows)
    out = []
    for e in ("s1", "1r", "s2", "2r"):
        a = recorded.filter((recorded["edge"] == e) & (recorded["status"] == "ok"))
        b = corrected.filter((corrected["edge"] == e) & (corrected["status"] == "ok"))

        def med(frame, col):
            return float(frame[col].median()) if frame.height else float("nan")

        out.append({
            "edge": e, "n_windows": int(min(a.height, b.height)),
            "alpha_hat_recorded": med(a, "alpha_hat"), "alpha_hat_corrected": med(b, "alpha_hat"),
            "x_hat_m_recorded": med(a, "x_hat_m"), "x_hat_m_corrected": med(b, "x_hat_m"),
            "e_m2_recorded": med(a, "e_m2"), "e_m2_corrected": med(b, "e_m2"),
        })
    return out


# --- the valve's own condition from its commissioning window --------------------------------

CONDITION_FD = (1.0e-3, 1.0e-7)
"""Finite-difference steps of the condition fit: relative α change, underlap change [m]."""


@dataclass(frozen=True)
class ConditionFit:
    """The valve condition identified on commissioning records.

    Attributes
    ----------
    condition : ValveCondition
        α and underlap per edge (EDGES order).
    alpha_se, underlap_se_m : tuple of 4 float
        Jackknife standard errors (over 1 s blocks).
    gap_design, gap_fitted : float
        Normalised replay gap of the commissioning records with the start and the fitted
        condition.
    n_records : int
    reason : str
        What the calibration found about the model itself (e.g. sharp edges where Eq. 3 is
        configured: :attr:`transforms.discrepancy.calibration.Calibration.reason`); empty if nothing.
    """

    condition: ValveCondition
    alpha_se: tuple[float, float, float, float]
    underlap_se_m: tuple[float, float, float, float]
    gap_design: float
    gap_fitted: float
    n_records: int
    reason: str = ""


def _with_condition_params(cond: ValveCondition, z: np.ndarray) -> ValveCondition:
    """z = (α scale − 1 per edge, underlap change per edge [m]) applied to ``cond``."""
    return ValveCondition(
        underlap_m=tuple(u + d for u, d in zip(cond.underlap_m, z[4:])),
        alpha=tuple(a * (1.0 + s) for a, s in zip(cond.alpha, z[:4])),
        x_l_fraction=cond.x_l_fraction,
    )


def fit_condition(records: list[Record], plant: PlantParams, start: ValveCondition | None = None, settings: DiscrepancySettings | None = None, iterations: int = 8) -> ConditionFit:
    """Identify the valve's condition -- contraction coefficient and underlap of every edge, the
    quantities the monitoring tracks -- on commissioning records by Gauss–Newton on the same
    integrated residuals the effect selection uses (base model, no library effect).

    The discrepancy workflow then judges later data against *this* valve (design data plus its
    manufacturing deviations), so a deviation present since commissioning is not taken for a
    library effect. (A spool sensor offset is the same as a pattern of underlap changes
    (−, +, +, −) and a pressure transmitter error acts on the flows like α changes: what is there
    at commissioning becomes part of the valve's condition; what develops later is found.)"""
    settings = settings or DiscrepancySettings()
    cond0 = plant.nominal_condition if start is None else start
    prepared = prepare_records(records, plant, cond0, settings)
    if not prepared:
        raise ValueError("no commissioning record long enough")
    base = Effects()
    rows0 = _rows(prepared, plant, cond0, base, settings)
    sig = _equation_sigmas(_eliminate_load(rows0.y, rows0), rows0)
    w = 1.0 / sig[rows0.eq]
    z = np.zeros(8)
    steps = np.array([CONDITION_FD[0]] * 4 + [CONDITION_FD[1]] * 4)
    cont = rows0.eq < 2  # the condition enters the chamber equations only

    def resid(zz):
        return _rows(prepared, plant, _with_condition_params(cond0, zz), base, settings).y

    J = None
    for _ in range(iterations):
        r = resid(z)
        J = np.column_stack([(resid(z + np.eye(8)[j] * steps[j]) - r) / steps[j] for j in range(8)])
        ok = cont & np.isfinite(r) & np.all(np.isfinite(J), axis=1)
        Jw, rw = J[ok] * w[ok, None], r[ok] * w[ok]
        sc = np.sqrt(np.mean(Jw * Jw, axis=0))
        sc = np.where(sc > 0, sc, 1.0)
        dz, *_ = np.linalg.lstsq(Jw / sc, -rw, rcond=None)
        dz = dz / sc
        z = z + dz
        if np.all(np.abs(dz[:4]) < 1e-5) and np.all(np.abs(dz[4:]) < 1e-9):
            break
    r = resid(z)
    sel = cont & np.isfinite(r) & np.all(np.isfinite(J), axis=1)
    st = block_stats((-r * w)[sel], (J * w[:, None])[sel], rows0.block[sel])
    _, _, loo = cv_losses(st, list(range(8)))
    B = loo.shape[0]
    se = np.sqrt((B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0)) / st.scale if B > 1 else np.full(8, np.inf)
    cond = _with_condition_params(cond0, z)
    g0 = _gaps(prepared, plant, cond0, base, settings, set(), split=False)[0].gap()
    fresh = prepare_records(records, plant, cond, settings)
    g1 = _gaps(fresh, plant, cond, base, settings, set(), split=False)[0].gap()
    return ConditionFit(
        condition=cond, alpha_se=tuple(float(a) for a in se[:4] * np.array(cond0.alpha)),
        underlap_se_m=tuple(float(u) for u in se[4:]), gap_design=g0, gap_fitted=g1, n_records=len(prepared),
    )

"""A pressure transmitter's gain error or its offset: told apart on the hydraulic replay, or ambiguous.

A gain error's reading error grows with the pressure, an offset's does not; over a narrow pressure
range the two look alike. The integrated chamber equations (the selection's rows) can also bias a
gain: on the reference plant (seed 1, with commissioning, p1 at 35–49 bar) a true p1 gain of 0.97
came out 0.982 on the rows, which replays the hydraulic gap to 0.355, where 0.97 replays it to the
floor's level (0.0675); the rows then preferred a −1.29 bar offset (0.107), and a true +2 bar
offset was read as a gain of 1.046 (0.152, the offset 0.0675). So both readings of a named
transmitter are fitted on the hydraulic replay itself (p1, p2 replayed on the recorded spool,
supply, return and cylinder motion: no load, mass or friction; one parameter each, the base model
otherwise as it is) and compared there (:func:`gain_or_offset`). Where the two replay alike, the
replay orders them only if it prefers one beyond its noise (:func:`replay_preference`); else the
rows' reading stays first.
"""

from __future__ import annotations

import numpy as np

from model.effects import Effects, EffectSpec, library_entry
from transforms.discrepancy.rows import hydraulic_gap, hydraulic_readings, perturbed

__all__ = ["GAIN_OR_OFFSET", "PRESSURE_SPAN", "TOLD_APART", "gain_or_offset", "replay_fit", "replay_preference"]

GAIN_OR_OFFSET = ("pressure_sensor_offset", "pressure_sensor_gain")
PRESSURE_SPAN = 2.0
"""Where a transmitter's pressure spans this factor (5th to 95th percentile), a gain error and an
offset of it have clearly different shapes: the named one must replay ``TOLD_APART`` better than the
other, or the verdict is ambiguous."""
TOLD_APART = 1.25
"""Told apart: the other reading's hydraulic gap (each fitted on the replay) is at least this factor larger."""
FIT_RANGE = 3.0
"""The replay fit searches the parameter within neutral ± this × max(|guess − neutral|, typical)."""
FIT_TOLERANCE = 1.0e-3
"""... to this fraction of the typical magnitude."""


def replay_fit(prepared, plant, condition, spec: EffectSpec, guess: float, settings) -> tuple[float, float]:
    """(value, hydraulic gap) of ``spec`` (a transmitter's gain or offset) alone fitted on the hydraulic replay of ``prepared``
    against ``plant``, ``condition`` (bounded Brent search around ``guess``; the gap is a smooth,
    single-minimum function of a transmitter's gain or offset). [spec.unit], [–]"""
    from scipy.optimize import minimize_scalar

    half = FIT_RANGE * max(abs(guess - spec.neutral), spec.typical)

    def gap(v: float) -> float:
        return hydraulic_gap(prepared, plant, condition, perturbed(Effects(), spec, v - spec.neutral), settings)

    r = minimize_scalar(gap, bounds=(spec.neutral - half, spec.neutral + half), method="bounded", options={"xatol": FIT_TOLERANCE * spec.typical})
    return float(r.x), float(r.fun)


def _squared_errors(prepared, plant, condition, spec: EffectSpec, value: float, settings) -> list[np.ndarray]:
    """Per record, (e_p1² + e_p2²) of the hydraulic replay with ``spec`` at ``value`` at every
    sample (NaN outside the replayed region). [Pa²]"""
    fx = perturbed(Effects(), spec, value - spec.neutral)
    out = []
    for p in prepared:
        e1, e2 = (rep - p.rec.raw[k] for k, rep in zip(("p1", "p2"), hydraulic_readings(p, plant, condition, fx, settings)))
        out.append(np.where(p.regions["all"], e1**2 + e2**2, np.nan))
    return out


def replay_preference(prepared, a: tuple, b: tuple, settings) -> float:
    """t of the hydraulic replay's preference for reading ``b`` over ``a`` (each (plant, condition,
    spec, value)): the per-sample difference of their squared errors (:func:`_squared_errors`),
    summed over blocks of ``settings.block_s`` (the replay's errors are correlated within a block,
    nearly independent between them), its mean over the blocks' scatter, as the selection's
    cross-validation pairs its blocks. > 0 where ``b`` replays better. [–]"""
    sums = []
    for p, sa, sb in zip(prepared, _squared_errors(prepared, *a, settings), _squared_errors(prepared, *b, settings)):
        d = sa - sb
        ok = np.isfinite(d)
        block = np.arange(d.size)[ok] // max(1, int(round(settings.block_s / p.rec.dt)))
        _, inv = np.unique(block, return_inverse=True)
        sums.append(np.bincount(inv, weights=d[ok]))
    d = np.concatenate(sums) if sums else np.zeros(0)
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    return float(np.mean(d) / (sd / np.sqrt(d.size))) if sd > 0.0 else 0.0


def _model(alone, spec: EffectSpec, value: float) -> tuple:
    """(plant, condition, spec, value) of ``alone`` (:func:`gain_or_offset`), for :func:`replay_fit`."""
    v, (plant, condition) = alone(spec, value)
    return plant, condition, spec, v


def other_reading(spec: EffectSpec) -> EffectSpec:
    """The same transmitter's other reading (gain for an offset and back)."""
    name = "pressure_sensor_gain" if spec.name == "pressure_sensor_offset" else "pressure_sensor_offset"
    return library_entry(f"{name}[{spec.variant}]")


def gain_or_offset(prepared, first, alone, settings, verdict):
    """The verdict for a named pressure transmitter offset or gain (``first``, a
    :class:`~transforms.discrepancy.pipeline.NamedEffect` of ``GAIN_OR_OFFSET``): it and the same
    transmitter's other reading are each fitted on the hydraulic replay (:func:`replay_fit`), from
    ``alone(spec, value)`` = (value, (plant, condition)): the reading fitted alone on the equation
    rows and the model it leaves (with free nuisances their joint fit, which holds what the
    calibrated base model had absorbed of the effect; the model taken as exact: that model).

    * The named one replays ``TOLD_APART`` better: ``verdict`` kept, the comparison added to its reason.
    * The replay prefers the other reading (the rows and the replay disagree), or the pressure spans
      ``PRESSURE_SPAN`` and the two are less than ``TOLD_APART`` apart: ``ambiguous``, both listed;
      first the other where the replay prefers it at t ≥ ``verdict.Z_AMBIGUOUS``
      (:func:`replay_preference`), else the named one (at the noisy end of plant sensors the replay
      preferred the wrong one by 0.5–1.6 % of its gap in four runs where the rows had it right).
    * Otherwise (the named one replays better, by less than ``TOLD_APART``, over a narrow pressure
      range where the two shapes hardly differ): ``verdict`` kept.

    Returns the verdict (``None`` stays ``None`` where kept: the model taken as exact)."""
    from transforms.discrepancy.verdict import SEPARATE_BY, Z_AMBIGUOUS, Verdict

    v = first.spec.variant
    p = np.concatenate([q.rec.raw[v] for q in prepared])
    lo, hi = np.nanpercentile(p, [5, 95])
    spans = bool(lo > 0 and hi >= PRESSURE_SPAN * lo)
    other = other_reading(first.spec)
    mean = float(np.nanmean(p))
    guess = (first.value - 1.0) * mean if other.name == "pressure_sensor_offset" else 1.0 + first.value / mean  # same reading at the mean
    m_first, m_other = _model(alone, first.spec, first.value), _model(alone, other, guess)
    v_first, g_first = replay_fit(prepared, *m_first, settings)
    v_other, g_other = replay_fit(prepared, *m_other, settings)
    span = f"{v} spans {lo / 1e5:.3g}–{hi / 1e5:.3g} bar"
    fitted = f"each fitted on the hydraulic replay: {first.spec.key} {v_first:.4g} leaves {g_first:.3g}, {other.key} {v_other:.4g} leaves {g_other:.3g}"
    if g_other >= TOLD_APART * g_first or (g_first <= g_other and not spans):
        if verdict is not None:
            verdict.reason += (f"; told from {other.key} ({span}; {fitted})" if g_other >= TOLD_APART * g_first else
                               f"; the replay prefers it to {other.key}, by less than {TOLD_APART:g}× over a narrow range ({span}; {fitted})")
        return verdict
    t = replay_preference(prepared, m_first[:3] + (v_first,), m_other[:3] + (v_other,), settings)
    readings = [(g_first, first.spec, v_first), (g_other, other, v_other)]
    (gb, sb, vb), (gw, sw, vw) = readings[::-1] if t >= Z_AMBIGUOUS else readings
    why = (f"the equations read {first.spec.key}, the replay {other.key} at t = {t:.2g}" if t >= Z_AMBIGUOUS else
           f"less than {TOLD_APART:g}× apart, the replay's preference t = {t:.2g}: the equations' reading first")
    return Verdict(
        "ambiguous", float(min(0.999, gw / (gb + gw))), sb, vb, alternatives=[f"{sw.key} {sw.parameter_name}={vw:.4g} {sw.unit}"],
        alternative_keys=[sw.key], separate_by=SEPARATE_BY["pressure_sensor_gain"],
        reason=f"{sb.key} and {sw.key} are not told apart ({span}; {fitted}: {why})",
        nuisances=verdict.nuisances if verdict is not None else [], scores=verdict.scores if verdict is not None else [],
        gap_before=first.gap_before, gap_after=first.gap_after)

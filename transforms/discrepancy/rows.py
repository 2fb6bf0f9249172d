"""The machinery of one model on prepared records: loads, residual rows and their derivatives, replays
and gaps (steps 1 and 2 of :mod:`transforms.discrepancy.pipeline`, which runs them; also used by
:mod:`transforms.discrepancy.calibration`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from model.effects import Effects, EffectSpec, equation_terms, pressure_readings, true_signals
from model.params import PlantParams, ValveCondition
from model.replay import DRIVE_HYDRAULIC, DRIVE_MECHANICAL, replay
from model.simulate import DEFAULT_REG_BAND_PA
from transforms.discrepancy.gaps import GAP_SCALES, RECORDED_OF, GapAccumulator
from transforms.discrepancy.load import LoadEstimate, away_from_steps, box_half_widths, box_within, estimate_load, load_valid, second_difference_energy, load_projector, friction_within, motion_mismatch, interval_load, project_out, replay_load, robust_sigma, stuck_spans
from transforms.discrepancy.records import REGIONS, Record, operating_regions, prepare_record
from transforms.discrepancy.residuals import (
    box_at,
    demean_by_group,
    interval_edges,
    interval_residuals,
    pointwise_residuals,
    triangular_force_balance,
)
from transforms.discrepancy.settings import DiscrepancySettings

EQUATIONS = ("chamber1", "chamber2", "motion")
FD_FRACTION = 0.01
"""Finite-difference step of the regressors: this fraction of the candidate's typical magnitude."""
RECORD_STRIDE = 100000
"""Block and group ids of record i are offset by i × this (:class:`_Rows`)."""


def perturbed(effects: Effects, spec: EffectSpec, delta: float) -> Effects:
    """``effects`` with the candidate's parameter moved by ``delta``."""
    return replace(effects, **{spec.attribute: spec.value(effects) + delta})


@dataclass
class _Prepared:
    rec: Record
    regions: dict[str, np.ndarray]
    edges: np.ndarray
    base_model: tuple  # (plant, condition, settings) of the base load (:attr:`base_load`)
    loads: dict = field(default_factory=dict)  # (plant, condition, Effects) -> LoadEstimate of that model
    seg: LoadEstimate | None = None  # the load segments of the regression (default base_load)

    @property
    def base_load(self) -> LoadEstimate:
        """The base model's load (no effects), estimated on first use: the pressure delays are
        measured on the hydraulic replay, which no load enters."""
        plant, condition, settings = self.base_model
        return _load_estimate_for(self, plant, condition, Effects(), settings)

    @property
    def segmentation(self) -> LoadEstimate:
        return self.base_load if self.seg is None else self.seg


def prepare_records(records: list[Record], plant: PlantParams, condition: ValveCondition, settings: DiscrepancySettings) -> list[_Prepared]:
    """Savitzky–Golay values, operating regions, interval edges (the base model's load on first
    use, :attr:`_Prepared.base_load`)."""
    out = []
    h = settings.savgol_window // 2
    k = settings.interval_smoothing // 2
    for rec in records:
        prepare_record(rec, settings, plant.spool)
        sg = rec.sg
        regions = operating_regions(sg["v"], sg["p1"], sg["p2"], sg["ps"], settings)
        edges = interval_edges(rec.n - max(h, k), settings.interval_samples, max(h, k))
        if edges.size < 4:
            continue
        out.append(_Prepared(rec, regions, edges, (plant, condition, settings)))
    return out


def _signals(rec: Record, smooth: bool) -> dict:
    src = rec.sg if smooth else rec.raw
    x = rec.sg["x"] if smooth else rec.position("x")
    return {"x": x, "p1": src["p1"], "p2": src["p2"], "ps": src["ps"], "pr": src["pr"], "X": rec.position("X"), "v": rec.sg["v"]}


def _terms_raw(rec, plant, condition, effects):
    return equation_terms(_signals(rec, False), plant, condition, effects, DEFAULT_REG_BAND_PA)


def _terms_sg(rec, plant, condition, effects):
    return equation_terms(_signals(rec, True), plant, condition, effects, DEFAULT_REG_BAND_PA)


def _force_balance(rec: Record, plant, condition, effects, settings) -> np.ndarray:
    t = _terms_raw(rec, plant, condition, effects)
    return triangular_force_balance(t["force"], rec.position("X"), t["mass"], rec.dt, settings.interval_samples)


def _load_motion(rec: Record, settings) -> tuple[np.ndarray, np.ndarray]:
    """(v_X [m/s], the acceleration averaged as in the force balance, (X₊ − 2X + X₋)/(L T)²
    [m/s²]): the columns of a friction and a mass mismatch in the load fit."""
    L = settings.interval_samples
    X = rec.position("X")
    a = np.full(X.size, np.nan)
    if X.size > 2 * L:
        a[L:-L] = (X[2 * L:] - 2.0 * X[L:-L] + X[:-2 * L]) / (L * rec.dt) ** 2
    return rec.sg["v"], a


def _accel_noise(rec: Record, half_widths: np.ndarray, settings) -> np.ndarray:
    """The noise variance [m²/s⁴] the recorded X's noise (white, at the record's estimated RMS)
    leaves in :func:`_load_motion`'s acceleration averaged over 2·``half_widths`` + 1 shifts at
    each sample (:func:`box_within`; 0 where X is reconstructed: its error is not white)."""
    L = settings.interval_samples
    ss, count = rec.noise["X"]
    if "X" in rec.pos or not count:
        return np.zeros(rec.n)
    energy = np.array([second_difference_energy(L, int(k)) for k in range(int(half_widths.max()) + 1)])
    return (ss / count) * energy[half_widths] / (L * rec.dt) ** 4


def _load_inputs(rec: Record, plant, condition, effects, settings) -> tuple:
    """(the force balance F̂_l [N], the equation terms (Savitzky–Golay), v_X [m/s], the
    acceleration [m/s²], :func:`_load_motion`) a record's load is estimated from."""
    return (_force_balance(rec, plant, condition, effects, settings), _terms_sg(rec, plant, condition, effects)) + _load_motion(rec, settings)


def _fit_load(rec: Record, load: LoadEstimate, inputs: tuple, plant, settings) -> LoadEstimate:
    """``load`` (its steps and knots) with its values, and the friction and mass it leaves
    (:func:`motion_mismatch`), fitted on the force balance of ``inputs`` (:func:`_load_inputs`)
    averaged as the motion rows are (:func:`box_within`): the second difference of X carries ~370 N
    of a 10 µm position noise on the reference plant, the average ~80 N, and the acceleration's
    noise that reads as a lighter mass falls 22× (:func:`second_difference_energy`); the fit
    corrects for the rest."""
    f_hat, t, v, a = inputs
    half = settings.interval_smoothing // 2
    a_ok = load_valid(a, v, settings)
    f_avg, a_avg = box_within(f_hat, load_valid(f_hat, v, settings), half), box_within(a, a_ok, half)
    load = load.refit(f_avg, (v, a_avg))
    noise = _accel_noise(rec, box_half_widths(a_ok, half), settings)
    dv, dm = motion_mismatch(f_avg, load.load, load.usable, (v, a_avg), (noise, t["mass"]))
    load = replace(load, friction_mismatch=dv, mass_mismatch=dm)
    d_v = plant.cylinder.d_v_n_s_m
    return friction_within(load, v, settings.mechanical_friction_rel * d_v, settings.load_friction_rel * d_v)


def _estimate_load(rec: Record, plant, condition, effects, settings) -> LoadEstimate:
    """The load of one record under the model with ``effects`` (piecewise constant, or piecewise
    linear within segments where it ramps).

    Its steps, whether it ramps and its knots are decided on the force balance as it is (so the
    regression's load elimination stays as it was; whether it ramps on what the residuals hold
    above the white noise X leaves there, :func:`transforms.discrepancy.load.follows_ramps`); its
    values on the averaged balance (:func:`_fit_load`)."""
    inputs = _load_inputs(rec, plant, condition, effects, settings)
    f_hat, t, v, a = inputs
    # the variance X's white noise leaves in f_hat, its second difference not averaged [N²]
    noise_n2 = float(_accel_noise(rec, np.zeros(1, dtype=np.int64), settings)[0]) * float(np.mean(t["mass"])) ** 2
    load = estimate_load(f_hat, v, settings, f_point=t["force"] - t["mass"] * rec.sg["a"], accel=a, dt=rec.dt, noise_n2=noise_n2)
    return _fit_load(rec, _refine_rest_steps(rec, load, f_hat, plant, condition, effects, settings), inputs, plant, settings)


def _load_estimate_for(p: _Prepared, plant, condition, effects, settings) -> LoadEstimate:
    """The record's load estimate under the model with ``effects`` (estimated once per model)."""
    key = (plant, condition, effects)
    if key not in p.loads:
        p.loads[key] = _estimate_load(p.rec, plant, condition, effects, settings)
    return p.loads[key]


def _load_for(p: _Prepared, plant, condition, effects, settings) -> np.ndarray:
    """The load at every sample under the model with ``effects`` (estimated once per model)."""
    return _load_estimate_for(p, plant, condition, effects, settings).load


def tapered(x: float, limit: float) -> float:
    """``x`` up to ±``limit``; beyond, less, down to 0 at ±2 ``limit`` and after: what the
    mechanical replay takes of a mass mismatch, a calibration's error, while a mismatch several
    times larger is a finding and stays whole in the gap where it is judged."""
    return float(np.sign(x) * np.clip(2.0 * limit - abs(x), 0.0, limit)) if abs(x) > limit else float(x)


def _mechanical_model(p: _Prepared, plant, condition, effects, settings, load: np.ndarray | None = None) -> tuple[PlantParams, np.ndarray]:
    """(plant, load [N]) the mechanical replay integrates: the model's viscous friction d_v and
    mass moved by the friction and the mass its load leaves in the record's force balance
    (:attr:`LoadEstimate.friction_mismatch`, :attr:`LoadEstimate.mass_mismatch`): d_v by at most
    ``settings.mechanical_friction_rel`` of it, the mass by at most ``mechanical_mass_rel`` of it
    and not at all beyond twice that (:func:`tapered`; ``DiscrepancySettings``); ``load`` (the
    replay's, :func:`_replay_load_for`, which is the default) plus the moved mass's weight, which
    the load estimate already holds."""
    if load is None:
        load = _replay_load_for(p, plant, condition, effects, settings)
    est = _load_estimate_for(p, plant, condition, effects, settings)
    c = plant.cylinder
    lim_v = settings.mechanical_friction_rel * c.d_v_n_s_m
    dv, dm = float(np.clip(est.friction_mismatch, -lim_v, lim_v)), tapered(est.mass_mismatch, settings.mechanical_mass_rel * c.mass_kg)
    return replace(plant, cylinder=replace(c, d_v_n_s_m=c.d_v_n_s_m + dv, mass_kg=c.mass_kg + dm)), load + dm * c.g_m_s2


def _holding(rec: Record, plant, condition, effects) -> tuple[np.ndarray, np.ndarray]:
    """(m g + A1 p1 − A2 p2 with the true smoothed pressures [N], stuck mask) of a record."""
    t = _terms_sg(rec, plant, condition, effects)
    c = plant.cylinder
    hold = t["mass"] * plant.cylinder.g_m_s2 + c.A1 * t["p1"] - c.A2 * t["p2"]
    return hold, stuck_spans(rec.sg["v"], DEFAULT_STUCK_V)


DEFAULT_STUCK_V = 1.0e-3
"""|v_X| below which the measured cylinder counts as sticking for the replay's load. [m/s]"""


def _replay_load_for(p: _Prepared, plant, condition, effects, settings) -> np.ndarray:
    est = _load_estimate_for(p, plant, condition, effects, settings)
    level = interval_load(est)
    if est.hold_until <= 0:
        return level
    hold, stuck = _holding(p.rec, plant, condition, effects)
    stuck = stuck & (np.arange(stuck.size) < est.hold_until)
    return replay_load(level, hold, stuck)


REST_STEP_GRID = 5
"""Candidate spacing (samples) when a load step found across a standstill is placed by replay."""
REST_STEP_TAIL = 300
"""Samples replayed after the standstill to judge a placement."""


def _replay_span(rec: Record, plant, condition, effects, a: int, b: int, load: np.ndarray, prefix=None, k: int = 0):
    """Replay samples [a, b) of a record from its measured state at a; returns its states
    (X, v_X, p1, p2) or None if the replay diverged. ``prefix``: the states of a
    replay of the span with a load that equals ``load`` before a + ``k`` (its :func:`_replay_span_states`):
    the replay is then continued from its state at a + k, the same numbers as replaying all."""
    if prefix is None or k <= 0:
        prefix, k = _replay_span_states(rec, plant, condition, effects, a, b, load), b - a
        if prefix is None:
            return None
    if k < b - a:
        x_true = true_signals(_smoothed(rec, "x")[a:b], rec.sg["p1"][a:a + 1], rec.sg["p2"][a:a + 1], effects)[0]
        try:
            r = replay(plant, x_true, rec.raw["ps"][a:b], rec.raw["pr"][a:b], load, [k], prefix[:, k], condition=condition, effects=effects)
        except FloatingPointError:
            return None
        prefix = np.concatenate([prefix[:, :k], np.vstack([r.X_m, r.vX_m_s, r.p1_pa, r.p2_pa])[:, k:]], axis=1)
    return prefix


def _smoothed(rec: Record, key: str) -> np.ndarray:
    """A recorded position the replays are driven with [m]: Savitzky–Golay, raw at the record's
    ends. The spool position ``"x"``, and the cylinder position ``"X"`` of the hydraulic replay,
    which takes the velocity as the slope between samples: the raw position's noise (1 µm) would
    drive the chambers with ~1.4 mm/s of velocity noise."""
    return np.where(np.isfinite(rec.sg[key]), rec.sg[key], rec.raw[key])


def _velocity(rec: Record) -> np.ndarray:
    """The cylinder velocity the replays restart with [m/s]: Savitzky–Golay, 0 at the record's ends."""
    return np.where(np.isfinite(rec.sg["v"]), rec.sg["v"], 0.0)


def _replay_span_states(rec: Record, plant, condition, effects, a: int, b: int, load: np.ndarray) -> np.ndarray | None:
    """The true states (X, v_X, p1, p2) of samples [a, b) replayed from the measured state at a,
    shape (4, b − a), or None if the replay diverged."""
    x_true, p1_true, p2_true = true_signals(_smoothed(rec, "x")[a:b], rec.sg["p1"][a:a + 1], rec.sg["p2"][a:a + 1], effects)
    v0 = rec.sg["v"][a]
    state = [[rec.position("X")[a], 0.0 if abs(v0) < 1e-3 else v0, p1_true[0], p2_true[0]]]
    try:
        r = replay(plant, x_true, rec.raw["ps"][a:b], rec.raw["pr"][a:b], load, [0], state, condition=condition, effects=effects)
    except FloatingPointError:
        return None
    return np.vstack([r.X_m, r.vX_m_s, r.p1_pa, r.p2_pa])


def _initial_hold(rec: Record, load: LoadEstimate, plant, condition, effects, settings) -> LoadEstimate:
    """Does the record start at rest with another load than the first level? Replay its start
    (to ``REST_STEP_TAIL`` samples past the first valid sample) both ways -- the first level from
    the start, or the holding force until the cylinder first moves -- and keep the better."""
    h = settings.savgol_window // 2
    hold, stuck = _holding(rec, plant, condition, effects)
    if not stuck[h] or not np.any(load.valid):
        return load
    first_move = int(np.argmin(stuck[h:])) + h  # first non-stuck sample
    first_valid = int(np.flatnonzero(load.valid)[0])
    if first_move <= h + 1 or first_move > first_valid:
        return load
    a, b = h, min(first_valid + REST_STEP_TAIL, rec.n - h - 1)
    if b - a < 10:
        return load
    level = load.load[a:b]
    sel = stuck[a:b] & (np.arange(a, b) < first_move)
    errs = []
    for F in (level, replay_load(level, hold[a:b], sel)):
        out = _replay_span(rec, plant, condition, effects, a, b, F)
        if out is None:
            errs.append(np.inf)
            continue
        errs.append(_span_error(rec, a, b, out, effects))
    if errs[1] < errs[0]:
        return replace(load, hold_until=first_move)
    return load


def _squared_misses(rec: Record, a: int, b: int, p1r: np.ndarray, p2r: np.ndarray, Xr: np.ndarray) -> tuple:
    """Per sample of [a, b), a replay's squared misses of the recorded p1, p2 [Pa²] and X [m²]."""
    return (p1r - rec.raw["p1"][a:b]) ** 2, (p2r - rec.raw["p2"][a:b]) ** 2, (Xr - rec.raw["X"][a:b]) ** 2


def _span_error(rec: Record, a: int, b: int, states: np.ndarray, effects) -> float:
    """How far a replay of samples [a, b) (its ``states``, :func:`_replay_span`) lies from the
    recorded p1, p2 [per 1e5 Pa] and X [per mm], in squares (:func:`_refine_rest_steps`)."""
    p1r, p2r = pressure_readings(states[2], states[3], effects)
    m1, m2, mX = _squared_misses(rec, a, b, p1r, p2r, states[0])
    return (np.sum(m1) + np.sum(m2)) / 1e10 + np.sum(mX) / 1e-6


def _prefix_errors(rec: Record, effects, a: int, b: int, prefix: np.ndarray | None) -> np.ndarray:
    """The terms of :func:`_span_error` of the replay ``prefix`` (its states, :func:`_replay_span_states`)
    summed over samples [a, a + k), for k = 0 … b − a (all 0 without a prefix)."""
    out = np.zeros(b - a + 1)
    if prefix is not None:
        p1r, p2r = pressure_readings(prefix[2], prefix[3], effects)
        m1, m2, mX = _squared_misses(rec, a, b, p1r, p2r, prefix[0])
        out[1:] = np.cumsum((m1 + m2) / 1e10 + mX / 1e-6)
    return out


def _replays_alike(last: np.ndarray | None, prefix: np.ndarray | None, j_last: int, j: int) -> bool:
    """Would a candidate step at index ``j`` of the span replay as the last candidate replayed
    (``last``, its step at ``j_last``)? Yes where ``last`` equals the old load's replay
    (``prefix``) from ``j_last`` to ``j``, ``j`` included: before ``j`` both are then the old
    load's, and from ``j`` on both replay the new load from the same state, the same numbers.
    A load step while the replayed cylinder sticks under both levels changes nothing (the
    chambers' flows do not depend on the load), so across a long standstill most candidates
    replay alike."""
    return last is not None and prefix is not None and j < last.shape[1] and np.array_equal(last[:, j_last:j + 1], prefix[:, j_last:j + 1])


def _refine_rest_steps(rec: Record, load: LoadEstimate, f_hat: np.ndarray, plant, condition, effects, settings) -> LoadEstimate:
    """Place each load step found across a standstill where a replay of the standstill (from
    the measured state before it to ``REST_STEP_TAIL`` samples after it) fits the recorded
    p1, p2 and X best: while the cylinder sticks the load does not show in the motion equation,
    but when it changed decides when and how the cylinder breaks away."""
    h = settings.savgol_window // 2
    load = _initial_hold(rec, load, plant, condition, effects, settings)
    if not np.any(load.brackets[:, 0] >= 0):
        return load
    steps = load.steps.copy()
    hold, stuck = _holding(rec, plant, condition, effects)
    stuck = stuck & (np.arange(stuck.size) < load.hold_until)
    for i, (lo, hi) in enumerate(load.brackets):
        if lo < 0:
            continue
        a = max(int(lo), h)
        b = min(int(hi) + REST_STEP_TAIL, rec.n - h - 1)
        prev_s = steps[i - 1] if i > 0 else 0
        next_s = steps[i + 1] if i + 1 < steps.size else rec.n
        cands = np.unique(np.r_[np.arange(max(lo + 1, prev_s + 1), min(hi, next_s - 1) + 1, REST_STEP_GRID), steps[i]])
        if b - a < 10 or cands.size < 2:
            continue
        old, new = (load.levels[i], load.levels[i + 1]) if not load.knot_samples else (load.load[lo], load.load[hi])
        best, best_err = steps[i], np.inf
        # every candidate's load is the old level's up to the step: replay that once and continue
        # each candidate from its state at the step (the same numbers as replaying each whole)
        prefix = _replay_span_states(rec, plant, condition, effects, a, b, replay_load(np.full(b - a, old), hold[a:b], stuck[a:b]))
        # a candidate's error sums non-negative terms, those before its step the prefix's: where
        # they alone exceed the best error (beyond rounding), it and every later one cannot win
        before = _prefix_errors(rec, effects, a, b, prefix)
        last, j_last = None, 0  # the states of the last candidate replayed, its step's index
        for c in cands:
            j = min(max(int(c) - a, 0), b - a)
            if before[j] > best_err * (1.0 + 1.0e-9):
                break
            if _replays_alike(last, prefix, j_last, j):
                continue
            F = replay_load(np.where(np.arange(a, b) < c, old, new), hold[a:b], stuck[a:b])
            out = _replay_span(rec, plant, condition, effects, a, b, F, prefix, int(c) - a)
            last, j_last = out, j
            if out is None:
                continue
            err = _span_error(rec, a, b, out, effects)
            if err < best_err:
                best, best_err = int(c), err
        steps[i] = best
    if np.array_equal(steps, load.steps):  # the estimate these steps were made with
        return load
    return load.with_steps(steps, f_hat, settings, _load_motion(rec, settings))


# --- step 2: regression data ---------------------------------------------------------------


@dataclass
class _Rows:
    """Stacked integrated residuals of all records (one model)."""

    y: np.ndarray  # residuals (not yet weighted)
    eq: np.ndarray  # equation index per row (0 chamber 1, 1 chamber 2, 2 motion)
    block: np.ndarray
    group: np.ndarray  # motion rows: (record, load segment) id = record × RECORD_STRIDE + segment; -1 otherwise
    sample: np.ndarray  # motion rows: the record's sample the row is centred at; -1 otherwise
    knots: dict = field(default_factory=dict)  # motion group -> knots of its piecewise-linear load (absent: a constant)
    _projector: list | None = None
    _mass_noise: dict = field(default_factory=dict)  # weights' bytes -> mass_term_noise

    @property
    def projector(self) -> list:
        """The elimination of the load from the motion rows (:func:`load.load_projector`)."""
        if self._projector is None:
            m = self.eq == 2
            self._projector = load_projector(self.group[m], self.sample[m], self.knots)
        return self._projector


def _rows(prepared: list[_Prepared], plant, condition, effects, settings) -> _Rows:
    c = plant.cylinder
    ys, eqs, blocks, groups, samples = [], [], [], [], []
    knots = {}
    for i, p in enumerate(prepared):
        rec = p.rec
        ir = interval_residuals(_terms_raw(rec, plant, condition, effects), rec.position("X"), c.A1, c.A2, rec.dt, p.edges, settings.interval_smoothing)
        e = p.edges
        nb = RECORD_STRIDE
        bc = (ir.t_cont // settings.block_s).astype(np.int64) + i * nb
        bm = (ir.t_motion // settings.block_s).astype(np.int64) + i * nb
        # motion rows: every sample of [e_{i-1}, e_{i+1}] usable and in one load segment
        us = p.segmentation.usable.astype(np.int64)
        cus = np.r_[0, np.cumsum(us)]
        lo, hi = e[:-2], e[2:] + 1
        all_usable = (cus[hi] - cus[lo]) == (hi - lo)
        seg = p.segmentation.segment
        same = seg[lo] == seg[np.minimum(hi - 1, rec.n - 1)]
        mrow = all_usable & same & np.isfinite(ir.rm)
        ys += [ir.r1, ir.r2, ir.rm[mrow]]
        eqs += [np.zeros(ir.r1.size, int), np.ones(ir.r2.size, int), np.full(int(mrow.sum()), 2)]
        blocks += [bc, bc, bm[mrow]]
        groups += [np.full(ir.r1.size, -1), np.full(ir.r2.size, -1), (i * nb + seg[e[1:-1]])[mrow]]
        samples += [np.full(ir.r1.size + ir.r2.size, -1), e[1:-1][mrow]]
        if p.segmentation.knot_samples:
            for sg in np.unique(seg[e[1:-1]][mrow]):
                knots[i * nb + int(sg)] = p.segmentation.knots(int(sg))
    return _Rows(np.concatenate(ys), np.concatenate(eqs), np.concatenate(blocks), np.concatenate(groups), np.concatenate(samples), knots)


def _eliminate_load(values: np.ndarray, rows: _Rows) -> np.ndarray:
    out = np.array(values, dtype=float, copy=True)
    m = rows.eq == 2
    if m.any():
        out[m] = project_out(out[m], rows.projector) if rows.knots else demean_by_group(out[m], rows.group[m])
    return out


def _equation_sigmas(y: np.ndarray, rows: _Rows) -> np.ndarray:
    """Robust scale (1.4826 MAD) of each equation's residual rows."""
    sig = np.ones(3)
    for k in range(3):
        v = y[(rows.eq == k) & np.isfinite(y)]
        if v.size > 10:
            s = robust_sigma(v)
            sig[k] = s if s > 0 else (float(np.std(v)) or 1.0)
    return sig


def _jacobian(prepared, plant, condition, effects, specs: list[EffectSpec], rows: _Rows, settings, r_here: np.ndarray | None = None) -> np.ndarray:
    """Forward differences (step FD_FRACTION x typical, towards the physical side) of the
    residual rows with respect to each candidate's parameter at ``effects``."""
    if r_here is None:
        r_here = _rows(prepared, plant, condition, effects, settings).y
    cols = []
    for spec in specs:
        d = FD_FRACTION * spec.typical
        rp = _rows(prepared, plant, condition, perturbed(effects, spec, d), settings).y
        cols.append(_eliminate_load((rp - r_here) / d, rows))
    return np.column_stack(cols) if cols else np.zeros((rows.y.size, 0))


# --- step 3 and 1: replays and gaps ---------------------------------------------------------


@dataclass
class ReplayTrace:
    """One record's recorded signals and replayed readings (for the overlay plots)."""

    record_index: int
    start_us: int
    t: np.ndarray
    measured: dict[str, np.ndarray]
    replayed: dict[str, np.ndarray]


def _replay_starts(p: _Prepared, effects, settings) -> tuple:
    """(spool position source, true x, p1, p2, v_X, restart indices every ``replay_segment_s``,
    the measured true states there) of the whole and the hydraulic replay."""
    rec = p.rec
    h = settings.savgol_window // 2
    x_src = _smoothed(rec, "x")
    x_true, p1_true, p2_true = true_signals(x_src, rec.sg["p1"], rec.sg["p2"], effects)
    starts = np.arange(h, rec.n - h - 1, max(2, int(round(settings.replay_segment_s / rec.dt))))
    v_all = _velocity(rec)
    v = v_all[starts]
    v = np.where(np.abs(v) < 1e-3, 0.0, v)
    states = np.column_stack([rec.position("X")[starts], v, p1_true[starts], p2_true[starts]])
    return x_src, x_true, p1_true, p2_true, v_all, starts, states


def _hydraulic_replay(p: _Prepared, plant, condition, effects, start: tuple, load) -> tuple[np.ndarray, np.ndarray]:
    """p1, p2 readings (sensor effects applied) replayed on the recorded cylinder motion from
    ``start`` (:func:`_replay_starts`); ``load`` does not enter the chambers."""
    rec = p.rec
    _, x_true, _, _, _, starts, states = start
    hyd = replay(plant, x_true, rec.raw["ps"], rec.raw["pr"], load, starts, states, condition=condition, effects=effects,
                 drive=DRIVE_HYDRAULIC, given=_smoothed(rec, "X"))
    p1h, p2h = pressure_readings(hyd.p1_pa, hyd.p2_pa, effects)
    return np.asarray(p1h, float).copy(), np.asarray(p2h, float).copy()


def hydraulic_readings(p: _Prepared, plant, condition, effects, settings) -> tuple[np.ndarray, np.ndarray]:
    """The p1, p2 readings of the hydraulic replay as :func:`_replay_record` gives them, without
    the load estimate, the whole or the mechanical replay (no load enters the chambers)."""
    h = settings.savgol_window // 2
    out = _hydraulic_replay(p, plant, condition, effects, _replay_starts(p, effects, settings), 0.0)
    for rep in out:
        rep[p.rec.n - h:] = np.nan  # as _replay_record
    return out


def hydraulic_gap(prepared, plant, condition, effects, settings) -> float:
    """The hydraulic gap (``gaps.SPLIT_GAPS``) of ``effects`` on ``prepared``: the chamber replay
    alone (:func:`hydraulic_readings`; for fits on it)."""
    acc = GapAccumulator()
    for p in prepared:
        for s, rep in zip(("p1_hydraulic", "p2_hydraulic"), hydraulic_readings(p, plant, condition, effects, settings)):
            acc.add(s, rep - p.rec.raw[RECORDED_OF[s]], p.regions)
    return acc.split_gap("hydraulic")


def _mechanical_restarts(rec: Record, settings, est: LoadEstimate) -> tuple[np.ndarray, np.ndarray]:
    """(judged mask, restart indices) of the mechanical replay: it restarts every
    ``mechanical_segment_s``, where a move leaves the breakaway (|v_X| rises past ``v_move_m_s``)
    and after every load step of ``est`` (the load estimate the replay is driven by): while the
    cylinder sticks or creeps the load does not show, so when and how it breaks away is not the
    motion's to judge; within ``step_guard_samples`` of a step the estimate's levels hold no sample
    (the load is unknown there: two steps 36 ms apart read as one put X 1 mm off for the rest of
    its 0.5 s piece), so the replay restarts at the guard's end and is not judged within it. X is
    judged at speed (the moving samples) away from the steps."""
    h = settings.savgol_window // 2
    n = rec.n
    v_all = _velocity(rec)
    moving = np.abs(v_all) > settings.v_move_m_s
    begins = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    g = settings.step_guard_samples
    judged = moving & away_from_steps(n, est.steps, g)
    resumes = est.steps + g
    extra = np.union1d(begins, resumes)
    starts = np.union1d(np.arange(h, n - h - 1, max(2, int(round(settings.mechanical_segment_s / rec.dt)))), extra[(extra > h) & (extra < n - h - 1)])
    return judged, starts


def _mechanical_replay(rec: Record, plant, condition, effects, load, mstarts: np.ndarray) -> np.ndarray:
    """X [m] replayed on the record's pressures (Savitzky–Golay, sensor effects removed) with
    ``load`` and ``plant`` (:func:`_mechanical_model`'s), restarted at ``mstarts``
    (:func:`_mechanical_restarts`) from the recorded X and its Savitzky–Golay velocity."""
    x_src = _smoothed(rec, "x")
    x_true, p1_true, p2_true = true_signals(x_src, rec.sg["p1"], rec.sg["p2"], effects)
    _, p1_rec, p2_rec = true_signals(x_src, rec.raw["p1"], rec.raw["p2"], effects)
    given_p = np.vstack([np.where(np.isfinite(p1_true), p1_true, p1_rec), np.where(np.isfinite(p2_true), p2_true, p2_rec)])
    vm = _velocity(rec)[mstarts]
    mstates = np.column_stack([rec.position("X")[mstarts], np.where(np.abs(vm) < 1e-3, 0.0, vm), given_p[0, mstarts], given_p[1, mstarts]])
    mech = replay(plant, x_true, rec.raw["ps"], rec.raw["pr"], load, mstarts, mstates, condition=condition, effects=effects,
                  drive=DRIVE_MECHANICAL, given=given_p)
    return mech.X_m.copy()


def _replay_record(p: _Prepared, plant, condition, effects, settings, split: bool = True) -> dict[str, np.ndarray]:
    """The record replayed whole (p1, p2, X) and, with ``split``, split (``gaps.SPLIT_GAPS``):
    p1, p2 on the recorded cylinder motion, X on the recorded pressures (restarts every
    ``mechanical_segment_s``, :func:`_mechanical_restarts`). Readings as recorded (sensor effects
    applied)."""
    rec = p.rec
    h = settings.savgol_window // 2
    n = rec.n
    start = _replay_starts(p, effects, settings)
    _, x_true, _, _, _, starts, states = start
    load = _replay_load_for(p, plant, condition, effects, settings)
    res = replay(plant, x_true, rec.raw["ps"], rec.raw["pr"], load, starts, states, condition=condition, effects=effects)
    p1r, p2r = pressure_readings(res.p1_pa, res.p2_pa, effects)
    out = {"p1": np.asarray(p1r, float).copy(), "p2": np.asarray(p2r, float).copy(), "X": res.X_m.copy()}
    if split:
        p1h, p2h = _hydraulic_replay(p, plant, condition, effects, start, load)
        judged, mstarts = _mechanical_restarts(rec, settings, _load_estimate_for(p, plant, condition, effects, settings))
        mplant, mload = _mechanical_model(p, plant, condition, effects, settings, load)
        out.update({"p1_hydraulic": p1h, "p2_hydraulic": p2h, "X_mechanical": _mechanical_replay(rec, mplant, condition, effects, mload, mstarts)})
    for k in out:
        out[k][n - h:] = np.nan  # the record's tail has no Savitzky–Golay regions
    if split:
        out["X_mechanical"][~judged] = np.nan  # at speed, away from load steps (_mechanical_restarts)
    return out


def _gaps(prepared, plant, condition, effects, settings, keep: set[int], split: bool = True) -> tuple[GapAccumulator, dict[int, dict]]:
    """The replay gaps of every record (and the replays of those in ``keep``); without ``split``,
    of the whole replay only (:meth:`GapAccumulator.gap`)."""
    acc = GapAccumulator()
    kept = {}
    for i, p in enumerate(prepared):
        rr = _replay_record(p, plant, condition, effects, settings, split)
        for s, rep in rr.items():
            acc.add(s, rep - p.rec.raw[RECORDED_OF[s]], p.regions)
        if i in keep:
            kept[i] = rr
    return acc, kept


NOISE_DRAWS = 16
"""Draws of fresh noise the mechanical noise floor averages over (:func:`noise_floors`): one draw's
floor scatters by ~20 % per 10 s record (the error of a twice-integrated force is set by a few
0.5 s pieces); over two records (the reference plant's clean valve, seeds 2008–2019 of the draws) 8 draws
scatter by ~6 % (10.0–12.5 µm), 16 by ~4 % (10.7–12.2 µm)."""
NOISE_SEED = 2013
"""Seed of those draws (the floor is a deterministic function of the records and the model)."""


def pooled_noise(prepared, keys) -> dict[str, float]:
    """Each channel of ``keys``' noise RMS over all the records (:attr:`Record.noise`). [Pa or m]"""
    out = {}
    for key in keys:
        ss = sum(p.rec.noise[key][0] for p in prepared)
        c = sum(p.rec.noise[key][1] for p in prepared)
        out[key] = float(np.sqrt(ss / c)) if c else 0.0
    return out


def noise_floors(prepared, plant, condition, effects, settings, draws: int = NOISE_DRAWS, seed: int = NOISE_SEED) -> dict[str, float]:
    """The split gaps (``gaps.SPLIT_GAPS``) the recorded sensor noise alone leaves through the
    replay, on the gap scales (each channel's noise as the records estimate it, :attr:`Record.noise`).

    Both by Monte Carlo: fresh white noise of each channel's estimated RMS is added to the records,
    they are prepared again (Savitzky–Golay) and replayed, and the RMS difference from the replay
    of the records as they are is taken over ``draws`` draws from ``seed``:

    * hydraulic: per chamber, sqrt(p noise² + e²), e what noise on every recorded channel (p_s,
      p_r, p1, p2, the spool position x and the cylinder position X) leaves in the hydraulic
      replay (:func:`hydraulic_readings`): the spool's noise enters through the flows, X's
      through the chamber volumes' rate (β/V1 · A1 · 10 µm is ~0.4 bar on Table 1's cylinder),
      the pressures' through the restarts;
    * mechanical: sqrt((X noise / 1 mm)² + (e / 1 mm)²), e the RMS over the judged samples of the
      mechanical replay (:func:`_mechanical_replay`, the model ``plant``, ``condition``,
      ``effects``) with the noise added to p1, p2 and X and the load's values fitted again on
      them (:func:`_fit_load`: its levels, ramps and the friction and mass it leaves, its steps
      and knots kept). X enters through the restarts (the position and its Savitzky–Golay
      velocity) and through the load's values. The replay integrates the force twice, so the
      pressures' noise (0.05 bar: ~30 N on Table 1's cylinder) leaves ~10 µm, ten times the X
      noise. At the noisy end of plant sensors (cylinder 10 µm in 5 µm steps) the load's values
      take a share: on the reference plant's clean valve (seeds 0–5, the spool reconstructed)
      the floor is 0.059–0.084 mm, 0.052–0.055 with the load kept, and the gap over it 0.66–2.06×
      instead of 0.94–2.85×. Where the rest lies: the load's decisions (seed 1 replays 0.018 mm
      on the load estimated from the same pressures and a 1 µm X, 0.15 mm on the 10 µm X's).
      At 1 µm the refitted load takes up part of the pressures' noise, as the record's own load
      does: the floor is ~20 % lower, the clean valve 0.93–1.65× it (0.76–1.36× with the load kept).
      Deciding the steps and ramps again in every draw took the gap under 1.43× its floor but
      doubled a diagnosis's CPU, and under a mechanical effect the base model's floor rose to
      2.0 mm (a 20 % friction change): not taken.
    """
    h = settings.savgol_window // 2
    rms = pooled_noise(prepared, ("p1", "p2", "X", "x", "ps", "pr"))
    mech, hyd = [0.0, 0], {"p1": [0.0, 0], "p2": [0.0, 0]}
    for i, p in enumerate(prepared):
        rec = p.rec
        key, est = (plant, condition, effects), _load_estimate_for(p, plant, condition, effects, settings)
        judged, mstarts = _mechanical_restarts(rec, settings, est)
        judged[rec.n - h:] = False
        mplant, load = _mechanical_model(p, plant, condition, effects, settings)
        nominal = _mechanical_replay(rec, mplant, condition, effects, load, mstarts)
        nominal_h = hydraulic_readings(p, plant, condition, effects, settings)
        rng = np.random.default_rng([seed, i])
        rng_h = np.random.default_rng([seed, i, 1])
        for _ in range(draws):
            raw = dict(rec.raw)
            for k in ("p1", "p2", "X"):
                raw[k] = raw[k] + rng.normal(0.0, rms[k], rec.n)
            noisy = prepare_record(Record(rec.valve_id, rec.start_us, rec.end_us, rec.dt, raw), settings, plant.spool)
            # the load's values estimated again on the noisy record, its steps and knots kept
            again = replace(p, rec=noisy, loads={key: _fit_load(noisy, est, _load_inputs(noisy, plant, condition, effects, settings), plant, settings)})
            mplant_n, load_n = _mechanical_model(again, plant, condition, effects, settings)
            d = (_mechanical_replay(noisy, mplant_n, condition, effects, load_n, mstarts) - nominal)[judged]
            ok = np.isfinite(d)
            mech[0] += float(np.sum(d[ok] ** 2))
            mech[1] += int(ok.sum())
            for k in ("x", "ps", "pr"):
                raw[k] = raw[k] + rng_h.normal(0.0, rms[k], rec.n)
            noisy = prepare_record(Record(rec.valve_id, rec.start_us, rec.end_us, rec.dt, raw), settings, plant.spool)
            for k, rep, ref in zip(("p1", "p2"), hydraulic_readings(replace(p, rec=noisy, loads={}), plant, condition, effects, settings), nominal_h):
                e = (rep - ref)[p.regions["all"]]
                ok = np.isfinite(e)
                hyd[k][0] += float(np.sum(e[ok] ** 2))
                hyd[k][1] += int(ok.sum())
    replayed = np.sqrt(mech[0] / mech[1]) if mech[1] else 0.0
    chamber = {k: np.hypot(rms[k], np.sqrt(ss / n) if n else 0.0) / GAP_SCALES[k] for k, (ss, n) in hyd.items()}
    return {"hydraulic": float(np.sqrt((chamber["p1"] ** 2 + chamber["p2"] ** 2) / 2)),
            "mechanical": float(np.hypot(rms["X"], replayed) / GAP_SCALES["X_mechanical"])}


MASS_NOISE_DRAWS = 16
"""Draws of :func:`mass_term_noise` (its scatter over draws: ~9 % per draw, ~2 % over 16)."""


def mass_term_noise(prepared, rows: _Rows, w_rows: np.ndarray, settings, draws: int = MASS_NOISE_DRAWS, seed: int = NOISE_SEED) -> np.ndarray:
    """E (w P ε)² per row [1/kg²]: what the recorded cylinder position's noise puts into each
    weighted motion row per kg² of moving mass, with the load eliminated (P) as in the rows (0 on
    the chamber rows); K below is their sum over the rows a fit uses.

    A motion row is F̄ − m ΔΔX̄ / T² (:func:`transforms.discrepancy.residuals.residuals_of_integrals`):
    the mass multiplies a second difference of the recorded X, so X's noise ε enters both the
    mass's column and the row (errors in variables). Least squares then reads the mass lighter by
    m·K / (K + I), I the mass's information in the rows: at the noisy end of plant sensors (10 µm)
    K/I was 0.14 on the reference plant's seed 4 (~800 kg of 6 t, 7σ of the mass's tolerance) and
    0.006 on seed 1; at 1 µm 0.002. The fits subtract K·m² from their sum of squares (a corrected score,
    :func:`transforms.discrepancy.corrected.corrected_lstsq`), whose expectation is then the
    noise-free one. Monte Carlo: white noise of X's RMS as the records estimate it (pooled) through
    the interval averages, the second difference, the rows and the load elimination; records whose
    X is reconstructed (``settings.reconstruct_cylinder``) contribute none (their error is not
    white). Cached on ``rows`` per weights."""
    key = np.asarray(w_rows, float).tobytes()
    if key in rows._mass_noise:
        return rows._mass_noise[key]
    sx = pooled_noise(prepared, ("X",))["X"]
    rec_of = rows.block // RECORD_STRIDE
    rng = np.random.default_rng(seed)
    total = np.zeros(rows.eq.size)
    for _ in range(draws):
        y = np.zeros(rows.eq.size)
        for i, p in enumerate(prepared):
            if "X" in p.rec.pos or sx == 0.0:
                continue
            e = p.edges
            L = int(e[1] - e[0])
            T = L * p.rec.dt
            Xs = box_at(rng.normal(0.0, sx, p.rec.n), e, settings.interval_smoothing)
            im = np.flatnonzero((rec_of == i) & (rows.eq == 2))
            at = (rows.sample[im] - e[1]) // L
            y[im] = (Xs[at + 2] - 2.0 * Xs[at + 1] + Xs[at]) / (T * T)
        y = _eliminate_load(y, rows)
        total += np.where(np.isfinite(y), (w_rows * y) ** 2, 0.0)
    rows._mass_noise[key] = total / draws
    return rows._mass_noise[key]


def _residual_summary(prepared, plant, condition, effects, settings) -> list[dict]:
    """RMS and mean of the pointwise residuals per equation and region."""
    c = plant.cylinder
    sums: dict[tuple[str, str], list[float]] = {}
    for p in prepared:
        rec = p.rec
        t = _terms_sg(rec, plant, condition, effects)
        g1 = effects.p1_sensor_gain
        g2 = effects.p2_sensor_gain
        r = pointwise_residuals(t, rec.sg["v"], rec.sg["a"], rec.sg["dp1"] / g1, rec.sg["dp2"] / g2, c.A1, c.A2, _load_for(p, plant, condition, effects, settings))
        for eq, key in (("chamber1", "r1"), ("chamber2", "r2"), ("motion", "rm")):
            val = r[key]
            base = np.isfinite(val)
            if eq == "motion":
                base &= p.base_load.usable
            for reg in REGIONS:
                m = base & p.regions[reg]
                acc = sums.setdefault((eq, reg), [0.0, 0.0, 0])
                acc[0] += float(np.sum(val[m] ** 2))
                acc[1] += float(np.sum(val[m]))
                acc[2] += int(m.sum())
    rows = []
    for (eq, reg), (ss, s, n) in sorted(sums.items()):
        rows.append({
            "equation": eq, "region": reg, "n_samples": n,
            "rms": float(np.sqrt(ss / n)) if n else float("nan"),
            "mean": float(s / n) if n else float("nan"),
            "unit": "N" if eq == "motion" else "m3/s",
        })
    return rows



"""Calibrating the base model's nuisance parameters (:mod:`transforms.discrepancy.nuisance`) on
records, alone or jointly with library effects.

The fit is a maximum a-posteriori Gauss–Newton on the same integrated residual rows the effect
selection regresses (:func:`transforms.discrepancy.rows._rows`: both chamber equations over
20-sample intervals and the motion equation integrated twice, the load eliminated per
segment), each row weighted by 1/σ of its equation, with the prior as extra rows: it minimises

    Σ_rows (w r(z, θ))² − K m(z, θ)² + |z|²

over the standardised nuisances z (prior N(0, I)) and the effect parameters θ (flat prior, kept
on their physical side); K m² is what the cylinder position's noise puts into the motion rows,
where it enters the mass's column too (:func:`transforms.discrepancy.rows.mass_term_noise`):
without it, least squares reads the mass lighter by ~m K / I (a corrected score; m the moving
mass with any mass change). Derivatives are finite differences of the exact residual functions
(central, step :data:`Z_STEP` σ for a nuisance; a nuisance's rows are evaluated from the equation
terms it enters only, :data:`TERMS_OF`, the same arithmetic as the whole rows). The equation weights are re-estimated from the calibrated
residuals once (the nominal model's residuals carry its own error and would under-weight the data).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from model.effects import Effects, EffectSpec
from model.params import PlantParams, ValveCondition
from transforms.discrepancy.corrected import capped_mass_noise, corrected_lstsq
from transforms.discrepancy.nuisance import NUISANCES, NuisancePriors, apply_nuisances, nuisance_sigmas, nuisance_values

__all__ = ["Calibration", "NuisanceModel", "calibrate", "calibrate_best", "effect_jacobian", "jacobians", "joint_fit"]

BREAKAWAY = NUISANCES.index("d_s")
CLEARANCE = NUISANCES.index("clearance")
SHARP_CLEARANCE = 0.1
"""A valve configured with Eq. 3's edges whose radial clearance calibrates below this fraction of
its configured one has sharp edges (issue 16's other family): it is calibrated and diagnosed with
the sharp-edged law, and the verdict says so (an Eq. 3 model left a gap of 0.5–1.6 there and named
p1 offsets; a commissioning calibration that kept Eq. 3 with the clearance near 0, which is the
sharp law only to ~1 % at larger openings, led the diagnosis taken as exact to name a 600 kg mass
change a small external leak)."""
BREAKAWAY_RANGE = 3.0
"""The breakaway force is searched within ±this many prior σ."""
Z_STEP = 0.05
"""Finite-difference step of a nuisance, in prior standard deviations."""
SPLIT_GAIN = 100.0
"""A calibration's load segment is split where a level change of its motion residuals reduces
their weighted sum of squares by more than this [σ² of the motion rows] (:func:`split_segment`;
on the robustness study's clean commissioning windows the largest such reduction was ≤ 34 where
no step was missed, 874 where a 325 N step was)."""
SPLIT_MIN_ROWS = 3
"""... with at least this many motion rows on either side."""
MAX_SPLITS = 4
"""At most this many load steps are added per calibration."""


@dataclass(frozen=True)
class NuisanceModel:
    """The nominal model, its nuisances' priors and the active (σ > 0) ones.

    Attributes
    ----------
    plant, condition : the nominal (design-data) model
    theta0, sigma : ndarray (15,)
        Nominal values and prior σ of :data:`NUISANCES` (SI).
    active : tuple of int
        Indices of the nuisances with σ > 0 fitted by Gauss–Newton (all but the breakaway force).
    breakaway_z : float
        The breakaway force d_s in prior σ: it shows only in when the cylinder breaks away, not in
        the integrated equations of moving samples, and is fitted on the replay
        (:func:`refine_breakaway`).
    """

    plant: PlantParams
    condition: ValveCondition
    theta0: np.ndarray
    sigma: np.ndarray
    active: tuple[int, ...]
    breakaway_z: float = 0.0

    @classmethod
    def of(cls, plant: PlantParams, condition: ValveCondition, priors: NuisancePriors) -> "NuisanceModel":
        sig = nuisance_sigmas(plant, condition, priors)
        return cls(plant, condition, nuisance_values(plant, condition), sig, tuple(int(i) for i in np.flatnonzero(sig > 0) if i != BREAKAWAY))

    def values(self, z: np.ndarray) -> np.ndarray:
        """θ = θ0 + σ z (z over the active nuisances; d_s at ``breakaway_z``)."""
        v = self.theta0.copy()
        v[list(self.active)] += self.sigma[list(self.active)] * np.asarray(z, float)
        v[BREAKAWAY] += self.sigma[BREAKAWAY] * self.breakaway_z
        return v

    def model(self, z: np.ndarray) -> tuple[PlantParams, ValveCondition]:
        """(plant, condition) at standardised nuisances z."""
        return apply_nuisances(self.plant, self.condition, self.values(z))

    def names(self) -> list[str]:
        return [NUISANCES[i] for i in self.active]


def _residuals(prepared, nm: NuisanceModel, z, effects, rows0, settings):
    from transforms.discrepancy.rows import _eliminate_load, _rows

    plant, cond = nm.model(z)
    return _eliminate_load(_rows(prepared, plant, cond, effects, settings).y, rows0)


TERMS_OF: dict[str, tuple[str, ...]] = {
    **{n: ("q1", "q2") for n in NUISANCES if n.startswith(("alpha_", "underlap_"))}, "clearance": ("q1", "q2"), "land_leakage": ("q1", "q2"),
    "bulk_modulus": ("c1", "c2"), "v01": ("c1", "c2"), "v02": ("c1", "c2"), "d_v": ("force",), "d_c": ("force",), "d_s": ("force",),
    "mass": ("force", "mass")}
"""The equation terms (:func:`model.effects.equation_terms`) each nuisance enters: the valve's
edges only the valve flows, β and the dead volumes only the chamber compliances, friction and
mass only the motion equation."""


class _RowsAround:
    """The residual rows at one model (as :func:`_residuals`) with every record's equation terms
    and interval integrals (:func:`transforms.discrepancy.residuals.interval_integrals`) kept, so
    that the rows of a model that differs only in some terms (one nuisance moved, :data:`TERMS_OF`)
    are evaluated from those terms and the integrals over them alone. The same arithmetic on the
    same numbers as :func:`_residuals`: the rows agree bit for bit."""

    def __init__(self, prepared, plant, condition, effects, rows0, settings):
        from transforms.discrepancy.residuals import interval_integrals, residuals_of_integrals
        from transforms.discrepancy.rows import RECORD_STRIDE, _eliminate_load, _terms_raw

        self.prepared, self.effects, self.rows0, self.settings = prepared, effects, rows0, settings
        self.parts = []
        y = np.full(rows0.eq.size, np.nan)
        rec_of = rows0.block // RECORD_STRIDE
        c = plant.cylinder
        for i, p in enumerate(prepared):
            t = _terms_raw(p.rec, plant, condition, effects)
            integrals = interval_integrals(t, p.rec.position("X"), p.rec.dt, p.edges, settings.interval_smoothing)
            ir = residuals_of_integrals(integrals, t["mass"], c.A1, c.A2, p.rec.dt, p.edges)
            mine = rec_of == i
            i1, i2, im = (np.flatnonzero(mine & (rows0.eq == k)) for k in range(3))
            at = (rows0.sample[im] - p.edges[1]) // (p.edges[1] - p.edges[0])  # the motion rows' interval edges
            y[i1], y[i2], y[im] = ir.r1, ir.r2, ir.rm[at]
            self.parts.append((p, integrals, t["mass"], i1, i2, im, at))
        self.y = y
        self.r = _eliminate_load(y, rows0)

    def rows(self, plant, condition, terms: tuple[str, ...]) -> np.ndarray:
        """The demeaned residual rows at (plant, condition), which differ from this model only in
        the equation ``terms``."""
        from model.effects import equation_terms
        from model.simulate import DEFAULT_REG_BAND_PA
        from transforms.discrepancy.residuals import INTEGRALS_OF, interval_integrals, residuals_of_integrals
        from transforms.discrepancy.rows import _eliminate_load, _signals

        redo = [k for k, deps in INTEGRALS_OF.items() if set(deps) & set(terms)]
        need = set(terms).union(*(INTEGRALS_OF[k] for k in redo))  # the terms of the integrals to redo
        y = self.y.copy()
        c = plant.cylinder
        for p, integrals, mass, i1, i2, im, at in self.parts:
            t = equation_terms(_signals(p.rec, False), plant, condition, self.effects, DEFAULT_REG_BAND_PA, only=need)
            new = {**integrals, **interval_integrals(t, p.rec.position("X"), p.rec.dt, p.edges, self.settings.interval_smoothing, only=redo)}
            ir = residuals_of_integrals(new, t.get("mass", mass), c.A1, c.A2, p.rec.dt, p.edges)
            y[i1], y[i2], y[im] = ir.r1, ir.r2, ir.rm[at]
        if "force" not in terms and "mass" not in terms:  # the motion rows, and so their load elimination, are unchanged
            r = self.r.copy()
            chamber = self.rows0.eq != 2
            r[chamber] = y[chamber]
            return r
        return _eliminate_load(y, self.rows0)


def jacobians(prepared, nm: NuisanceModel, z, effects: Effects, specs: list[EffectSpec], rows0, settings, r_here=None):
    """(r, J_z, J_θ): the demeaned residual rows at (z, effects) and their central-difference
    derivatives with respect to the active standardised nuisances and the effects' parameters
    (forward differences for a parameter at its physical bound). Central, because the verdict
    compares an effect with the nuisance pattern it resembles: a spool sensor offset is exactly an
    underlap pattern, and forward differences of different steps would make them differ by the
    curvature of the orifice law, which the heavily weighted data rows then take for a real difference.
    A nuisance's rows are evaluated from the terms it enters only (:class:`_RowsAround`)."""
    around = _RowsAround(prepared, *nm.model(z), effects, rows0, settings)
    r = around.r if r_here is None else r_here
    cols = []
    for j, k in enumerate(nm.active):
        zp, zm = np.array(z, float), np.array(z, float)
        zp[j] += Z_STEP
        zm[j] -= Z_STEP
        terms = TERMS_OF[NUISANCES[k]]
        cols.append((around.rows(*nm.model(zp), terms) - around.rows(*nm.model(zm), terms)) / (2 * Z_STEP))
    Jz = np.column_stack(cols) if cols else np.zeros((r.size, 0))
    return r, Jz, effect_jacobian(prepared, nm, z, effects, specs, rows0, settings, r)


def effect_jacobian(prepared, nm: NuisanceModel, z, effects: Effects, specs: list[EffectSpec], rows0, settings, r_here=None):
    """J_θ of :func:`jacobians` alone."""
    from transforms.discrepancy.rows import FD_FRACTION, perturbed

    ecols = []
    for spec in specs:
        d = FD_FRACTION * spec.typical
        lo = spec.value(effects) - d
        if spec.lower is not None and lo < spec.lower:  # one-sided at the physical bound
            r = _residuals(prepared, nm, z, effects, rows0, settings) if r_here is None else r_here
            ecols.append((_residuals(prepared, nm, z, perturbed(effects, spec, d), rows0, settings) - r) / d)
            continue
        ecols.append((_residuals(prepared, nm, z, perturbed(effects, spec, d), rows0, settings)
                      - _residuals(prepared, nm, z, perturbed(effects, spec, -d), rows0, settings)) / (2 * d))
    return np.column_stack(ecols) if ecols else np.zeros((rows0.eq.size, 0))


def _with_params(effects: Effects, specs, values) -> Effects | None:
    new = effects
    for spec, v in zip(specs, values):
        if spec.lower is not None and v < spec.lower:
            v = spec.lower
        new = replace(new, **{spec.attribute: float(v)})
    try:
        return Effects(**{f: getattr(new, f) for f in new.__dataclass_fields__})
    except ValueError:
        return None


@dataclass
class JointFit:
    """Outcome of :func:`joint_fit`.

    Attributes
    ----------
    z : standardised active nuisances
    effects : Effects with the fitted parameters
    z_se, effect_se : posterior standard deviations (Gauss–Newton, data rows taken independent)
    data_ss, prior_ss : Σ (w r)² and |z|² at the optimum
    r, Jz, Je : residual rows and derivatives at the optimum (unweighted)
    mass_noise, noise_ss : K [1/kg²] and K m² at the optimum (the fit's objective is
        data_ss − noise_ss + prior_ss; module docstring)
    mass_gradient : dm/d(z, θ) [kg per unit]
    """

    z: np.ndarray
    effects: Effects
    z_se: np.ndarray
    effect_se: np.ndarray
    data_ss: float
    prior_ss: float
    r: np.ndarray
    Jz: np.ndarray
    Je: np.ndarray
    mass_noise: float
    noise_ss: float
    mass_gradient: np.ndarray

    @property
    def usable(self) -> np.ndarray:
        """The rows the fit used: its residual and every derivative finite."""
        return _usable_rows(self.r, self.Jz, self.Je)


def _usable_rows(r: np.ndarray, Jz: np.ndarray, Je: np.ndarray) -> np.ndarray:
    """Rows whose residual ``r`` and derivatives (``Jz``, ``Je``: one column per parameter) are all finite."""
    return np.isfinite(r) & np.all(np.isfinite(Jz), axis=1) & np.all(np.isfinite(Je), axis=1)


def moving_mass(nm: NuisanceModel, z, effects: Effects) -> float:
    """The model's moving mass at nuisances ``z`` with ``effects``' mass change. [kg]"""
    return float(nm.model(z)[0].cylinder.mass_kg + effects.delta_mass_kg)


def mass_gradient(nm: NuisanceModel | None, specs: list[EffectSpec]) -> np.ndarray:
    """dm/d(z, θ) over the active nuisances (none with ``nm`` None: a model taken as exact) and
    the parameters of ``specs`` (1 for a mass change, else 0). [kg per unit]"""
    active = () if nm is None else nm.active
    g = np.zeros(len(active) + len(specs))
    mass = NUISANCES.index("mass")
    if mass in active:
        g[active.index(mass)] = nm.sigma[mass]
    for j, spec in enumerate(specs):
        g[len(active) + j] = 1.0 if spec.attribute == "delta_mass_kg" else 0.0
    return g


def joint_fit(prepared, nm: NuisanceModel, z0, specs: list[EffectSpec], effects0: Effects, rows0, w_rows, settings, iterations: int = 8) -> JointFit:
    """MAP Gauss–Newton for the active nuisances and the parameters of ``specs`` (module docstring)."""
    from transforms.discrepancy.rows import mass_term_noise

    z = np.array(z0, float)
    fx = effects0
    q, p = len(nm.active), len(specs)
    g = mass_gradient(nm, specs)
    r, Jz, Je = jacobians(prepared, nm, z, fx, specs, rows0, settings)
    k = 0.0
    if np.any(g):
        ok = _usable_rows(r, Jz, Je)
        k = capped_mass_noise(float(np.sum(mass_term_noise(prepared, rows0, w_rows, settings)[ok])), np.column_stack([Jz[ok], Je[ok]]) * w_rows[ok, None], g)

    def objective(rr, zz, ff):
        ok = np.isfinite(rr)
        return float(np.sum((rr[ok] * w_rows[ok]) ** 2) + zz @ zz - k * moving_mass(nm, zz, ff) ** 2)

    obj = objective(r, z, fx)
    for _ in range(iterations):
        ok = _usable_rows(r, Jz, Je)
        A = np.vstack([np.column_stack([Jz[ok], Je[ok]]) * w_rows[ok, None], np.hstack([np.eye(q), np.zeros((q, p))])])
        b = np.r_[-r[ok] * w_rows[ok], -z]
        step, _ = corrected_lstsq(A, b, g, k, moving_mass(nm, z, fx))
        accepted = False
        for lam in (1.0, 0.5, 0.25, 0.1):
            z_new = z + lam * step[:q]
            fx_new = _with_params(fx, specs, [spec.value(fx) + lam * d for spec, d in zip(specs, step[q:])])
            if fx_new is None:
                continue
            r_new = _residuals(prepared, nm, z_new, fx_new, rows0, settings)
            o = objective(r_new, z_new, fx_new)
            if np.isfinite(o) and o <= obj:
                accepted = True
                break
        if not accepted:
            break
        small = np.all(np.abs(lam * step[:q]) < 1e-3) and all(abs(lam * d) < 1e-4 * spec.typical for spec, d in zip(specs, step[q:]))
        z, fx, obj = z_new, fx_new, o
        r, Jz, Je = jacobians(prepared, nm, z, fx, specs, rows0, settings, r_new)
        if small:
            break
    ok = _usable_rows(r, Jz, Je)
    A = np.column_stack([Jz[ok], Je[ok]]) * w_rows[ok, None]
    H = A.T @ A
    H[:q, :q] += np.eye(q)
    H -= k * np.outer(g, g)
    try:
        cov = np.linalg.pinv(H)
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        se = np.full(q + p, np.inf)
    data_ss = float(np.sum((r[ok] * w_rows[ok]) ** 2))
    m = moving_mass(nm, z, fx)
    return JointFit(z=z, effects=fx, z_se=se[:q], effect_se=se[q:], data_ss=data_ss, prior_ss=float(z @ z), r=r, Jz=Jz, Je=Je,
                    mass_noise=k, noise_ss=k * m * m, mass_gradient=g)


@dataclass(frozen=True)
class Calibration:
    """The base model calibrated on records (no library effect).

    Attributes
    ----------
    nm : NuisanceModel
    z, z_se : standardised nuisances and their posterior SDs (over ``nm.active``)
    plant, condition : the calibrated model
    sigmas : equation weights' scales used (chamber 1, chamber 2 [m³/s], motion [N])
    """

    nm: NuisanceModel
    z: np.ndarray
    z_se: np.ndarray
    plant: PlantParams
    condition: ValveCondition
    sigmas: tuple[float, float, float]
    gap_nominal: float = float("nan")
    gap_calibrated: float = float("nan")
    """Normalised replay gaps of the records with the nominal and the calibrated model."""
    reason: str = ""
    """What the calibration found about the model itself: the records show sharp edges where Eq. 3
    is configured (:func:`is_sharp`), so it calibrated the sharp-edged law; empty if nothing."""

    def table(self) -> list[dict]:
        """One dict per nuisance: name, nominal, value, prior σ, z (SI units, :data:`NUISANCE_UNITS`)."""
        from transforms.discrepancy.nuisance import NUISANCE_UNITS

        vals = self.nm.values(self.z)
        zfull = np.zeros(len(NUISANCES))
        sefull = np.zeros(len(NUISANCES))
        zfull[list(self.nm.active)] = self.z
        sefull[list(self.nm.active)] = self.z_se
        zfull[BREAKAWAY] = self.nm.breakaway_z
        return [{"name": n, "unit": NUISANCE_UNITS[n], "nominal": float(self.nm.theta0[i]), "value": float(vals[i]),
                 "prior_sigma": float(self.nm.sigma[i]), "z": float(zfull[i]), "se": float(sefull[i] * self.nm.sigma[i])}
                for i, n in enumerate(NUISANCES)]


def refine_breakaway(prepared, nm: NuisanceModel, z, settings, effects: Effects | None = None) -> NuisanceModel:
    """The breakaway force d_s that makes the replay fit best (a grid over ±``BREAKAWAY_RANGE`` σ,
    then golden-section search), the other nuisances held at z and the loads those of the model at
    the start. Returns the nuisance model with ``breakaway_z`` set."""
    from transforms.discrepancy.rows import _gaps, _load_estimate_for

    if nm.sigma[BREAKAWAY] <= 0:
        return nm
    fx = Effects() if effects is None else effects
    ref = nm.model(z)
    ref_loads = [_load_estimate_for(p, *ref, fx, settings) for p in prepared]

    def gap(zb: float) -> float:
        m = replace(nm, breakaway_z=float(zb))
        plant, cond = m.model(z)
        for p, est in zip(prepared, ref_loads):
            p.loads.setdefault((plant, cond, fx), est)
        return _gaps(prepared, plant, cond, fx, settings, set(), split=False)[0].gap()

    grid = np.linspace(-BREAKAWAY_RANGE, BREAKAWAY_RANGE, 13)
    vals = [gap(g) for g in grid]
    k = int(np.argmin(vals))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    phi = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = b - phi * (b - a), a + phi * (b - a)
    gc, gd = gap(c), gap(d)
    for _ in range(8):
        if gc < gd:
            b, d, gd = d, c, gc
            c = b - phi * (b - a)
            gc = gap(c)
        else:
            a, c, gc = c, d, gd
            d = a + phi * (b - a)
            gd = gap(d)
    best = min([(vals[k], grid[k]), (gc, c), (gd, d)])[1]
    return replace(nm, breakaway_z=float(best))


def _split_gains(r: np.ndarray) -> np.ndarray:
    """Reduction of the sum of squares of ``r`` (one segment's rows in time order, demeaned)
    by a level change after each row but the last: n₁ n₂ / n (mean₁ − mean₂)²."""
    n = r.size
    c = np.cumsum(r)
    k = np.arange(1, n)
    return (c[:-1] - k / n * c[-1]) ** 2 * n / (k * (n - k))


def split_segment(prepared, fit: JointFit, rows, w_rows: np.ndarray, settings) -> bool:
    """Add a load step where the calibrated motion residuals change level most, if that reduces
    their weighted sum of squares by more than :data:`SPLIT_GAIN`: a load step the detector missed
    (:func:`transforms.discrepancy.load.estimate_load` answers a step at ~0.4 of its size and keeps
    those above 400 N) leaves the segment's load off on one side, which on slow moves the mass
    takes up (a missed 325 N step put it 530 kg off). The step goes between the two rows, on the
    record's regression segments (``_Prepared.seg``). Returns whether a step was added."""
    from transforms.discrepancy.rows import RECORD_STRIDE

    m = (rows.eq == 2) & np.isfinite(fit.r)
    r, g, smp = (fit.r * w_rows)[m], rows.group[m], rows.sample[m]
    best = (SPLIT_GAIN, None)
    for gg in np.unique(g):
        sel = np.flatnonzero(g == gg)
        if sel.size < 2 * SPLIT_MIN_ROWS:
            continue
        gain = _split_gains(r[sel])[SPLIT_MIN_ROWS - 1:sel.size - SPLIT_MIN_ROWS]
        j = int(np.argmax(gain))
        if gain[j] > best[0]:
            a, b = smp[sel[j + SPLIT_MIN_ROWS - 1]], smp[sel[j + SPLIT_MIN_ROWS]]
            best = (float(gain[j]), (int(gg) // RECORD_STRIDE, int(a + b) // 2))
    if best[1] is None:
        return False
    i, k = best[1]
    prepared[i].seg = prepared[i].segmentation.with_added_step(k, settings.step_guard_samples)
    return True


def calibrate_prepared(prepared, nm: NuisanceModel, settings, effects: Effects | None = None, z0=None,
                       split: bool = False) -> tuple[JointFit, object, np.ndarray, np.ndarray]:
    """Calibrate the nuisances on prepared records with ``effects`` held (default none); with
    ``split``, add up to :data:`MAX_SPLITS` load steps the detector missed (:func:`split_segment`),
    refitting after each. Returns (fit, rows, weights, equation sigmas)."""
    from transforms.discrepancy.rows import _eliminate_load, _equation_sigmas, _rows

    fx = Effects() if effects is None else effects
    z = np.zeros(len(nm.active)) if z0 is None else np.asarray(z0, float)
    for n_split in range(MAX_SPLITS + 1):
        plant, cond = nm.model(z)
        rows0 = _rows(prepared, plant, cond, fx, settings)
        sig = _equation_sigmas(_eliminate_load(rows0.y, rows0), rows0)
        fit = None
        for _ in range(2):  # weights from the nominal residuals, then from the calibrated ones
            w = 1.0 / sig[rows0.eq]
            fit = joint_fit(prepared, nm, z, [], fx, rows0, w, settings)
            z = fit.z
            new = _equation_sigmas(fit.r, rows0)
            if np.allclose(new, sig, rtol=0.2):
                sig = new
                break
            sig = new
        if not split or n_split == MAX_SPLITS or not split_segment(prepared, fit, rows0, 1.0 / sig[rows0.eq], settings):
            break
    return fit, rows0, 1.0 / sig[rows0.eq], sig


def is_sharp(nm: NuisanceModel, z: np.ndarray) -> bool:
    """Do the nuisances ``z`` calibrate the radial clearance of a valve configured with Eq. 3's
    edges below ``SHARP_CLEARANCE`` of its configured value: sharp edges."""
    return bool(CLEARANCE in nm.active and nm.values(z)[CLEARANCE] < SHARP_CLEARANCE * nm.theta0[CLEARANCE])


def sharp_edges_reason(nm: NuisanceModel, z: np.ndarray, what: str) -> str:
    """'the edges are sharp (…): ``what`` with the sharp-edged law (configure area_law = "sharp")'."""
    return (f"the edges are sharp (radial clearance calibrated to {nm.values(z)[CLEARANCE] * 1e6:.2g} µm of the configured "
            f"{nm.theta0[CLEARANCE] * 1e6:.3g} µm): {what} with the sharp-edged law (configure area_law = \"sharp\")")


def calibrate_best(prepared, nm: NuisanceModel, settings, effects: Effects | None = None,
                   split: bool = False) -> tuple[JointFit, object, np.ndarray, np.ndarray]:
    """:func:`calibrate_prepared` from the design data and, when the radial clearance is a
    nuisance, also from no clearance (a sharp-edged spool): the clearance moves the effective
    underlap of every edge by 55-109 µm, and Gauss–Newton from Eq. 3's nominal clearance can stop
    in a local minimum on a sharp-edged valve. The start kept is the one with the larger posterior,
    the equations' noise scales estimated (Σ_eq n_eq log σ_eq² + |z|²); with ``split``, the load
    steps that start added stay on the records."""
    starts = [None]
    if CLEARANCE in nm.active:
        z0 = np.zeros(len(nm.active))
        z0[nm.active.index(CLEARANCE)] = -nm.theta0[CLEARANCE] / nm.sigma[CLEARANCE]
        starts.append(z0)
    segs0 = [p.seg for p in prepared]
    best, best_score, best_segs = None, np.inf, segs0
    for z0 in starts:
        for p, sg in zip(prepared, segs0):
            p.seg = sg
        out = calibrate_prepared(prepared, nm, settings, effects, z0, split)
        fit, rows0, _, sig = out
        n_eq = np.bincount(rows0.eq[np.isfinite(fit.r)], minlength=3)[:3]
        score = float(np.sum(n_eq * np.log(sig ** 2)) + fit.z @ fit.z)
        if score < best_score:
            best, best_score, best_segs = out, score, [p.seg for p in prepared]
    for p, sg in zip(prepared, best_segs):
        p.seg = sg
    return best


def calibrate(records, plant: PlantParams, condition: ValveCondition, priors: NuisancePriors, settings, effects: Effects | None = None) -> Calibration:
    """Calibrate the base model's nuisances on ``records`` (e.g. a commissioning window): the
    loads are estimated with the nominal model, the nuisances fitted, the loads estimated again
    with the calibrated model and the nuisances refitted; each fit adds the load steps the
    detector missed (:func:`split_segment`)."""
    from transforms.discrepancy.rows import _gaps, prepare_records

    from transforms.discrepancy.alignment import align_prepared

    fx = Effects() if effects is None else effects
    nm = NuisanceModel.of(plant, condition, priors)
    records, _, prepared = align_prepared(records, plant, condition, settings)  # the pressure channels' delay
    if not prepared:
        raise ValueError("no record long enough to calibrate on")
    g0 = _gaps(prepared, plant, condition, fx, settings, set(), split=False)[0].gap()
    fit, _, _, sig = calibrate_best(prepared, nm, settings, effects, split=True)
    if is_sharp(nm, fit.z):
        # the window shows sharp edges, not the configured Eq. 3's: calibrate with that law (as diagnose does)
        cal = calibrate(records, replace(plant, geometry=replace(plant.geometry, area_law="sharp")), condition, priors, settings, effects)
        return replace(cal, reason=sharp_edges_reason(nm, fit.z, "calibrated"), gap_nominal=g0)  # the configured design's gap
    nm = refine_breakaway(prepared, nm, fit.z, settings, effects)
    p1, c1 = nm.model(fit.z)
    prepared = prepare_records(records, p1, c1, settings)
    fit, _, _, sig = calibrate_prepared(prepared, nm, settings, effects, fit.z, split=True)
    p1, c1 = nm.model(fit.z)
    prepared = prepare_records(records, p1, c1, settings)
    g1 = _gaps(prepared, p1, c1, fx, settings, set(), split=False)[0].gap()
    return Calibration(nm=nm, z=fit.z, z_se=fit.z_se, plant=p1, condition=c1, sigmas=tuple(float(s) for s in sig), gap_nominal=g0, gap_calibrated=g1)

"""Candidate physical effects the base model of Steinboeck et al. (2013) leaves out: the library
the model-discrepancy workflow tests, each a switchable term of the simulator.

Every effect has a name (``docs/interfaces.md``), a term in the equations and one
parameter with a unit. With every parameter at its neutral value (:class:`Effects` defaults)
the model is exactly the base model of ``docs/model.md``.

| effect (variant)            | parameter           | unit           | term                                                      |
|-----------------------------|---------------------|----------------|-----------------------------------------------------------|
| internal_leakage            | K_i                 | m^3/(s Pa)     | q_i = K_i (p1 - p2) from chamber 1 to chamber 2 (piston)  |
| external_leakage            | K_e                 | m^3/(s Pa)     | q_e = K_e p2 out of chamber 2 (rod seal; p2 gauge)        |
| entrained_air               | eps_air             | -              | 1/beta_e(p) = 1/beta + eps h(p) (undissolved air, below)  |
| spool_sensor_offset         | delta_x             | m              | the LVDT reads x + delta_x                                |
| pressure_sensor_offset (p1) | delta_p1            | Pa             | the p1 transmitter reads p1 + delta_p1                    |
| pressure_sensor_offset (p2) | delta_p2            | Pa             | the p2 transmitter reads p2 + delta_p2                    |
| pressure_sensor_gain (p1)   | gain_p1             | -              | the p1 transmitter reads gain_p1 * p1 (neutral 1)         |
| pressure_sensor_gain (p2)   | gain_p2             | -              | the p2 transmitter reads gain_p2 * p2 (neutral 1)         |
| supply_line_resistance      | R_s                 | Pa s^2/m^6     | p_s,valve = p_s - R_s q_s abs(q_s), q_s = flow s1 + s2    |
| friction_change             | delta_d_v           | N s/m          | d_v -> d_v + delta_d_v (viscous friction, Eq. 5)          |
| load_mass_change            | delta_m             | kg             | m -> m + delta_m (inertia and weight, Eq. 5)              |

Chamber equations with the effects (Eq. 6 extended):

    dp1/dt = beta_e(p1) / V1 (q1 - A1 v_X - q_i)
    dp2/dt = beta_e(p2) / V2 (A2 v_X - q2 + q_i - q_e)

q1, q2 are Eq. 4 evaluated with the supply pressure at the valve, p_s,valve, which solves
p_s,valve = p_s - R_s q_s(p_s,valve) abs(q_s(p_s,valve)) with
q_s = sqrt(2/rho) [alpha_s1 A_s1 ssqrt(p_s,valve - p1) + alpha_s2 A_s2 ssqrt(p_s,valve - p2)]
(monotone in p_s,valve, solved by safeguarded Newton). p_s is what the supply transmitter
measures upstream of the line; a quadratic (turbulent) law is used because supply lines of a
mill carry 100-200 L/min at Reynolds numbers of several thousand.

Entrained air: a volume fraction eps of undissolved air at atmospheric pressure P_ATM,
compressed polytropically (exponent n = 1.4) with the fluid, adds its compliance:

    h(p) = (P_ATM / (p + P_ATM))^(1/n) / (n (p + P_ATM))       (p gauge) [1/Pa]

(eps = 1 % makes the fluid about 23 % softer at 30 bar and 2 % softer at 150 bar.)

Spool sensor offset: the valve's inner position loop regulates the LVDT reading, so in closed
loop the spool settles at x_ref - delta_x, and the recorded x is the true x + delta_x.
Pressure sensor offset/gain act on the recorded pressures only (the position loop does not use
them): p_recorded = gain p + offset.

:func:`sensor_readings` and :func:`true_signals` map between true and recorded signals;
:func:`equation_terms` evaluates every term of the chamber and motion equations, with the
effects, on given (recorded) signals -- what the discrepancy workflow's residuals and
regressors are built from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from numba import njit

from .area import _valve_areas_array, valve_edge_constants
from .orifice import signed_sqrt_kernel
from .params import PlantParams, ValveCondition

#: Atmospheric pressure the air fraction refers to (pressures in the model are gauge). [Pa]
P_ATM_PA = 1.013e5
#: Polytropic exponent of the entrained air (adiabatic compression of small bubbles). [-]
AIR_POLYTROPIC_EXPONENT = 1.4

EFFECT_NAMES: tuple[str, ...] = (
    "internal_leakage", "external_leakage", "entrained_air", "spool_sensor_offset",
    "pressure_sensor_offset", "pressure_sensor_gain", "supply_line_resistance",
    "friction_change", "load_mass_change",
)
"""The effect names of ``docs/interfaces.md``, in library order."""


@dataclass(frozen=True)
class Effects:
    """Parameters of every library effect; the defaults (all neutral) are the base model.

    Attributes
    ----------
    internal_leakage_m3_s_pa : float
        K_i, leakage conductance across the piston, q_i = K_i (p1 - p2). [m^3/(s Pa)]
    external_leakage_m3_s_pa : float
        K_e, leakage conductance from chamber 2 to the outside, q_e = K_e p2. [m^3/(s Pa)]
    air_fraction : float
        eps, volume fraction of undissolved air at atmospheric pressure. [-]
    spool_sensor_offset_m : float
        delta_x, offset of the spool position transducer. [m]
    p1_sensor_offset_pa, p2_sensor_offset_pa : float
        Offsets of the chamber pressure transmitters. [Pa]
    p1_sensor_gain, p2_sensor_gain : float
        Gains of the chamber pressure transmitters (1 = correct). [-]
    supply_resistance_pa_s2_m6 : float
        R_s, quadratic flow resistance of the supply line between the supply transmitter and
        the valve. [Pa s^2/m^6]
    delta_viscous_friction_n_s_m : float
        Change of the viscous friction coefficient d_v. [N s/m]
    delta_mass_kg : float
        Change of the moving mass m (inertia and weight). [kg]
    """

    internal_leakage_m3_s_pa: float = 0.0
    external_leakage_m3_s_pa: float = 0.0
    air_fraction: float = 0.0
    spool_sensor_offset_m: float = 0.0
    p1_sensor_offset_pa: float = 0.0
    p2_sensor_offset_pa: float = 0.0
    p1_sensor_gain: float = 1.0
    p2_sensor_gain: float = 1.0
    supply_resistance_pa_s2_m6: float = 0.0
    delta_viscous_friction_n_s_m: float = 0.0
    delta_mass_kg: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            v = float(getattr(self, f.name))
            if not math.isfinite(v):
                raise ValueError(f"{f.name} must be finite")
            object.__setattr__(self, f.name, v)
        if self.air_fraction < 0 or self.air_fraction >= 0.5:
            raise ValueError("air_fraction must lie in [0, 0.5)")
        if self.p1_sensor_gain <= 0 or self.p2_sensor_gain <= 0:
            raise ValueError("pressure sensor gains must be > 0")
        if self.supply_resistance_pa_s2_m6 < 0:
            raise ValueError("supply_resistance_pa_s2_m6 must be >= 0")

    @property
    def is_neutral(self) -> bool:
        """True if every effect is off (the base model)."""
        return self == Effects()

    @property
    def has_flow_terms(self) -> bool:
        """True if an effect changes the chamber equations (leakage, air, supply line)."""
        return (self.internal_leakage_m3_s_pa != 0.0 or self.external_leakage_m3_s_pa != 0.0
                or self.air_fraction != 0.0 or self.supply_resistance_pa_s2_m6 != 0.0)

    def combined(self, other: "Effects") -> "Effects":
        """Both sets of effects: additive parameters add, gains multiply."""
        kw = {}
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            kw[f.name] = a * b if f.name.endswith("_gain") else a + b
        return Effects(**kw)


def effect_key(name: str, variant: str | None) -> str:
    """An effect's key (:attr:`EffectSpec.key`) from its name and variant (p1, p2, or none)."""
    return f"{name}[{variant}]" if variant else name


@dataclass(frozen=True)
class EffectSpec:
    """One candidate of the library: an effect name, a variant and its parameter.

    Attributes
    ----------
    name : str
        Effect name of interfaces.md.
    variant : str
        "" or which signal it concerns ("p1", "p2") when the name has several variants.
    attribute : str
        The :class:`Effects` attribute that holds the parameter.
    parameter_name : str
        Name of the parameter as reported.
    unit : str
        Its SI unit.
    neutral : float
        Its value when the effect is off.
    term : str
        The term in the equations.
    typical : float
        A typical magnitude of a clearly present effect (a scale for numerics and tests).
    lower : float or None
        Physical lower bound of the parameter (leakage conductances, the air fraction and the
        line resistance cannot be negative); None = either sign is physical.
    """

    name: str
    variant: str
    attribute: str
    parameter_name: str
    unit: str
    neutral: float
    term: str
    typical: float
    lower: float | None = None

    @property
    def key(self) -> str:
        """``name`` or ``name[variant]``: unique within the library."""
        return effect_key(self.name, self.variant)

    def effects(self, value: float) -> Effects:
        """Effects with only this one switched on at ``value``."""
        return replace(Effects(), **{self.attribute: float(value)})

    def value(self, effects: Effects) -> float:
        """This candidate's parameter in ``effects``."""
        return float(getattr(effects, self.attribute))


EFFECT_LIBRARY: tuple[EffectSpec, ...] = (
    EffectSpec("internal_leakage", "", "internal_leakage_m3_s_pa", "K_i", "m3/(s*Pa)", 0.0,
               "q_i = K_i (p1 - p2) from chamber 1 to chamber 2", 2.0e-12, 0.0),
    EffectSpec("external_leakage", "", "external_leakage_m3_s_pa", "K_e", "m3/(s*Pa)", 0.0,
               "q_e = K_e p2 out of chamber 2", 2.0e-12, 0.0),
    EffectSpec("entrained_air", "", "air_fraction", "air_fraction", "-", 0.0,
               "1/beta_e(p) = 1/beta + eps (P_atm/(p+P_atm))^(1/1.4) / (1.4 (p+P_atm))", 5.0e-3,
               0.0),
    EffectSpec("spool_sensor_offset", "", "spool_sensor_offset_m", "delta_x", "m", 0.0,
               "x_recorded = x + delta_x", 10.0e-6),
    EffectSpec("pressure_sensor_offset", "p1", "p1_sensor_offset_pa", "delta_p1", "Pa", 0.0,
               "p1_recorded = p1 + delta_p1", 2.0e5),
    EffectSpec("pressure_sensor_offset", "p2", "p2_sensor_offset_pa", "delta_p2", "Pa", 0.0,
               "p2_recorded = p2 + delta_p2", 2.0e5),
    EffectSpec("pressure_sensor_gain", "p1", "p1_sensor_gain", "gain_p1", "-", 1.0,
               "p1_recorded = gain_p1 p1", 0.03),
    EffectSpec("pressure_sensor_gain", "p2", "p2_sensor_gain", "gain_p2", "-", 1.0,
               "p2_recorded = gain_p2 p2", 0.03),
    EffectSpec("supply_line_resistance", "", "supply_resistance_pa_s2_m6", "R_s", "Pa*s2/m6", 0.0,
               "p_s,valve = p_s - R_s q_s |q_s|", 1.0e11, 0.0),
    EffectSpec("friction_change", "", "delta_viscous_friction_n_s_m", "delta_d_v", "N*s/m", 0.0,
               "F_f = (d_v + delta_d_v) v_X + Stribeck/Coulomb terms", 20.0e3),
    EffectSpec("load_mass_change", "", "delta_mass_kg", "delta_m", "kg", 0.0,
               "m -> m + delta_m in m g and m dv_X/dt", 600.0),
)
"""The library of candidate effects, one entry per (effect, variant)."""


def library_entry(key: str) -> EffectSpec:
    """The library entry with this ``key`` (``name`` or ``name[variant]``)."""
    for spec in EFFECT_LIBRARY:
        if spec.key == key:
            return spec
    raise ValueError(f"unknown effect {key!r}; known: {[s.key for s in EFFECT_LIBRARY]}")


def apply_to_params(params: PlantParams, effects: Effects | None) -> PlantParams:
    """The plant with the parameter-change effects (friction, mass) applied; the other effects
    are terms of the kernel (:func:`model.simulate.pack_params`) or of the sensors."""
    if effects is None or (effects.delta_viscous_friction_n_s_m == 0.0
                           and effects.delta_mass_kg == 0.0):
        return params
    c = params.cylinder
    d_v = c.d_v_n_s_m + effects.delta_viscous_friction_n_s_m
    m = c.mass_kg + effects.delta_mass_kg
    if d_v < 0 or m <= 0:
        raise ValueError("the friction or mass change makes d_v < 0 or m <= 0")
    return replace(params, cylinder=replace(c, d_v_n_s_m=d_v, mass_kg=m))


# --- kernels ---------------------------------------------------------------------------------


@njit(cache=True)
def air_compliance_kernel(p):
    """h(p) [1/Pa] of entrained air at gauge pressure p [Pa] (module docstring)."""
    pa = p + P_ATM_PA
    if pa < 0.1 * P_ATM_PA:
        pa = 0.1 * P_ATM_PA
    return (P_ATM_PA / pa) ** (1.0 / AIR_POLYTROPIC_EXPONENT) / (AIR_POLYTROPIC_EXPONENT * pa)


@njit(cache=True)
def effective_bulk_modulus_kernel(p, beta, air_fraction):
    """beta_e(p) [Pa] = 1 / (1/beta + eps h(p)); beta itself when eps = 0."""
    if air_fraction == 0.0:
        return beta
    return 1.0 / (1.0 / beta + air_fraction * air_compliance_kernel(p))


@njit(cache=True)
def _dssqrt(dp, band):
    """d/d(dp) of the (regularised) signed square root."""
    a = abs(dp)
    if a >= band:
        return 0.5 / math.sqrt(a) if a > 0.0 else 1.0e30
    y = dp / band
    return math.sqrt(band) * (5.0 - 3.0 * y * y) * 0.25 / band


@njit(cache=True)
def supply_valve_pressure_kernel(p_s, p1, p2, g_s1, g_s2, k_rho, band, R):
    """Supply pressure at the valve [Pa] behind a line of quadratic resistance R
    [Pa s^2/m^6]: the root of f(pv) = pv - p_s + R q_s |q_s|, q_s = k_rho (g_s1 ssqrt(pv - p1)
    + g_s2 ssqrt(pv - p2)), g = alpha A of the supply edges [m^2]. f rises with pv, so the root
    is bracketed ([min(p1, p2, p_s), p_s] when q_s(p_s) >= 0, else [p_s, max(p1, p2)]) and found
    by Newton steps kept inside the bracket (bisection otherwise)."""
    if R <= 0.0:
        return p_s
    q = k_rho * (g_s1 * signed_sqrt_kernel(p_s - p1, band) + g_s2 * signed_sqrt_kernel(p_s - p2, band))
    if q == 0.0:
        return p_s
    if q > 0.0:
        lo = min(p1, p2, p_s)
        hi = p_s
    else:
        lo = p_s
        hi = max(p1, p2)
    pv = p_s
    for _ in range(60):
        q = k_rho * (g_s1 * signed_sqrt_kernel(pv - p1, band) + g_s2 * signed_sqrt_kernel(pv - p2, band))
        f = pv - p_s + R * q * abs(q)
        if f > 0.0:
            hi = pv
        else:
            lo = pv
        dq = k_rho * (g_s1 * _dssqrt(pv - p1, band) + g_s2 * _dssqrt(pv - p2, band))
        df = 1.0 + 2.0 * R * abs(q) * dq
        new = pv - f / df
        if not (lo < new < hi):
            new = 0.5 * (lo + hi)
        if abs(new - pv) < 1.0e-4 or hi - lo < 1.0e-4:
            return new
        pv = new
    return pv


@njit(cache=True)
def _flows_array(areas, alpha, p1, p2, ps, pr, k_rho, band, R):
    n = p1.size
    q1 = np.empty(n)
    q2 = np.empty(n)
    psv = np.empty(n)
    for i in range(n):
        if not (math.isfinite(p1[i]) and math.isfinite(p2[i]) and math.isfinite(ps[i])
                and math.isfinite(pr[i]) and math.isfinite(areas[0, i])):
            q1[i] = math.nan
            q2[i] = math.nan
            psv[i] = math.nan
            continue
        pv = supply_valve_pressure_kernel(ps[i], p1[i], p2[i], alpha[0] * areas[0, i],
                                          alpha[2] * areas[2, i], k_rho, band, R)
        psv[i] = pv
        q1[i] = k_rho * (alpha[0] * areas[0, i] * signed_sqrt_kernel(pv - p1[i], band)
                         + alpha[1] * areas[1, i] * signed_sqrt_kernel(pr[i] - p1[i], band))
        q2[i] = k_rho * (alpha[2] * areas[2, i] * signed_sqrt_kernel(p2[i] - pv, band)
                         + alpha[3] * areas[3, i] * signed_sqrt_kernel(p2[i] - pr[i], band))
    return q1, q2, psv


@njit(cache=True)
def _friction_dir_array(v, d_v, d_c, d_s, v0):
    out = np.empty(v.size)
    for i in range(v.size):
        vi = v[i]
        if vi == 0.0:
            out[i] = 0.0
            continue
        r2 = (vi / v0) * (vi / v0)
        f = d_c
        if r2 < 36.0:
            f += (d_s - d_c) * math.exp(-r2)
        out[i] = d_v * vi + (f if vi > 0.0 else -f)
    return out


# --- array functions -------------------------------------------------------------------------


def pressure_readings(p1_pa, p2_pa, effects: Effects | None):
    """What the pressure transducers record of the true chamber pressures.

    Returns
    -------
    (p1, p2) : ndarrays
        gain_p1 p1 + delta_p1, gain_p2 p2 + delta_p2. [Pa]
    """
    p1 = np.asarray(p1_pa, float)
    p2 = np.asarray(p2_pa, float)
    if effects is None:
        return p1, p2
    e = effects
    return (e.p1_sensor_gain * p1 + e.p1_sensor_offset_pa
            if (e.p1_sensor_gain != 1.0 or e.p1_sensor_offset_pa != 0.0) else p1,
            e.p2_sensor_gain * p2 + e.p2_sensor_offset_pa
            if (e.p2_sensor_gain != 1.0 or e.p2_sensor_offset_pa != 0.0) else p2)


def sensor_readings(x_m, p1_pa, p2_pa, effects: Effects | None):
    """What the transducers record of the true spool position and chamber pressures.

    Returns
    -------
    (x, p1, p2) : ndarrays
        x + delta_x [m], gain_p1 p1 + delta_p1 [Pa], gain_p2 p2 + delta_p2 [Pa].
    """
    x = np.asarray(x_m, float)
    if effects is not None and effects.spool_sensor_offset_m != 0.0:
        x = x + effects.spool_sensor_offset_m
    return (x, *pressure_readings(p1_pa, p2_pa, effects))


def true_signals(x_m, p1_pa, p2_pa, effects: Effects | None):
    """Inverse of :func:`sensor_readings`: the true x [m], p1, p2 [Pa] behind recorded ones."""
    x = np.asarray(x_m, float)
    p1 = np.asarray(p1_pa, float)
    p2 = np.asarray(p2_pa, float)
    if effects is None:
        return x, p1, p2
    e = effects
    return (x - e.spool_sensor_offset_m if e.spool_sensor_offset_m != 0.0 else x,
            (p1 - e.p1_sensor_offset_pa) / e.p1_sensor_gain
            if (e.p1_sensor_gain != 1.0 or e.p1_sensor_offset_pa != 0.0) else p1,
            (p2 - e.p2_sensor_offset_pa) / e.p2_sensor_gain
            if (e.p2_sensor_gain != 1.0 or e.p2_sensor_offset_pa != 0.0) else p2)


def effective_bulk_modulus(p_pa, bulk_modulus_pa: float, air_fraction: float):
    """beta_e(p) of fluid with entrained air (module docstring). [Pa]"""
    p = np.asarray(p_pa, float)
    if air_fraction == 0.0:
        return np.full(p.shape, float(bulk_modulus_pa))
    pa = np.maximum(p + P_ATM_PA, 0.1 * P_ATM_PA)
    h = (P_ATM_PA / pa) ** (1.0 / AIR_POLYTROPIC_EXPONENT) / (AIR_POLYTROPIC_EXPONENT * pa)
    return 1.0 / (1.0 / bulk_modulus_pa + air_fraction * h)


def valve_flows(x_m, p1_pa, p2_pa, p_s_pa, p_r_pa, params: PlantParams,
                condition: ValveCondition | None = None, effects: Effects | None = None,
                reg_band_pa: float = 0.0):
    """Eq. 4 with the supply line: (q1, q2, p_s,valve) for true spool position and pressures.

    Parameters
    ----------
    x_m : array_like, shape (n,)
        True spool position. [m]
    p1_pa, p2_pa, p_s_pa, p_r_pa : array_like, shape (n,)
        True chamber pressures, measured supply and return pressure. [Pa]
    params, condition, effects
        Plant, valve condition (default nominal) and effects (only the supply line matters).
    reg_band_pa : float
        Regularisation band of the orifice law (0 = exact). [Pa]

    Returns
    -------
    (q1, q2, p_sv) : ndarrays
        Flow into chamber 1, flow out of chamber 2 [m^3/s], supply pressure at the valve [Pa].
    """
    cond = params.nominal_condition if condition is None else condition
    x = np.ascontiguousarray(np.asarray(x_m, float).ravel())
    n = x.size
    arrs = [np.array(np.broadcast_to(np.asarray(a, float).ravel() if np.ndim(a) else float(a), (n,)))
            for a in (p1_pa, p2_pa, p_s_pa, p_r_pa)]  # writable copies: one compiled kind of array
    areas = _valve_areas_array(x, valve_edge_constants(params.geometry, cond))
    R = 0.0 if effects is None else effects.supply_resistance_pa_s2_m6
    return _flows_array(areas, np.asarray(cond.alpha, float), *arrs,
                        math.sqrt(2.0 / params.fluid.density_kg_m3), float(reg_band_pa), float(R))


def friction(v_X_m_s, params: PlantParams, effects: Effects | None = None) -> np.ndarray:
    """Eq. 5 Stribeck friction F_f(v_X) [N] with the friction change; 0 at v_X = 0."""
    c = apply_to_params(params, effects).cylinder
    v = np.ascontiguousarray(np.asarray(v_X_m_s, float).ravel())
    return _friction_dir_array(v, c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.v0_m_s)


def equation_terms(signals: dict, params: PlantParams, condition: ValveCondition | None = None,
                   effects: Effects | None = None, reg_band_pa: float = 0.0, only=None) -> dict:
    """Every term of the chamber equations (Eq. 6 with leakage and air) and of the motion
    equation (Eq. 5), with ``effects``, at each sample of recorded signals.

    Parameters
    ----------
    signals : dict of arrays, shape (n,)
        Recorded ``x`` [m], ``p1``, ``p2``, ``ps``, ``pr`` [Pa], ``X`` [m] and the cylinder
        velocity ``v`` [m/s] (e.g. a Savitzky-Golay derivative of X).
    params, condition, effects, reg_band_pa
        As in :func:`valve_flows`; the sensor effects are inverted first
        (:func:`true_signals`).
    only : collection of str, optional
        Compute only these terms (``p1`` and ``p2`` always), e.g. ``("q1", "q2")`` where only
        the valve's parameters changed; default every term.

    Returns
    -------
    dict of arrays
        ``p1``, ``p2`` true pressures [Pa]; ``q1`` flow into chamber 1 and ``q2`` flow out of
        chamber 2 through the valve [m^3/s]; ``ql1`` flow leaving chamber 1 other than through
        the valve and the piston (q_i) and ``ql2`` flow leaving chamber 2 likewise (q_e - q_i)
        [m^3/s]; ``c1`` = V1/beta_e(p1), ``c2`` = V2/beta_e(p2) [m^3/Pa]; ``force`` = m g + A1 p1
        - A2 p2 - F_f(v) [N] (no load, no inertia); ``mass`` [kg] (scalar); ``ps_valve`` [Pa].
        Chamber equations: c1 dp1/dt = q1 - A1 v - ql1, c2 dp2/dt = A2 v - q2 - ql2; motion:
        mass dv/dt = force - F_l.
    """
    e = Effects() if effects is None else effects
    want = set(("q1", "q2", "ql1", "ql2", "c1", "c2", "force", "mass", "ps_valve") if only is None else only)
    x, p1, p2 = true_signals(signals["x"], signals["p1"], signals["p2"], e)
    out = {"p1": p1, "p2": p2}
    if want & {"q1", "q2", "ps_valve"}:
        out["q1"], out["q2"], out["ps_valve"] = valve_flows(x, p1, p2, signals["ps"], signals["pr"], params, condition, e,
                                                            reg_band_pa)
    if want & {"ql1", "ql2"}:
        qi = e.internal_leakage_m3_s_pa * (p1 - p2)
        qe = e.external_leakage_m3_s_pa * p2
        out["ql1"], out["ql2"] = qi, qe - qi
    c = apply_to_params(params, e).cylinder
    if want & {"c1", "c2"}:
        X = np.asarray(signals["X"], float)
        beta = params.fluid.bulk_modulus_pa
        out["c1"] = (c.v01_m3 + c.A1 * X) / effective_bulk_modulus(p1, beta, e.air_fraction)
        out["c2"] = (c.v02_m3 - c.A2 * X) / effective_bulk_modulus(p2, beta, e.air_fraction)
    if "force" in want:
        v = np.asarray(signals["v"], float)
        out["force"] = c.weight_n + c.A1 * p1 - c.A2 * p2 - friction(v, params, e).reshape(v.shape)
    if "mass" in want:
        out["mass"] = c.mass_kg
    return out

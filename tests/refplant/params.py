"""Parameters of the second reference plant: frozen dataclasses, SI units, named presets.

Written from the equations of the method (spool Eq. 1, orifice Eq. 2, area Eq. 3, cylinder Eq. 5,
chambers Eq. 6) and the paper's Table 1, apart from ``model/``: nothing here is imported from
the project's packages. Edges are ordered ``("s1", "1r", "s2", "2r")``; each edge has its opening
coordinate u = +x (s1, 2r) or u = -x (1r, s2), in which a larger underlap is "more open".

Presets: :data:`NAMEPLATE` (the design data, Table 1, Eq. 3 edges), :func:`family` (the edge
law of every edge), :func:`manufactured` (scatter of underlaps and alpha per edge, beta off its
nameplate), :func:`worn` (alpha scale and underlap shift per edge), :func:`idealised` (every
deliberate difference from ``model/`` switched off, for the cross-check).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

EDGES: tuple[str, str, str, str] = ("s1", "1r", "s2", "2r")
#: u = OPENING[i] * x for edge EDGES[i].
OPENING: tuple[float, float, float, float] = (1.0, -1.0, -1.0, 1.0)
#: Port (1 head side, 2 rod side) of each edge.
PORT: tuple[int, int, int, int] = (1, 1, 2, 2)
#: Edge laws (:mod:`.edges`): Eq. 3; sharp conical edge without radial clearance; linear gradient;
#: linear gradient whose discharge coefficient falls at small openings (laminar region).
LAWS: tuple[str, str, str, str] = ("eq3", "sharp", "linear", "laminar")


@dataclass(frozen=True)
class Edge:
    """One control edge.

    Attributes
    ----------
    law : str
        ``"eq3"`` (Eq. 3: conical gap with the radial clearance and a leakage branch),
        ``"sharp"`` (the exact conical-gap area of a sharp edge with no radial clearance:
        A = pi h (2R - h cos phi), h = max(u + x_u, 0) sin phi; no closed-edge leakage) or
        ``"linear"`` (alpha A = alpha g max(u + x_u, 0): a linear gradient g and a hard corner,
        no radial clearance, no leakage) or ``"laminar"`` (the linear gradient whose orifice law
        leaves Eq. 4's near the corner: the discharge coefficient is alpha tanh(2 lambda /
        lambda_t), lambda = (D_h / nu) sqrt(2 |dp| / rho) the flow number of the slot, D_h = 2 s,
        s = u + x_u; laminar, q ~ s^2 dp, at small openings and pressure drops). [-]
    underlap_m : float
        Underlap x_u in the edge's opening coordinate (> 0: open at x = 0). [m]
    alpha : float
        Contraction (discharge) coefficient alpha of Eq. 2, C_q of the linear law. [-]
    gradient_m : float
        Linear law only: area gradient g = dA/du [m^2/m = m]; 0 = the port's f pi d with
        f = sin(phi) and d = 2R (:meth:`Valve.port_gradient`).
    x_l_fraction : float
        Eq. 3 only: x_l = -x_u + f delta, f in (0, 1] (onset of the leakage branch). [-]
    transition_flow_number : float
        Laminar law only: lambda_t, the flow number about which the discharge coefficient reaches
        its turbulent value (1000: Merritt's sharp-edged orifice; 0.76 alpha at lambda_t / 2). [-]
    """

    law: str = "eq3"
    underlap_m: float = 40.0e-6
    alpha: float = 0.675
    gradient_m: float = 0.0
    x_l_fraction: float = 0.5
    transition_flow_number: float = 1000.0

    def __post_init__(self):
        if self.law not in LAWS:
            raise ValueError(f"edge law must be one of {LAWS}, got {self.law!r}")
        if not self.alpha > 0:
            raise ValueError("alpha must be > 0")
        if self.gradient_m < 0:
            raise ValueError("gradient_m must be >= 0")
        if not 0.0 < self.x_l_fraction <= 1.0:
            raise ValueError("x_l_fraction must lie in (0, 1]")
        if not self.transition_flow_number > 0:
            raise ValueError("transition_flow_number must be > 0")


@dataclass(frozen=True)
class Valve:
    """Servo valve third stage (Table 1) with its four edges in EDGES order.

    Attributes
    ----------
    x_max_m : float  Spool stroke limit. [m] (3.5 mm)
    bore_radius_m : float  R. [m] (10.00 mm)
    spool_radius_m : float  r. [m] (9.99 mm)
    taper1_rad, taper2_rad : float  phi1 (port 1: s1, 1r), phi2 (port 2: s2, 2r). [rad]
    edges : tuple of 4 Edge
    """

    x_max_m: float = 3.5e-3
    bore_radius_m: float = 10.00e-3
    spool_radius_m: float = 9.99e-3
    taper1_rad: float = math.radians(10.48)
    taper2_rad: float = math.radians(5.24)
    edges: tuple[Edge, Edge, Edge, Edge] = (Edge(),) * 4

    def __post_init__(self):
        if len(self.edges) != 4:
            raise ValueError(f"need 4 edges in order {EDGES}")
        if not self.bore_radius_m > self.spool_radius_m > 0:
            raise ValueError("need bore_radius_m > spool_radius_m > 0")

    def taper(self, i: int) -> float:
        """Taper angle of edge i. [rad]"""
        return self.taper1_rad if PORT[i] == 1 else self.taper2_rad

    def port_gradient(self, i: int) -> float:
        """Default linear-law gradient of edge i: f pi d, f = sin(phi of its port), d = 2R. [m]"""
        return math.sin(self.taper(i)) * math.pi * 2.0 * self.bore_radius_m

    def gradient(self, i: int) -> float:
        """The linear- or laminar-law gradient of edge i (its own, else the port's). [m]"""
        g = self.edges[i].gradient_m
        return g if g > 0 else self.port_gradient(i)

    def with_edges(self, **per_edge) -> "Valve":
        """A copy with fields of every edge replaced; each value a scalar or 4 values in EDGES order,
        e.g. ``with_edges(law="linear", alpha=(0.7, 0.66, 0.68, 0.69))``."""
        edges = list(self.edges)
        for name, value in per_edge.items():
            vals = value if isinstance(value, (tuple, list, np.ndarray)) else (value,) * 4
            if len(vals) != 4:
                raise ValueError(f"{name}: need 4 values in order {EDGES}")
            edges = [replace(e, **{name: (float(v) if not isinstance(v, str) else v)}) for e, v in zip(edges, vals)]
        return replace(self, edges=tuple(edges))


@dataclass(frozen=True)
class Spool:
    """Eq. 1: T [s] (1 ms), zeta [-] (1), v_max [m/s] (velocity limit; 0.3 m/s)."""

    T_s: float = 1.0e-3
    zeta: float = 1.0
    v_max_m_s: float = 0.3


@dataclass(frozen=True)
class Cylinder:
    """Eqs. 5 and 6 (Table 1; volumes, static friction chosen as documented in model.md's list).

    Attributes
    ----------
    piston_diameter_m, rod_diameter_m, stroke_m : [m] (0.140, 0.100, 0.610)
    mass_kg : [kg] (6000)
    g_m_s2 : [m/s^2] (9.81; +m g in F_R: the load hangs from the rod)
    d_v_n_s_m : viscous friction [N s/m] (100 kN s/m)
    d_c_n : Coulomb friction [N] (2 kN)
    d_s_n : static friction [N] (6 kN; Table 1: 4-10 kN)
    v0_m_s : Stribeck velocity [m/s] (0.015)
    v01_m3, v02_m3 : chamber volumes at X = 0 [m^3] (3.0 L, 7.1 L; V02 includes the stroke volume)
    karnopp_band_m_s : half-width of the stick band around v_X = 0 [m/s] (1 mm/s): inside it the
        rod sticks while |F_R| <= d_s (Karnopp)
    stick_time_s : inside the band and sticking, v_X decays as dv_X/dt = -v_X / stick_time [s] (1 ms)
    """

    piston_diameter_m: float = 0.140
    rod_diameter_m: float = 0.100
    stroke_m: float = 0.610
    mass_kg: float = 6000.0
    g_m_s2: float = 9.81
    d_v_n_s_m: float = 100.0e3
    d_c_n: float = 2.0e3
    d_s_n: float = 6.0e3
    v0_m_s: float = 0.015
    v01_m3: float = 3.0e-3
    v02_m3: float = 7.1e-3
    karnopp_band_m_s: float = 1.0e-3
    stick_time_s: float = 1.0e-3

    @property
    def A1(self) -> float:
        """pi D^2 / 4. [m^2]"""
        return math.pi * self.piston_diameter_m**2 / 4.0

    @property
    def A2(self) -> float:
        """A1 - pi d^2 / 4. [m^2]"""
        return self.A1 - math.pi * self.rod_diameter_m**2 / 4.0


@dataclass(frozen=True)
class Fluid:
    """beta [Pa] (1.5 GPa nameplate), rho [kg/m^3] (870), dp_transition_pa: the orifice law
    sign(dp) sqrt|dp| is replaced by dp / (dp^2 + dp_t^2)^(1/4) (smooth through 0, within 2.5e-5
    relative of the square root at 1 bar for dp_t = 10 mbar). [Pa]
    nu: kinematic viscosity [m^2/s] (32 mm^2/s, ISO VG 32 at 40 degC; the laminar edge law)."""

    bulk_modulus_pa: float = 1.5e9
    density_kg_m3: float = 870.0
    dp_transition_pa: float = 1.0e3
    kinematic_viscosity_m2_s: float = 32.0e-6


@dataclass(frozen=True)
class Supply:
    """p_s(t) = p_s + drift t + ripple sin(2 pi f t + phase) (level, drift and phase drawn per
    window: level +- spread, drift +- drift_max); p_r constant. [Pa], [Pa/s], [Hz]"""

    p_s_pa: float = 200.0e5
    p_s_spread_pa: float = 7.0e5
    drift_max_pa_s: float = 0.1e5
    ripple_pa: float = 0.3e5
    ripple_hz: float = 225.0
    p_r_pa: float = 0.5e5


@dataclass(frozen=True)
class Controller:
    """Continuous-time PI position controller with anti-windup and velocity feed-forward:

        u = w_ff x_ff(v_ref) + K_p (X_ref - X) + z,  x_ref = sat(u, +-x_lim),
        dz/dt = K_p / T_i (X_ref - X) + (x_ref - u) / T_t

    x_ff is closed-form: the steady spool opening of a linear-gradient valve (the valve's own
    port gradients, its mean alpha, no underlap) moving at v_ref without load (:mod:`.plant`).
    K_p [m/m], T_i [s], T_t [s], x_lim [m] (None = x_max), w_ff [-]."""

    kp_m_per_m: float = 0.06
    ti_s: float = 0.6
    tt_s: float = 0.1
    x_limit_m: float | None = None
    feedforward: float = 1.0


@dataclass(frozen=True)
class Channel:
    """One recorded signal: noise std, quantisation step, range (SI)."""

    noise: float
    step: float
    lo: float
    hi: float


@dataclass(frozen=True)
class Sensors:
    """What the acquisition records, at ``sample_rate_hz``.

    Pressure transmitters (ps, pr, p1, p2) have a first-order lag ``lag_s`` (1 ms each; a tuple
    in the order ps, pr, p1, p2); the pressure channels are recorded ``skew_samples`` samples late
    against the position channels (1: the pressure at t_{k-1} is stored at t_k). Noise and 16-bit
    quantisation as a mill's acquisition: 0.05 bar on 0-250 bar, 1 um on the positions.
    ``fine_per_sample``: sub-steps per sample on which the lag is computed from the dense output."""

    sample_rate_hz: float = 1000.0
    lag_s: tuple[float, float, float, float] = (1.0e-3,) * 4
    skew_samples: int = 1
    ps: Channel = Channel(0.05e5, 250e5 / 2**16, 0.0, 250e5)
    pr: Channel = Channel(0.05e5, 25e5 / 2**16, 0.0, 25e5)
    p1: Channel = Channel(0.05e5, 250e5 / 2**16, 0.0, 250e5)
    p2: Channel = Channel(0.05e5, 250e5 / 2**16, 0.0, 250e5)
    x_spool: Channel = Channel(1.0e-6, 8e-3 / 2**16, -4e-3, 4e-3)
    x_cyl: Channel = Channel(1.0e-6, 1.0e-6, -0.005, 0.615)
    x_ref: Channel = Channel(0.0, 8e-3 / 2**16, -4e-3, 4e-3)
    fine_per_sample: int = 10


@dataclass(frozen=True)
class Operation:
    """Operating conditions of the positioning unit.

    Reference: minimum-jerk moves between targets in [X_low, X_high] alternating in direction,
    peak speeds drawn in ``v_extend`` / ``v_retract`` [m/s], dwells [s] between them (a window
    starts with ``first_dwell``). Load: a new level every ``load_interval_s`` (uniform) [s],
    0 with probability ``load_p_zero`` else uniform in +-``load_max_n`` [N], reached by a linear
    ramp of ``load_ramp_s`` [s] (a rolling force: continuous, piecewise linear)."""

    X_low_m: float = 0.04
    X_high_m: float = 0.57
    min_travel_m: float = 0.15
    v_extend_m_s: tuple[float, float] = (0.14, 0.24)
    v_retract_m_s: tuple[float, float] = (0.07, 0.13)
    dwell_s: tuple[float, float] = (0.2, 0.8)
    first_dwell_s: tuple[float, float] = (0.2, 0.5)
    load_interval_s: tuple[float, float] = (1.0, 4.0)
    load_max_n: float = 6.0e3
    load_p_zero: float = 0.2
    load_ramp_s: tuple[float, float] = (0.1, 0.4)


@dataclass(frozen=True)
class Integration:
    """solve_ivp settings: method (LSODA, BDF or Radau), rtol, atol per state scale."""

    method: str = "LSODA"
    rtol: float = 1.0e-6
    max_step_s: float = 2.0e-3


@dataclass(frozen=True)
class RefPlant:
    """The whole second reference plant."""

    valve: Valve = field(default_factory=Valve)
    spool: Spool = field(default_factory=Spool)
    cylinder: Cylinder = field(default_factory=Cylinder)
    fluid: Fluid = field(default_factory=Fluid)
    supply: Supply = field(default_factory=Supply)
    controller: Controller = field(default_factory=Controller)
    sensors: Sensors = field(default_factory=Sensors)
    operation: Operation = field(default_factory=Operation)
    integration: Integration = field(default_factory=Integration)

    @property
    def x_limit_m(self) -> float:
        c = self.controller.x_limit_m
        return self.valve.x_max_m if c is None else min(c, self.valve.x_max_m)


#: The design data (Table 1, Eq. 3 edges, underlap 0.04 mm, alpha 0.675, beta 1.5 GPa).
NAMEPLATE = RefPlant()


def family(plant: RefPlant, law: str) -> RefPlant:
    """``plant`` with every edge on ``law`` (``"eq3"``, ``"sharp"``, ``"linear"``, ``"laminar"``)."""
    return replace(plant, valve=plant.valve.with_edges(law=law))


def manufactured(plant: RefPlant = NAMEPLATE, seed: int = 0, *, underlap_sd_m: float = 5.0e-6,
                 alpha_sd: float = 0.03, beta_off: float = 0.025) -> RefPlant:
    """A valve as built: every edge's underlap + N(0, ``underlap_sd_m``) and alpha x (1 + N(0,
    ``alpha_sd``)), drawn from ``seed``; beta ``beta_off`` (relative) off its nameplate."""
    rng = np.random.default_rng([int(seed), 2323])
    v = plant.valve
    xu = [e.underlap_m + underlap_sd_m * rng.normal() for e in v.edges]
    al = [e.alpha * (1.0 + alpha_sd * rng.normal()) for e in v.edges]
    fluid = replace(plant.fluid, bulk_modulus_pa=plant.fluid.bulk_modulus_pa * (1.0 + beta_off))
    return replace(plant, valve=v.with_edges(underlap_m=tuple(xu), alpha=tuple(al)), fluid=fluid)


def worn(plant: RefPlant, *, alpha_scale=(1.0,) * 4, underlap_shift_m=(0.0,) * 4) -> RefPlant:
    """Wear per edge: alpha x ``alpha_scale`` and underlap + ``underlap_shift_m`` (opening
    coordinate, > 0 more open), each 4 values in EDGES order or a dict ``{"s2": 1.15}``."""

    def four(v, neutral):
        if isinstance(v, dict):
            unknown = set(v) - set(EDGES)
            if unknown:
                raise ValueError(f"unknown edges {sorted(unknown)}; expected {EDGES}")
            return tuple(float(v.get(e, neutral)) for e in EDGES)
        return tuple(float(x) for x in v)

    a, s = four(alpha_scale, 1.0), four(underlap_shift_m, 0.0)
    v = plant.valve
    return replace(plant, valve=v.with_edges(
        alpha=tuple(e.alpha * k for e, k in zip(v.edges, a)),
        underlap_m=tuple(e.underlap_m + d for e, d in zip(v.edges, s))))


def position_sensors(plant: RefPlant, *, spool_noise_fraction: float, cylinder_noise_m: float,
                     cylinder_step_m: float) -> RefPlant:
    """``plant`` whose position transmitters record as a plant's do: spool noise
    ``spool_noise_fraction`` of x_max with 16-bit steps over its range, cylinder noise
    ``cylinder_noise_m`` [m] in steps of ``cylinder_step_m`` [m] (pressures unchanged)."""
    s = plant.sensors
    spool = replace(s.x_spool, noise=spool_noise_fraction * plant.valve.x_max_m)
    cyl = replace(s.x_cyl, noise=float(cylinder_noise_m), step=float(cylinder_step_m))
    return replace(plant, sensors=replace(s, x_spool=spool, x_cyl=cyl))


def plant_grade(plant: RefPlant = NAMEPLATE, seed: int = 0) -> RefPlant:
    """``plant`` with position transmitters drawn from what plants record, per plant (``seed``):
    spool noise uniform in 0.05-0.3 % of x_max (16-bit steps), cylinder noise uniform in 1-20 um
    in steps drawn from 1-5 um."""
    rng = np.random.default_rng([int(seed), 4747])
    return position_sensors(plant, spool_noise_fraction=float(rng.uniform(0.5e-3, 3.0e-3)),
                            cylinder_noise_m=float(rng.uniform(1.0e-6, 20.0e-6)),
                            cylinder_step_m=float(rng.integers(1, 6)) * 1.0e-6)


def noisy_end(plant: RefPlant = NAMEPLATE) -> RefPlant:
    """``plant`` at the noisy end of plant sensor quality: spool 0.2 % of x_max (7 um),
    cylinder 10 um in 5 um steps."""
    return position_sensors(plant, spool_noise_fraction=2.0e-3, cylinder_noise_m=10.0e-6, cylinder_step_m=5.0e-6)


def sparse(plant: RefPlant = NAMEPLATE) -> RefPlant:
    """``plant`` operated as a positioning cylinder on a mill: it moves between positions and
    dwells there 2-10 s (a window starts with 0.5-3 s; the default dwells 0.2-0.8 s)."""
    return replace(plant, operation=replace(plant.operation, dwell_s=(2.0, 10.0), first_dwell_s=(0.5, 3.0)))


def idealised(plant: RefPlant = NAMEPLATE) -> RefPlant:
    """Every deliberate difference from ``model/`` off: no transmitter lag, no skew, a stick band
    of 1 um/s (Karnopp's band shrunk to a near-exact stick condition), Eq. 3 edges, no load steps
    (the caller passes a constant load)."""
    return replace(
        family(plant, "eq3"),
        sensors=replace(plant.sensors, lag_s=(0.0,) * 4, skew_samples=0),
        cylinder=replace(plant.cylinder, karnopp_band_m_s=1.0e-6, stick_time_s=1.0e-4),
    )

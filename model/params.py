"""Parameters of the valve, the positioning unit and its operation, in SI units.

Every parameter set is a frozen dataclass, so a parameter set is a value: it can be
hashed, compared and used as a cache key. :data:`TABLE1` is the preset of the paper's
Table 1 (Steinboeck et al. 2013) completed by documented choices for every value the paper
leaves open (``docs/model.md``, section "Parameters").

Conventions: edges are ordered :data:`EDGES`; each edge has its opening coordinate
u = +x (s1, 2r) or u = -x (1r, s2), in which a positive underlap change means "more open".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

#: The four control edges, in the order used by every per-edge tuple and array.
EDGES: tuple[str, str, str, str] = ("s1", "1r", "s2", "2r")

#: Opening direction of each edge: u = OPENING_SIGN[edge] * x.
OPENING_SIGN: dict[str, float] = {"s1": 1.0, "1r": -1.0, "s2": -1.0, "2r": 1.0}

#: Port of each edge (1 = head side, taper angle phi1; 2 = rod side, phi2).
EDGE_PORT: dict[str, int] = {"s1": 1, "1r": 1, "s2": 2, "2r": 2}


#: The valve families' area laws (:class:`ValveGeometry` ``area_law``).
AREA_LAWS: tuple[str, str, str] = ("eq3", "sharp", "linear")


def edge_index(edge: str) -> int:
    """Position of ``edge`` in :data:`EDGES`; raises ``ValueError`` for an unknown name."""
    try:
        return EDGES.index(edge)
    except ValueError:
        raise ValueError(f"unknown edge {edge!r}; expected one of {EDGES}") from None


def _four(name: str, value) -> tuple[float, float, float, float]:
    if isinstance(value, (int, float)):
        value = (float(value),) * 4
    value = tuple(float(v) for v in value)
    if len(value) != 4:
        raise ValueError(f"{name} needs 4 values in EDGES order {EDGES}, got {len(value)}")
    return value  # type: ignore[return-value]


@dataclass(frozen=True)
class ValveGeometry:
    """Design geometry of the servo valve's third stage (paper Table 1, Fig. 1).

    Attributes
    ----------
    x_max_m : float
        Maximum spool displacement; the spool moves in [-x_max, x_max]. [m] (Table 1: 3.5 mm)
    bore_radius_m : float
        Radius R of the valve bore. [m] (Table 1: 10.00 mm)
    spool_radius_m : float
        Radius r of the spool. [m] (Table 1: 9.99 mm; radial clearance R - r = 10 um)
    taper_angle_port1_rad : float
        Taper angle phi1 of the control edges of port 1 (s1, 1r). [rad] (Table 1: 10.48 deg)
    taper_angle_port2_rad : float
        Taper angle phi2 of the control edges of port 2 (s2, 2r). [rad] (Table 1: 5.24 deg)
    area_law : str
        The valve family's area law (:mod:`model.area`): ``"eq3"`` (the paper's Eq. 3, with the
        radial-clearance annulus and the closed edge's leakage branch), ``"sharp"`` (sharp
        edges: A = 0 below -x_u, linear above, no radial-clearance intercept, no leakage) or
        ``"linear"`` (the linear-gradient, hard-corner edge of system simulators' valve
        components: A = sin(phi) pi d max(u + x_u, 0), d = 2r the spool diameter; no
        clearance, no leakage). [-]
    leakage_factor : float
        Eq. 3 only: the closed edge's leakage branch, far from the edge, is this many times
        Eq. 3's (worn lands); continuous at x_l; 1 = Eq. 3. [-]
    """

    x_max_m: float = 3.5e-3
    bore_radius_m: float = 10.00e-3
    spool_radius_m: float = 9.99e-3
    taper_angle_port1_rad: float = math.radians(10.48)
    taper_angle_port2_rad: float = math.radians(5.24)
    area_law: str = "eq3"
    leakage_factor: float = 1.0

    def __post_init__(self):
        if not self.bore_radius_m > self.spool_radius_m > 0:
            raise ValueError("need bore_radius_m > spool_radius_m > 0")
        for a in (self.taper_angle_port1_rad, self.taper_angle_port2_rad):
            if not 0 < a < math.pi / 2:
                raise ValueError("taper angles must lie in (0, pi/2) rad")
        if self.x_max_m <= 0:
            raise ValueError("x_max_m must be > 0")
        if self.area_law not in AREA_LAWS:
            raise ValueError(f"area_law must be one of {AREA_LAWS}, got {self.area_law!r}")
        if not self.leakage_factor > 0:
            raise ValueError("leakage_factor must be > 0")

    @property
    def radial_clearance_m(self) -> float:
        """Radial clearance R - r between bore and spool. [m]"""
        return self.bore_radius_m - self.spool_radius_m

    def taper_angle(self, edge: str) -> float:
        """Taper angle of ``edge`` (phi1 for s1 and 1r, phi2 for s2 and 2r). [rad]"""
        edge_index(edge)
        return self.taper_angle_port1_rad if EDGE_PORT[edge] == 1 else self.taper_angle_port2_rad

    def taper_angles(self) -> tuple[float, float, float, float]:
        """Taper angles of all edges in :data:`EDGES` order. [rad]"""
        return tuple(self.taper_angle(e) for e in EDGES)  # type: ignore[return-value]

    def transition_width(self, edge: str) -> float:
        """delta = (R - r) tan(phi): width of the transition branch of Eq. 3. [m]"""
        return self.radial_clearance_m * math.tan(self.taper_angle(edge))


@dataclass(frozen=True)
class ValveCondition:
    """Condition of the four control edges (what wear and faults change).

    Attributes
    ----------
    underlap_m : tuple of 4 float
        Underlap x_u of each edge in :data:`EDGES` order, in the edge's opening coordinate
        (> 0: the edge is open at x = 0). [m] Default 0.04 mm on every edge: the plant
        configuration's example value, within model.md's "a few hundredths of a millimetre up to
        about 0.1 mm" and about 1 % of x_max.
    alpha : tuple of 4 float
        Contraction coefficient of each edge, Eq. 2. [-] Nominal 0.675 (the plant
        configuration's ``contraction_coefficient``; typical of sharp-edged spool orifices,
        0.6-0.7).
    x_l_fraction : float
        Onset of the leakage branch of Eq. 3 as a fraction f of the transition width:
        x_l = -x_u + f * delta with delta = (R - r) tan(phi). model.md requires
        x_l in (-x_u, -x_u + delta], i.e. f in (0, 1]; default f = 1/2 (model.md's example).
        Tying x_l to x_u makes an underlap change an exact shift of the whole characteristic. [-]
    """

    underlap_m: tuple[float, float, float, float] = (4.0e-5,) * 4
    alpha: tuple[float, float, float, float] = (0.675,) * 4
    x_l_fraction: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "underlap_m", _four("underlap_m", self.underlap_m))
        object.__setattr__(self, "alpha", _four("alpha", self.alpha))
        if any(a <= 0 for a in self.alpha):
            raise ValueError("contraction coefficients must be > 0")
        if not 0.0 < self.x_l_fraction <= 1.0:
            raise ValueError("x_l_fraction must lie in (0, 1] (model.md: x_l in (-x_u, -x_u+delta])")

    @classmethod
    def nominal(cls, underlap_m: float = 4.0e-5, alpha: float = 0.675) -> "ValveCondition":
        """A symmetric valve: the same underlap [m] and contraction coefficient [-] on every edge."""
        return cls(underlap_m=(underlap_m,) * 4, alpha=(alpha,) * 4)

    def x_l_m(self, geometry: ValveGeometry) -> tuple[float, float, float, float]:
        """x_l of every edge in its opening coordinate, Eq. 3. [m]"""
        return tuple(
            -xu + self.x_l_fraction * geometry.transition_width(e)
            for e, xu in zip(EDGES, self.underlap_m)
        )  # type: ignore[return-value]

    def with_edge(self, edge: str, *, underlap_m: float | None = None,
                  alpha: float | None = None) -> "ValveCondition":
        """A copy with one edge's underlap [m] and/or contraction coefficient [-] replaced."""
        i = edge_index(edge)
        xu = list(self.underlap_m)
        al = list(self.alpha)
        if underlap_m is not None:
            xu[i] = underlap_m
        if alpha is not None:
            al[i] = alpha
        return replace(self, underlap_m=tuple(xu), alpha=tuple(al))


@dataclass(frozen=True)
class SpoolParams:
    """Spool dynamics, Eq. 1.

    Attributes
    ----------
    T_s : float
        Characteristic time T. [s] (Table 1: 1 ms)
    zeta : float
        Damping coefficient zeta; Eq. 1 requires zeta >= 1 so the spool cannot overshoot
        +-x_max. [-] (Table 1: 1)
    v_max_m_s : float
        Spool velocity limit v_max. [m/s] Not in the paper. Chosen 0.3 m/s: a full-stroke
        step (0 to x_max = 3.5 mm) then takes about 12 ms plus the 2nd-order tail, in line with
        the 10-20 ms 0-100 % step response of large three-stage servo valves, whereas the
        unsaturated model (T = 1 ms) would reach 1.3 m/s on such a step. Small-signal
        behaviour (|dx| < 0.8 mm, peak speed |dx|/(e T)) is unaffected.
    """

    T_s: float = 1.0e-3
    zeta: float = 1.0
    v_max_m_s: float = 0.3

    def __post_init__(self):
        if self.T_s <= 0 or self.v_max_m_s <= 0:
            raise ValueError("T_s and v_max_m_s must be > 0")
        if self.zeta < 1.0:
            raise ValueError("Eq. 1 needs zeta >= 1 (no overshoot beyond +-x_max)")


@dataclass(frozen=True)
class CylinderParams:
    """Differential cylinder, load and friction, Eqs. 5 and 6 (Table 1 unless stated).

    Attributes
    ----------
    piston_diameter_m : float
        Piston diameter D. [m] (0.140)
    rod_diameter_m : float
        Rod diameter d. [m] (0.100)
    stroke_m : float
        Stroke; X in [0, stroke]. [m] (0.610)
    mass_kg : float
        Moving mass m (load, piston and rod). [kg] (6000)
    g_m_s2 : float
        Gravitational acceleration. [m/s^2] (9.81). Enters F_R as +m g: the load hangs from the
        rod, so gravity helps extension (model.md).
    d_v_n_s_m : float
        Viscous friction coefficient d_v. [N s/m] (100 kN s/m)
    d_c_n : float
        Coulomb (minimum kinetic) friction force d_c. [N] (2 kN)
    d_s_n : float
        Static friction force d_s. [N] Table 1 gives 4-10 kN; chosen 6 kN, close to the
        geometric mean (6.3 kN) of the range and 3 x d_c, so the Stribeck curve falls from
        6 kN at breakaway to 2 kN, a moderate stick-slip tendency.
    v0_m_s : float
        Stribeck velocity v_0. [m/s] (0.015)
    v01_m3 : float
        Head-side volume V_01 at X = 0, chamber dead volume plus piping. [m^3] (3.0 L; plant
        configuration ``v01_l``)
    v02_m3 : float
        Rod-side volume V_02 at X = 0, piping and the rod-side stroke volume included
        (A2 * stroke = 4.6 L, leaving 2.5 L at full extension). [m^3] (7.1 L; ``v02_l``)
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

    def __post_init__(self):
        if not self.piston_diameter_m > self.rod_diameter_m > 0:
            raise ValueError("need piston_diameter_m > rod_diameter_m > 0")
        if self.v01_m3 <= 0 or self.v02_m3 <= self.A2 * self.stroke_m:
            raise ValueError("need v01_m3 > 0 and v02_m3 > A2 * stroke (V2 > 0 over the stroke)")
        if self.d_s_n < self.d_c_n:
            raise ValueError("static friction d_s must be >= Coulomb friction d_c")

    @property
    def A1(self) -> float:
        """Head-side piston area A1 = pi D^2 / 4. [m^2]"""
        return math.pi * self.piston_diameter_m**2 / 4.0

    @property
    def A2(self) -> float:
        """Rod-side annulus area A2 = A1 - pi d^2 / 4. [m^2]"""
        return self.A1 - math.pi * self.rod_diameter_m**2 / 4.0

    @property
    def weight_n(self) -> float:
        """m g. [N]"""
        return self.mass_kg * self.g_m_s2


@dataclass(frozen=True)
class FluidParams:
    """Hydraulic fluid (Table 1).

    Attributes
    ----------
    bulk_modulus_pa : float
        Bulk modulus beta. [Pa] (Table 1: 1.4-1.6 GPa; mid value 1.5 GPa)
    density_kg_m3 : float
        Mass density rho. [kg/m^3] (870)
    """

    bulk_modulus_pa: float = 1.5e9
    density_kg_m3: float = 870.0


@dataclass(frozen=True)
class SupplyParams:
    """Supply and return pressure seen by the valve (all measured; Table 1: p_s 190-210 bar).

    p_s(t) = p_s0 + drift * t + A sin(2 pi f t + phase), with p_s0 drawn per window uniformly
    in p_s_nominal +- p_s_window_spread, the drift rate drawn uniformly in +-drift_max and a
    random ripple phase.

    Attributes
    ----------
    p_s_nominal_pa : float
        Nominal supply pressure. [Pa] (200 bar, the middle of Table 1's range)
    p_s_window_spread_pa : float
        Half-width of the per-window supply level. [Pa] 7 bar, so levels cover most of
        Table 1's 190-210 bar (slow day-to-day changes of the pressure controller set point
        and accumulator state).
    p_s_drift_max_pa_s : float
        Largest slow drift rate within a window. [Pa/s] 0.1 bar/s, i.e. at most 1 bar over a
        10 s window (accumulator charge/discharge, slow enough that dp_s/dt is negligible,
        as the paper assumes).
    ripple_amplitude_pa : float
        Pump ripple amplitude. [Pa] 0.3 bar: a 9-piston pump behind an accumulator and
        long supply lines; a few tenths of a bar is typical at the valve.
    ripple_frequency_hz : float
        Pump ripple frequency. [Hz] 225 Hz = 9 pistons x 1500 rpm / 60, below the 500 Hz
        Nyquist limit of the 1 kHz acquisition.
    p_r_nominal_pa : float
        Return (tank) pressure. [Pa] 0.5 bar gauge: return-filter back pressure; "for all
        practical purposes p_r = 0 bar" (paper Sec. 5.1).
    p_r_window_spread_pa : float
        Half-width of the per-window return pressure level. [Pa] 0.2 bar.
    """

    p_s_nominal_pa: float = 200.0e5
    p_s_window_spread_pa: float = 7.0e5
    p_s_drift_max_pa_s: float = 0.1e5
    ripple_amplitude_pa: float = 0.3e5
    ripple_frequency_hz: float = 225.0
    p_r_nominal_pa: float = 0.5e5
    p_r_window_spread_pa: float = 0.2e5


@dataclass(frozen=True)
class ControllerParams:
    """Digital PI position controller on the measured cylinder position X, output x_ref.

    x_ref[k] = sat( w_ff x_ff(v_ref[k]) + K_p e[k] + I[k] ),  e = X_ref - X,  sat to +-x_lim;
    I[k+1] = I[k] + (K_p T_0 / T_i) e[k] + (T_0 / T_t) (x_ref[k] - unsat[k])  (back-calculation
    anti-windup); x_ref is held (zero-order hold) until the next sample.

    Gains, justified on the linearised plant of Table 1 (valve, cylinder and chambers
    linearised about steady motion with :func:`model.standstill.steady_state`, loop
    L = C(s) G(s) e^{-s T_0/2}): the velocity gain K_v = dv_X/dx is about 90-100 1/s when
    extending and 40-60 1/s when retracting; the hydraulic mode has omega_h = 100-135 rad/s
    over the stroke (sqrt(beta (A1^2/V1 + A2^2/V2) / m)) with zeta_h ~ 0.06 from d_v alone and
    0.07-0.19 with the valve's flow-pressure coefficient. An integrator plus such a mode only
    tolerates a crossover K_p K_v below ~ 2 zeta_h omega_h. K_p = 0.07 m/m puts the crossover
    at 6.5-7.3 rad/s extending and 3.4-3.8 rad/s retracting; worst gain margin 2.4 (7.6 dB,
    slow extension at mid-stroke, where zeta_h is lowest), phase margin >= 58 deg everywhere.
    T_i = 0.5 s puts the PI zero at 2 rad/s, below every crossover, so the integral removes
    load offsets and the feed-forward mismatch of a worn or faulty valve within about a
    second at < 15 deg phase cost. Tracking on the standard trajectories: healthy valve
    |X - X_ref| < ~1 mm, the paper's broken edge 1r < ~6 mm.

    Attributes
    ----------
    sample_time_s : float
        Controller sample time T_0. [s] (1 ms, the acquisition rate; must equal 1/f_s)
    kp_m_per_m : float
        Proportional gain K_p, spool metres per metre of position error. [m/m] (0.07)
    ti_s : float
        Integral time T_i. [s] (0.5)
    tt_s : float
        Anti-windup tracking time T_t of the back-calculation. [s] (0.1: a fifth of T_i, so
        the integrator unwinds within ~0.1 s after saturation)
    x_limit_m : float | None
        Output saturation. [m] None = +-x_max of the valve geometry.
    feedforward : float
        Weight w_ff of the velocity feed-forward x_ff(v_ref) (0 = off, 1 = full). [-] The
        feed-forward is the steady-state spool position of the *nominal* valve for the reference
        velocity (a commissioning table, :func:`model.controller.feedforward_table`), so a worn
        or faulty valve needs a different spool position for the same motion and the PI makes up
        the difference, as in the paper's Fig. 7. Default 1.
    """

    sample_time_s: float = 1.0e-3
    kp_m_per_m: float = 0.07
    ti_s: float = 0.5
    tt_s: float = 0.1
    x_limit_m: float | None = None
    feedforward: float = 1.0


@dataclass(frozen=True)
class SensorChannel:
    """One measured signal: additive white Gaussian noise, then uniform quantisation and
    clipping to the sensor range.

    Attributes
    ----------
    noise_std : float
        Standard deviation of the additive noise, in the signal's SI unit.
    step : float
        Quantisation step (range / 2**bits for an ADC), in the signal's SI unit; 0 = none.
    lo, hi : float
        Sensor range; readings are clipped to it.
    """

    noise_std: float
    step: float
    lo: float
    hi: float


def _adc(lo: float, hi: float, bits: int = 16) -> float:
    return (hi - lo) / 2**bits


@dataclass(frozen=True)
class SensorParams:
    """What the plant's acquisition records (1 kHz, as usual in rolling mills).

    Pressure transmitters: 0-250 bar (ps, p1, p2) and 0-25 bar (pr), 16-bit acquisition
    (3.8 mbar resp. 0.38 mbar steps), noise 0.05 bar std (0.02 % of span: industrial
    transmitters plus EMI in a mill). Spool position: the valve's built-in LVDT, +-4 mm over
    16 bit (0.12 um steps), noise 1 um std (0.03 % of x_max). Cylinder position: magnetostrictive
    transducer with SSI output, 1 um resolution, noise 1 um std. x_ref: the controller's own
    digital output, 16 bit over +-4 mm, no noise.
    """

    sample_rate_hz: float = 1000.0
    ps: SensorChannel = SensorChannel(0.05e5, _adc(0.0, 250e5), 0.0, 250e5)
    pr: SensorChannel = SensorChannel(0.05e5, _adc(0.0, 25e5), 0.0, 25e5)
    p1: SensorChannel = SensorChannel(0.05e5, _adc(0.0, 250e5), 0.0, 250e5)
    p2: SensorChannel = SensorChannel(0.05e5, _adc(0.0, 250e5), 0.0, 250e5)
    x_spool: SensorChannel = SensorChannel(1.0e-6, _adc(-4e-3, 4e-3), -4e-3, 4e-3)
    x_cyl: SensorChannel = SensorChannel(1.0e-6, 1.0e-6, -0.005, 0.615)
    x_ref: SensorChannel = SensorChannel(0.0, _adc(-4e-3, 4e-3), -4e-3, 4e-3)


@dataclass(frozen=True)
class TrajectoryParams:
    """Reference moves of the cylinder within a window (see :mod:`model.trajectory`).

    A window is a sequence of dwells and smooth moves (cruise between raised-cosine velocity
    ramps, or minimum-jerk) alternating in direction between random targets in
    [X_low, X_high]. Peak speeds and ramp times are drawn per move; extension (load goes
    down) is faster than retraction (load is lifted) because the valve is matched so. With
    the nominal valve of :data:`TABLE1`, |x| > 1 mm needs |v_X| > ~0.10 m/s extending and
    > ~0.05 m/s retracting; the peak speeds below keep the steady spool stroke below ~2.9 mm
    (83 % of x_max; extension at 0.24 m/s needs 2.5 mm, retraction at 0.13 m/s 2.9 mm). Measured
    on 64 healthy 10 s windows: |x| > 1 mm for 57-80 % of a window (median 68 %), x > +1 mm for
    9-40 % (median 21 %), x < -1 mm for 26-63 % (median 45 %).

    Attributes
    ----------
    X_low_m, X_high_m : float
        Range of targets, margins of 40 mm to the end stops. [m]
    min_travel_m : float
        Smallest move length. [m]
    v_extend_m_s : tuple(float, float)
        Range of the peak speed of extending moves. [m/s]
    v_retract_m_s : tuple(float, float)
        Range of the peak speed of retracting moves. [m/s]
    dwell_s : tuple(float, float)
        Range of dwell durations between moves. [s]
    first_dwell_s : tuple(float, float)
        Range of the dwell that opens every window (the window starts at rest). [s]
    ramp_s : tuple(float, float)
        Range of the raised-cosine ramp time T_a of a move. [s] (0.3-0.6 s: peak acceleration
        pi v / (2 T_a) <= 1.3 m/s^2, i.e. at most ~8 kN of inertial force on 6000 kg)
    profile : str
        ``"cosine"`` (default) or ``"minimum_jerk"``.
    """

    X_low_m: float = 0.04
    X_high_m: float = 0.57
    min_travel_m: float = 0.15
    v_extend_m_s: tuple[float, float] = (0.14, 0.24)
    v_retract_m_s: tuple[float, float] = (0.07, 0.13)
    dwell_s: tuple[float, float] = (0.2, 0.8)
    first_dwell_s: tuple[float, float] = (0.2, 0.5)
    ramp_s: tuple[float, float] = (0.3, 0.6)
    profile: str = "cosine"


@dataclass(frozen=True)
class LoadParams:
    """Unknown external load F_l: piecewise constant (see :mod:`model.trajectory`).

    Load changes arrive as a Poisson process; each new level is 0 with probability
    ``p_zero`` and otherwise uniform in +-level_max. Steps are what makes the pressure peaks
    that step 3 of the method discards.

    Attributes
    ----------
    rate_per_s : float
        Mean number of load changes per second. [1/s] (0.2: about two per 10 s window)
    level_max_n : float
        Largest |F_l|. [N] 15 kN, a quarter of m g: process forces comparable to the
        friction and well inside what the supply can hold (A1 p_s ~ 300 kN).
    p_zero : float
        Probability that a new level is exactly 0. [-] (0.5)
    """

    rate_per_s: float = 0.2
    level_max_n: float = 15.0e3
    p_zero: float = 0.5


@dataclass(frozen=True)
class PlantParams:
    """Everything the closed-loop simulator needs except the (per-window) valve condition.

    ``nominal_condition`` is the as-designed valve: the controller's feed-forward table and
    the default condition of scenarios are built from it.
    """

    geometry: ValveGeometry = field(default_factory=ValveGeometry)
    nominal_condition: ValveCondition = field(default_factory=ValveCondition)
    spool: SpoolParams = field(default_factory=SpoolParams)
    cylinder: CylinderParams = field(default_factory=CylinderParams)
    fluid: FluidParams = field(default_factory=FluidParams)
    supply: SupplyParams = field(default_factory=SupplyParams)
    controller: ControllerParams = field(default_factory=ControllerParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    trajectory: TrajectoryParams = field(default_factory=TrajectoryParams)
    load: LoadParams = field(default_factory=LoadParams)

    @property
    def x_limit_m(self) -> float:
        """Controller output saturation. [m]"""
        c = self.controller.x_limit_m
        return self.geometry.x_max_m if c is None else min(c, self.geometry.x_max_m)


#: Paper Table 1 plus the documented choices above. Nominal underlap 0.04 mm on every edge
#: (the plant configuration's example; model.md: "a few hundredths of a millimetre up to
#: about 0.1 mm is typical"), alpha = 0.675, x_l = -x_u + delta/2, beta = 1.5 GPa,
#: p_s = 200 bar, d_s = 6 kN, v_max = 0.3 m/s, V_01 = 3.0 L, V_02 = 7.1 L.
TABLE1: PlantParams = PlantParams()

#: Named valve-family presets on Table 1's geometry (issue 16; ``model.area``): ``eq3`` the
#: paper's valve, ``sharp`` sharp edges without closed-edge leakage or clearance intercept,
#: ``worn3`` / ``worn4`` Eq. 3 with worn lands leaking up to 3× / 4× Eq. 3's, ``linear`` the
#: linear-gradient, hard-corner edge (area gradient sin φ·π·d per port, d the spool diameter; no
#: clearance, no leakage: a third-party simulator's servo valve).
GEOMETRY_FAMILIES: dict[str, ValveGeometry] = {
    "eq3": TABLE1.geometry,
    "sharp": replace(TABLE1.geometry, area_law="sharp"),
    "worn3": replace(TABLE1.geometry, leakage_factor=3.0),
    "worn4": replace(TABLE1.geometry, leakage_factor=4.0),
    "linear": replace(TABLE1.geometry, area_law="linear"),
}

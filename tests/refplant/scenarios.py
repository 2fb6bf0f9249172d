"""What the reference plant is run with: the reference trajectory, the load, and the effects
hidden in the data.

* :class:`Trajectory`: minimum-jerk moves of the cylinder, X(t) and v(t) continuous in time.
* :class:`Load`: a continuous piecewise-linear force F_l(t) [N] (> 0 opposes extension); the
  default steps to a new level every 1-4 s and ramps there as a rolling force does.
* :class:`Effects`: the discrepancy workflow's library of effects, written here in this
  package's own way, each switchable with a magnitude, and two effects outside that library
  (pressure-dependent seal friction, an extra lag on one pressure transmitter) for tests in
  which no library effect can explain the data. :func:`effect` builds one from its name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from .params import Operation

#: Typical magnitudes: library names as the workflow reports them, and the two outside it.
TYPICAL: dict[str, float] = {
    "internal_leakage": 2.0e-12,        # K_i [m^3/(s Pa)]: 0.3 L/min at 100 bar across the piston
    "external_leakage": 2.0e-12,        # K_e [m^3/(s Pa)]: rod seal
    "entrained_air": 5.0e-3,            # air volume fraction at 1 atm [-]
    "spool_sensor_offset": 10.0e-6,     # [m]
    "pressure_sensor_offset": 2.0e5,    # [Pa]
    "pressure_sensor_gain": 1.03,       # [-]
    "supply_line_resistance": 1.0e11,   # [Pa s^2/m^6]: ~3.5 bar at 350 L/min
    "friction_change": 2.0e4,           # change of d_v [N s/m]
    "load_mass_change": 600.0,          # [kg]
    "pressure_dependent_friction": 1.0e-4,  # seal friction per Pa of p1 + p2 [m^2]: ~1.8 kN at 180 bar
    "transmitter_lag": 2.0e-3,          # extra first-order lag on one pressure transmitter [s]
}

#: Names of the effects in the discrepancy workflow's library.
LIBRARY = ("internal_leakage", "external_leakage", "entrained_air", "spool_sensor_offset",
           "pressure_sensor_offset", "pressure_sensor_gain", "supply_line_resistance",
           "friction_change", "load_mass_change")
#: Effects outside the library ("unexplained" tests).
OUTSIDE = ("pressure_dependent_friction", "transmitter_lag")


@dataclass(frozen=True)
class Effects:
    """Hidden effects; the defaults (all off) are the clean plant.

    Attributes
    ----------
    internal_leakage_m3_s_pa : q_i = K_i (p1 - p2) across the piston, chamber 1 to 2. [m^3/(s Pa)]
    external_leakage_m3_s_pa : q_e = K_e (p2 - p_atm,gauge = 0) out of chamber 2. [m^3/(s Pa)]
    air_fraction : undissolved air, volume fraction at atmospheric pressure; the chamber's
        compliance V/beta grows by eps V (p_atm / (p + p_atm))^(1/n) / (n (p + p_atm)), n = 1.4. [-]
    spool_sensor_offset_m : the spool transducer reads x + delta; the valve's inner loop holds
        the reading at x_ref, so the spool sits delta below its command. [m]
    p1_offset_pa, p2_offset_pa, p1_gain, p2_gain : the transmitter reads gain p + offset. [Pa], [-]
    supply_resistance_pa_s2_m6 : a supply line between the supply transmitter and the valve,
        p_valve = p_s - R q_s |q_s| with q_s the flow through s1 and s2. [Pa s^2/m^6]
    delta_viscous_n_s_m : d_v -> d_v + delta. [N s/m]
    delta_mass_kg : m -> m + delta (inertia and weight). [kg]
    seal_friction_m2 : outside the library: the Coulomb and static friction grow by
        k (p1 + p2) (seals pressed harder at higher pressure). [m^2]
    extra_lag_s, extra_lag_channel : outside the library: one pressure transmitter
        (``"ps"``, ``"pr"``, ``"p1"``, ``"p2"``) lags this much more. [s]
    """

    internal_leakage_m3_s_pa: float = 0.0
    external_leakage_m3_s_pa: float = 0.0
    air_fraction: float = 0.0
    spool_sensor_offset_m: float = 0.0
    p1_offset_pa: float = 0.0
    p2_offset_pa: float = 0.0
    p1_gain: float = 1.0
    p2_gain: float = 1.0
    supply_resistance_pa_s2_m6: float = 0.0
    delta_viscous_n_s_m: float = 0.0
    delta_mass_kg: float = 0.0
    seal_friction_m2: float = 0.0
    extra_lag_s: float = 0.0
    extra_lag_channel: str = "p1"

    def __post_init__(self):
        for f in fields(self):
            if f.name != "extra_lag_channel" and not math.isfinite(getattr(self, f.name)):
                raise ValueError(f"{f.name} must be finite")
        if self.extra_lag_channel not in ("ps", "pr", "p1", "p2"):
            raise ValueError("extra_lag_channel must be one of ps, pr, p1, p2")
        if not 0.0 <= self.air_fraction < 0.5 or self.p1_gain <= 0 or self.p2_gain <= 0:
            raise ValueError("need 0 <= air_fraction < 0.5 and positive transmitter gains")
        if min(self.internal_leakage_m3_s_pa, self.external_leakage_m3_s_pa,
               self.supply_resistance_pa_s2_m6, self.extra_lag_s) < 0:
            raise ValueError("leakages, line resistance and lag cannot be negative")

    @property
    def active(self) -> list[str]:
        """Names of the effects switched on (library names, then the outside ones)."""
        on = []
        checks = [("internal_leakage", self.internal_leakage_m3_s_pa != 0),
                  ("external_leakage", self.external_leakage_m3_s_pa != 0),
                  ("entrained_air", self.air_fraction != 0),
                  ("spool_sensor_offset", self.spool_sensor_offset_m != 0),
                  ("pressure_sensor_offset", self.p1_offset_pa != 0 or self.p2_offset_pa != 0),
                  ("pressure_sensor_gain", self.p1_gain != 1 or self.p2_gain != 1),
                  ("supply_line_resistance", self.supply_resistance_pa_s2_m6 != 0),
                  ("friction_change", self.delta_viscous_n_s_m != 0),
                  ("load_mass_change", self.delta_mass_kg != 0),
                  ("pressure_dependent_friction", self.seal_friction_m2 != 0),
                  ("transmitter_lag", self.extra_lag_s != 0)]
        return [n for n, c in checks if c]


def effect(name: str, magnitude: float | None = None, *, channel: str = "p1") -> Effects:
    """One effect switched on: ``name`` of :data:`LIBRARY` or :data:`OUTSIDE`, ``magnitude`` in
    its unit (default :data:`TYPICAL`; a gain is the factor, e.g. 1.05); ``channel`` for the
    pressure transmitter effects (``"p1"`` or ``"p2"``; ``transmitter_lag`` also ps, pr)."""
    if name not in TYPICAL:
        raise ValueError(f"unknown effect {name!r}; known: {LIBRARY + OUTSIDE}")
    m = TYPICAL[name] if magnitude is None else float(magnitude)
    if name in ("pressure_sensor_offset", "pressure_sensor_gain") and channel not in ("p1", "p2"):
        raise ValueError(f"{name}: channel must be p1 or p2")
    attr = {
        "internal_leakage": "internal_leakage_m3_s_pa", "external_leakage": "external_leakage_m3_s_pa",
        "entrained_air": "air_fraction", "spool_sensor_offset": "spool_sensor_offset_m",
        "pressure_sensor_offset": f"{channel}_offset_pa", "pressure_sensor_gain": f"{channel}_gain",
        "supply_line_resistance": "supply_resistance_pa_s2_m6", "friction_change": "delta_viscous_n_s_m",
        "load_mass_change": "delta_mass_kg", "pressure_dependent_friction": "seal_friction_m2",
        "transmitter_lag": "extra_lag_s",
    }[name]
    if name == "transmitter_lag":
        return Effects(extra_lag_s=m, extra_lag_channel=channel)
    return replace(Effects(), **{attr: m})


@dataclass(frozen=True)
class Trajectory:
    """Reference of the cylinder: from ``X0_m`` [m], minimum-jerk moves i from ``x_a[i]`` to
    ``x_b[i]`` over [``t_start[i]``, ``t_start[i] + duration[i]``] [s], holding between them."""

    X0_m: float
    t_start: np.ndarray
    duration: np.ndarray
    x_a: np.ndarray
    x_b: np.ndarray

    @classmethod
    def hold(cls, X_m: float) -> "Trajectory":
        """Stand still at ``X_m``. [m]"""
        e = np.empty(0)
        return cls(float(X_m), e, e, e, e)

    @classmethod
    def moves(cls, X0_m: float, moves: list[tuple[float, float, float]]) -> "Trajectory":
        """Explicit moves (start [s], duration [s], target [m]) from ``X0_m``."""
        xa, x = [], float(X0_m)
        for _, _, target in moves:
            xa.append(x)
            x = float(target)
        a = np.array(moves, float).reshape(-1, 3)
        return cls(float(X0_m), a[:, 0].copy(), a[:, 1].copy(), np.array(xa), a[:, 2].copy())

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (np.ascontiguousarray(self.t_start, float), np.ascontiguousarray(self.duration, float),
                np.ascontiguousarray(self.x_a, float), np.ascontiguousarray(self.x_b, float))

    def at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """(X_ref [m], v_ref [m/s]) at times ``t_s`` [s]."""
        t = np.atleast_1d(np.asarray(t_s, float))
        X = np.full(t.shape, self.X0_m)
        v = np.zeros(t.shape)
        for t0, T, a, b in zip(*self.arrays()):
            s = np.clip((t - t0) / T, 0.0, 1.0)
            after = t >= t0
            X = np.where(after, a + (b - a) * (10 * s**3 - 15 * s**4 + 6 * s**5), X)
            v = np.where(after, (b - a) / T * (30 * s**2 - 60 * s**3 + 30 * s**4), v)
        return X, v


def draw_trajectory(op: Operation, duration_s: float, rng: np.random.Generator) -> Trajectory:
    """Moves over the stroke for ``duration_s``: a first dwell, then moves alternating in direction
    to random targets (at least ``min_travel`` long where there is room), dwells between."""
    X = float(rng.uniform(op.X_low_m, op.X_high_m))
    X0, t = X, float(rng.uniform(*op.first_dwell_s))
    up = rng.uniform() < 0.5
    moves = []
    while t < duration_s:
        room_up, room_down = op.X_high_m - X, X - op.X_low_m
        if up and room_up < op.min_travel_m:
            up = False
        elif not up and room_down < op.min_travel_m:
            up = True
        room = room_up if up else room_down
        d = float(rng.uniform(min(op.min_travel_m, room), room))
        v = float(rng.uniform(*(op.v_extend_m_s if up else op.v_retract_m_s)))
        T = 1.875 * d / v
        target = X + d if up else X - d
        moves.append((t, T, target))
        X = target
        t += T + float(rng.uniform(*op.dwell_s))
        up = not up
    return Trajectory.moves(X0, moves)


@dataclass(frozen=True)
class Load:
    """F_l(t) [N], linear between knots (``t_s`` [s], ``force_n`` [N]), constant outside."""

    t_s: np.ndarray
    force_n: np.ndarray

    @classmethod
    def constant(cls, force_n: float = 0.0) -> "Load":
        return cls(np.array([0.0]), np.array([float(force_n)]))

    def at(self, t_s) -> np.ndarray:
        return np.interp(np.asarray(t_s, float), self.t_s, self.force_n)


def draw_load(op: Operation, duration_s: float, rng: np.random.Generator) -> Load:
    """A new level every ``load_interval_s`` (uniform), 0 with probability ``load_p_zero``, else
    uniform in +-``load_max_n``, each reached by a linear ramp of ``load_ramp_s`` (uniform)."""

    def level():
        return 0.0 if rng.uniform() < op.load_p_zero else float(rng.uniform(-1, 1) * op.load_max_n)

    t, f = [0.0], [level()]
    tc = float(rng.uniform(*op.load_interval_s))
    while tc < duration_s:
        ramp = float(rng.uniform(*op.load_ramp_s))
        t += [tc, tc + ramp]
        f += [f[-1], level()]
        tc += ramp + float(rng.uniform(*op.load_interval_s))
    return Load(np.array(t), np.array(f))

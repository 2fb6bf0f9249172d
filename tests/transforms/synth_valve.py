"""Synthetic but physically consistent valve data for the transforms tests (no model/ needed).

* :func:`eq3_area` — the opening area of one edge by model.md's Eq. 3 (for nominal curves).
* :func:`chamber_data` — cylinder motion X(t) and spool x(t) prescribed (any X(t) is reachable
  with some unknown load F_l), chamber pressures integrated from Eq. 6 with the orifice flows of
  Eq. 4 through the *open* edges only (zero-lapped edges without leakage, so Eq. 7's assumption
  holds exactly). The Eq. 7 points must then reproduce α_e A_e(u) up to the Savitzky–Golay error.
* :func:`lake_frame` — the canonical lake columns from arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np
import polars as pl
from scipy.integrate import solve_ivp

from transforms.params import MonitorParams

D_PISTON, D_ROD = 0.140, 0.100
A1 = np.pi * D_PISTON**2 / 4
A2 = A1 - np.pi * D_ROD**2 / 4
BETA, RHO = 1.5e9, 870.0
V01, V02 = 3.0e-3, 7.1e-3
X_MAX = 3.5e-3
R_BORE, R_SPOOL = 10.00e-3, 9.99e-3
PHI1, PHI2 = np.deg2rad(10.48), np.deg2rad(5.24)
PS, PR = 200e5, 1e5
T0 = datetime(2025, 3, 1, 12, 0, tzinfo=timezone.utc)


def params(**settings) -> MonitorParams:
    base = dict(
        piston_area_m2=A1,
        annulus_area_m2=A2,
        v01_m3=V01,
        v02_m3=V02,
        bulk_modulus_pa=BETA,
        density_kg_m3=RHO,
        underlap_m={"s1": 4e-5, "1r": 4e-5, "s2": 4e-5, "2r": 4e-5},
        x_max_m=X_MAX,
        sample_period_s=1e-3,
    )
    base.update(settings)
    return MonitorParams(**base)


def eq3_area(u, underlap: float, phi: float, big_r: float = R_BORE, r: float = R_SPOOL) -> np.ndarray:
    """Eq. 3 of model.md (open, transition and leakage branches), x_l = −x_u + δ/2."""
    u = np.asarray(u, dtype=float)
    delta = (big_r - r) * np.tan(phi)
    x_l = -underlap + delta / 2
    s = u + underlap
    h = (big_r - r) * np.cos(phi) + s * np.sin(phi)
    a_o = np.pi * h * (2 * big_r - h * np.cos(phi))
    a_t = np.pi * (big_r + r) * np.sqrt((big_r - r) ** 2 + s**2)
    c = (big_r - r) ** 2 + (x_l + underlap) ** 2
    a_l = np.pi * (big_r + r) * c**1.5 / (c + (x_l - u) * (x_l + underlap))
    return np.where(u >= -underlap + delta, a_o, np.where(u >= x_l, a_t, a_l))


def lake_frame(t_s, ps, pr, p1, p2, x, xc, *, valve_id: str = "V1", start: datetime = T0) -> pl.DataFrame:
    t_us = np.round(np.asarray(t_s) * 1e6).astype(np.int64)
    n = t_us.shape[0]
    offset_us = int((start - datetime(1970, 1, 1, tzinfo=timezone.utc)).total_seconds() * 1e6)
    ts = pl.Series("timestamp_utc", t_us + offset_us).cast(pl.Datetime("us", "UTC"))

    def col(v):
        return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

    return pl.DataFrame(
        {
            "valve_id": [valve_id] * n,
            "timestamp_utc": ts,
            "ps_pa": col(ps),
            "pr_pa": col(pr),
            "p1_pa": col(p1),
            "p2_pa": col(p2),
            "x_spool_m": col(x),
            "x_cyl_m": col(xc),
        }
    ).with_columns(pl.col("timestamp_utc").dt.date().alias("date"))


@dataclass(frozen=True)
class EdgeTruth:
    """α_e A_e(u) = alpha_e · slope_e · max(u + shift_e, 0): sharp, leak-free edges."""

    alpha: dict
    slope: dict
    shift: dict | None = None

    def area(self, edge: str, u) -> np.ndarray:
        d = 0.0 if self.shift is None else self.shift[edge]
        return self.alpha[edge] * self.slope[edge] * np.maximum(np.asarray(u) + d, 0.0)

    def changed(self, alpha_factor: float, shift_m: float) -> EdgeTruth:
        return EdgeTruth(
            alpha={e: a * alpha_factor for e, a in self.alpha.items()},
            slope=self.slope,
            shift={e: shift_m for e in self.alpha},
        )


TRUTH = EdgeTruth(
    alpha={"s1": 0.62, "1r": 0.71, "s2": 0.66, "2r": 0.74},
    # port 1 opens at 2πR sin φ1 per metre, port 2 at 2πR sin φ2 (the open branch of Eq. 3)
    slope={
        "s1": 2 * np.pi * R_BORE * np.sin(PHI1),
        "1r": 2 * np.pi * R_BORE * np.sin(PHI1),
        "s2": 2 * np.pi * R_BORE * np.sin(PHI2),
        "2r": 2 * np.pi * R_BORE * np.sin(PHI2),
    },
)


_CACHE: dict = {}


def chamber_data(duration_s: float = 6.0, dt: float = 1e-3, truth: EdgeTruth = TRUTH):
    """Cached :func:`_chamber_data` (the stiff integration takes about a second); read-only arrays."""
    key = (duration_s, dt, repr(truth))
    if key not in _CACHE:
        out = _chamber_data(duration_s, dt, truth)
        for arr in out:
            arr.setflags(write=False)
        _CACHE[key] = out
    return _CACHE[key]


def _chamber_data(duration_s: float, dt: float, truth: EdgeTruth):
    """X(t), x(t) prescribed; p1, p2 integrated from Eq. 6 with Eq. 4 flows of the open edges.

    X moves sinusoidally (period 3 s, amplitude 80 mm, up to 0.17 m/s); the spool follows
    x = K(t)·v_X with a slowly varying gain K ∈ [11, 19] ms, so that all edges close together
    with the flow and the quasi-steady pressure drops stay between about 30 and 150 bar (they do
    not depend on |v_X|, only on K), while |x| sweeps 0 … 3.2 mm. Starts at the quasi-steady
    pressures. Returns (t, X, x, p1, p2, dp1_dt, dp2_dt, v_X) sampled every dt.
    """
    om = 2 * np.pi / 3.0
    amp = 0.08

    def xc(t):
        return 0.3 + amp * np.sin(om * t)

    def vx(t):
        return amp * om * np.cos(om * t)

    def gain(t):
        return 0.015 + 0.004 * np.sin(0.41 * om * t)

    def spool(t):
        return gain(t) * vx(t)

    def q_in_1(x, p1):
        qs = truth.area("s1", x) * np.sqrt(2 * np.abs(PS - p1) / RHO) * np.sign(PS - p1)
        qr = truth.area("1r", -x) * np.sqrt(2 * np.abs(PR - p1) / RHO) * np.sign(PR - p1)
        return qs + qr

    def q_out_2(x, p2):
        qs = truth.area("s2", -x) * np.sqrt(2 * np.abs(p2 - PS) / RHO) * np.sign(p2 - PS)
        qr = truth.area("2r", x) * np.sqrt(2 * np.abs(p2 - PR) / RHO) * np.sign(p2 - PR)
        return qs + qr

    def rhs(t, y):
        p1, p2 = y
        x = spool(t)
        v = vx(t)
        xcyl = xc(t)
        dp1 = BETA / (V01 + A1 * xcyl) * (q_in_1(x, p1) - A1 * v)
        dp2 = BETA / (V02 - A2 * xcyl) * (A2 * v - q_out_2(x, p2))
        return [dp1, dp2]

    k0 = gain(0.0)
    p1_0 = PS - RHO / 2 * (A1 / (truth.alpha["s1"] * truth.slope["s1"] * k0)) ** 2
    p2_0 = PR + RHO / 2 * (A2 / (truth.alpha["2r"] * truth.slope["2r"] * k0)) ** 2
    t = np.arange(0.0, duration_s, dt)
    sol = solve_ivp(rhs, (0.0, t[-1]), [p1_0, p2_0], t_eval=t, method="Radau", rtol=1e-11, atol=1e-3)
    assert sol.success, sol.message
    p1, p2 = sol.y
    x = spool(t)
    dpdt = np.array([rhs(ti, yi) for ti, yi in zip(t, sol.y.T, strict=True)]).T
    return t, xc(t), x, p1, p2, dpdt[0], dpdt[1], vx(t)

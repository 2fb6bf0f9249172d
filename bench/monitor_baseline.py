"""The monitoring's steps 2–4b written the straightforward way, with pandas and scipy: the
baseline that ``bench/monitor_pipeline.py`` measures :mod:`transforms.monitor` against.

Same steps and settings as the production path (``flows/monitor/flow.py`` → ``transforms.monitor``):

1. windows: a time step longer than ``gap_limit_periods`` sample periods starts a new window
   (pandas ``diff``/``cumsum``), then a ``groupby`` over the windows;
2. per window, ``scipy.signal.savgol_filter`` (21 samples, order 3) for the smoothed chamber
   pressures and the derivatives of p1, p2 and X; the first and last h samples of a window get
   no derivative (as the compiled path, which never lays the stencil across a window edge);
3. the step-3 rules (standstill, pressure peaks and the compressibility ratio, spool range,
   minimum |Δp|) as boolean masks;
4. Eq. 7 and its siblings with the closed edge's flow subtracted (baseline-state leakage);
5. Eq. 8 per window and edge with ``scipy.optimize.least_squares`` from (α, x) = (1, 0), no
   analytic Jacobian (2-point finite differences), x̂ bounded to ±1.5 mm; statuses
   ``too_few_points`` / ``too_little_coverage`` as in :mod:`transforms.fit`;
6. the leakage refinement: each window's closed-edge leakage rebuilt from that edge's own
   estimate (scale-only where the fit has no estimate), then a second ``least_squares`` from
   the first estimate.

What it leaves out: the confidence intervals, the per-rule selection counts and irregular
steps inside a window (the benchmark archive has none). It returns one row per window and edge
(``window_start, edge, status, n_points, alpha_hat, x_hat_m, e_m2``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

EDGES = ("s1", "1r", "s2", "2r")
OPPOSITE = {"s1": "1r", "1r": "s1", "s2": "2r", "2r": "s2"}
SIGN = {"s1": 1.0, "1r": -1.0, "s2": -1.0, "2r": 1.0}


def _interp(knots: np.ndarray, values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Piecewise linear, linear beyond the end knots (as transforms.characteristic)."""
    y = np.interp(u, knots, values)
    lo = u < knots[0]
    hi = u > knots[-1]
    if lo.any():
        y[lo] = values[0] + (values[1] - values[0]) / (knots[1] - knots[0]) * (u[lo] - knots[0])
    if hi.any():
        y[hi] = values[-1] + (values[-1] - values[-2]) / (knots[-1] - knots[-2]) * (u[hi] - knots[-1])
    return y


def window_points(w: pd.DataFrame, p, dt: float) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Steps 2–3 and Eq. 7 of one window: per edge (u, area without the closed edge's flow,
    ratio of the closed edge's sqrt-pressure term to the open edge's)."""
    n = len(w)
    h = p.savgol_window // 2
    if n < p.savgol_window:
        return {e: (np.empty(0), np.empty(0), np.empty(0)) for e in EDGES}
    kw = dict(window_length=p.savgol_window, polyorder=p.savgol_order)
    p1 = w["p1_pa"].to_numpy(np.float64)
    p2 = w["p2_pa"].to_numpy(np.float64)
    xc = w["x_cyl_m"].to_numpy(np.float64)
    p1s = savgol_filter(p1, **kw)
    p2s = savgol_filter(p2, **kw)
    dp1 = savgol_filter(p1, deriv=1, delta=dt, **kw)
    dp2 = savgol_filter(p2, deriv=1, delta=dt, **kw)
    v = savgol_filter(xc, deriv=1, delta=dt, **kw)
    ok = np.ones(n, dtype=bool)
    ok[:h] = False
    ok[n - h :] = False
    ps = w["ps_pa"].to_numpy(np.float64)
    pr = w["pr_pa"].to_numpy(np.float64)
    x = w["x_spool_m"].to_numpy(np.float64)
    beta, a1, a2 = p.bulk_modulus_pa, p.piston_area_m2, p.annulus_area_m2
    v1 = p.v01_m3 + a1 * xc
    v2 = p.v02_m3 - a2 * xc
    q1 = dp1 * v1 / beta + a1 * v  # flow into chamber 1
    q2 = a2 * v - dp2 * v2 / beta  # flow out of chamber 2
    moving = np.abs(v) >= p.standstill_velocity_m_s
    no_peak = (np.abs(dp1) <= p.peak_dpdt_pa_s) & (np.abs(dp2) <= p.peak_dpdt_pa_s)
    ratio1 = np.abs(v1 * dp1 / beta) <= p.compressibility_ratio_max * np.abs(a1 * v)
    ratio2 = np.abs(v2 * dp2 / beta) <= p.compressibility_ratio_max * np.abs(a2 * v)
    dps = {"s1": ps - p1s, "1r": pr - p1s, "s2": p2s - ps, "2r": p2s - pr}
    sq = np.sqrt(p.density_kg_m3 / 2.0)
    out = {}
    for e in EDGES:
        port1 = e in ("s1", "1r")
        limit = p.spool_limit_m(e)
        spool = x >= limit if SIGN[e] > 0 else x <= -limit
        dp = dps[e]
        keep = ok & moving & no_peak & (ratio1 if port1 else ratio2) & spool & (np.abs(dp) >= p.min_dp_pa)
        q = (q1 if port1 else q2)[keep]
        d = dp[keep]
        do = dps[OPPOSITE[e]][keep]
        den = np.sign(d) * np.sqrt(np.abs(d))
        out[e] = (SIGN[e] * x[keep], sq * q / den, np.sign(do) * np.sqrt(np.abs(do)) / den)
    return out


def fit_eq8(u, a, knots, values, x0=(1.0, 0.0), x_bound_m=1.5e-3):
    """Eq. 8 by scipy.optimize.least_squares, no Jacobian (2-point differences). Inside, x is in
    mm and the residuals in mm²: in SI (1e-5 m², 1e-4 m) the default tolerances stop at the
    start point."""
    a_mm2 = a * 1e6
    v_mm2 = values * 1e6

    def resid(theta):
        return a_mm2 - theta[0] * _interp(knots, v_mm2, u + theta[1] * 1e-3)

    b = x_bound_m * 1e3
    start = (x0[0], float(np.clip(x0[1] * 1e3, -b + 1e-9, b - 1e-9)))
    r = least_squares(resid, start, bounds=([0.0, -b], [np.inf, b]))
    return float(r.x[0]), float(r.x[1] * 1e-3), float(np.sqrt(np.mean(r.fun**2))) * 1e-6


def monitor_pandas(lake: pd.DataFrame, p, baseline: dict, leakage: dict, passes: int = 1) -> pd.DataFrame:
    """Steps 2–4b for one valve's rows (pandas frame) against ``baseline[edge] = (knots, values)``
    with the closed-edge leakage ``leakage[edge] = (knots, values)`` (module docstring)."""
    dt = p.sample_period_s
    lake = lake.sort_values("timestamp_utc", kind="stable")
    t = lake["timestamp_utc"]
    new = t.diff() > pd.Timedelta(seconds=p.gap_limit_periods * dt)
    lake = lake.assign(window=new.cumsum())
    rows = []
    for _, w in lake.groupby("window", sort=True):
        pts = window_points(w, p, dt)
        start = w["timestamp_utc"].iloc[0]
        # first pass: the closed edges at their baseline state
        area = {e: pts[e][1] - _interp(*leakage[OPPOSITE[e]], -pts[e][0]) * pts[e][2] for e in EDGES}
        est = {}
        for k in range(passes + 1):
            new_est = {}
            for e in EDGES:
                u, a = pts[e][0], area[e]
                n = u.shape[0]
                if n < p.min_points:
                    new_est[e] = ("too_few_points" if n else "no_points", n, np.nan, np.nan, np.nan)
                elif u.max() - u.min() < p.min_coverage_m:
                    new_est[e] = ("too_little_coverage", n, np.nan, np.nan, np.nan)
                else:
                    x0 = (est[e][2], est[e][3]) if e in est and np.isfinite(est[e][2]) else (1.0, 0.0)
                    al, xh, err = fit_eq8(u, a, *baseline[e], x0=x0, x_bound_m=p.x_hat_bound_m)
                    new_est[e] = ("ok", n, al, xh, err)
            est = new_est
            if k == passes:
                break
            # the refinement: each closed edge's leakage from its own estimate in this window
            for e in EDGES:
                o = OPPOSITE[e]
                st, n_o, al, xh, _ = est[o]
                if st == "ok":
                    sc, sh = al, xh
                elif n_o >= 50:
                    b = _interp(*baseline[o], pts[o][0])
                    sc, sh = float(area[o] @ b / (b @ b)), 0.0
                else:
                    sc, sh = 1.0, 0.0
                area[e] = pts[e][1] - sc * _interp(*leakage[o], -pts[e][0] + sh) * pts[e][2]
        for e in EDGES:
            st, n, al, xh, err = est[e]
            rows.append({"window_start": start, "edge": e, "status": st, "n_points": n, "alpha_hat": al, "x_hat_m": xh, "e_m2": err})
    return pd.DataFrame(rows)

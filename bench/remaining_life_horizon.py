"""How far a linear remaining-life forecast can be trusted: the wear study behind the forecast
horizon (docs/monitoring.md, "Remaining life: the forecast horizon").

The paper's wear scenario (Table 3, calibrated in ``model.condition.wear``: α grows by 18 % with
τ = 3000 h and flattens, the underlap grows by 7.75 nm/h) is sampled as the monitor sees it, one
window every 6 h with the window-to-window scatter of α̂ and x̂ (``--alpha-sd``, ``--x-sd``; the
defaults are the residual scatter of the demo's trends), either since commissioning
("continuous") or as the demo has it: the commissioning day and the last 60 days ("demo"). At
ages of 100 … 16,700 h, with wear bounds that the trajectory crosses at known hours, the views
of ``sql/`` themselves (``parameter_trends``) fit the trend and forecast the crossing. Every
forecast gives

    r = forecast remaining hours / observed span of the trend (the extrapolation ratio)
    q = true remaining hours / forecast remaining hours (1 = exact, > 1 = too early)

and the table lists, per bin of r, how far q strays and how often the 95 % interval holds the
true crossing. Wear bounds that the trajectory never crosses (α̂ 1.30 under Table 3's wear)
count as "never" and are listed apart.

Before that, without noise: the ratio r at which the linear α̂ trend fitted since commissioning
predicts an increment twice (1.5×, 3×) the true one (the flattening), at each age; and Table 3's
own two measurements extrapolated from the first (700 h) to the second (16,700 h).

    .venv/bin/python bench/remaining_life_horizon.py [--seeds 3]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

X_MAX_MM = 3.5
CADENCE_H = 6.0
AGES_H = (100, 250, 500, 1000, 1500, 2000, 3000, 4000, 5000, 6000, 8000, 10_000, 12_000, 14_000, 16_700)
ALPHA_BOUNDS = (1.03, 1.05, 1.08, 1.11, 1.14, 1.16, 1.30)  # 1.30: the default, never reached
X_BOUNDS_PCT = (1.0, 2.0, 3.0, 4.5, 6.0)
R_BINS = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 10.0, np.inf)


def trajectory(hours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """α̂ (relative to commissioning) and x̂ [% of x_max] of the Table 3 wear at ``hours``."""
    from model.condition import condition_arrays, wear

    xu, al = condition_arrays(wear(), np.concatenate([[0.0], hours]))
    return al[1:, 0] / al[0, 0], (xu[1:, 0] - xu[0, 0]) * 1e3 / X_MAX_MM * 100


def crossing_hour(level, bound) -> float:
    """The hour at which the noiseless trajectory first reaches ``bound`` (inf: never)."""
    h = np.arange(0.0, 200_000.0, 1.0)
    a, x = trajectory(h)
    v = a if level == "alpha_hat" else x
    hit = np.flatnonzero(v >= bound)
    return float(h[hit[0]]) if hit.size else np.inf


def window_hours(age: float, sampling: str, span_h: float) -> np.ndarray:
    every = np.arange(0.0, age + 1e-9, CADENCE_H)
    if sampling == "demo":  # the commissioning day and the last 60 days
        every = every[(every < 24.0) | (every > age - 60 * 24.0)]
    return every[every >= age - span_h]


def run(seeds: int, alpha_sd: float, x_sd: float) -> list[dict]:
    from schemas.plant_config import ConditionBounds
    from tests.report.viewdb import Warehouse

    span_h = ConditionBounds().trend_span_hours
    truth = {("alpha_hat", b): crossing_hour("alpha_hat", b) for b in ALPHA_BOUNDS}
    truth |= {("x_hat_pct", b): crossing_hour("x_hat_pct", b) for b in X_BOUNDS_PCT}
    rows = []
    for sampling in ("continuous", "demo"):
        for seed in range(seeds):
            wh = Warehouse()
            rng = np.random.default_rng(seed)
            for age in AGES_H:
                h = window_hours(age, sampling, span_h)
                a, x = trajectory(h)
                a = a + alpha_sd * rng.standard_normal(h.size)
                x = x + x_sd * rng.standard_normal(h.size)
                studied = [{"alpha_wear_high": b, "x_hat_pct_wear_high": 80.0} for b in ALPHA_BOUNDS]
                studied += [{"alpha_wear_high": 8.0, "x_hat_pct_wear_high": b} for b in X_BOUNDS_PCT]
                for k, bounds in enumerate(studied):
                    vid = f"A{age}_{k}"  # one studied bound near, the other far away; no alarms
                    wh.add_valve(vid, **bounds, alpha_fault_high=9.0, x_hat_pct_fault_high=90.0, change_z=1e6)
                    wh.add_fits(vid, "s2", h, a, x, 0.2)
            got = wh.q(
                "SELECT valve_id, parameter, bound, crossing_status, latest_hours, span_hours, "
                "remaining_hours, remaining_hours_low, remaining_hours_high FROM parameter_trends "
                "WHERE side = 'high' AND parameter IN ('alpha_hat', 'x_hat_pct')"
            )
            wh.con.close()
            for r in got.iter_rows(named=True):
                t_true = truth.get((r["parameter"], round(r["bound"], 6)))
                if t_true is None or t_true <= r["latest_hours"]:
                    continue  # a far bound, or already beyond the bound (worn)
                rows.append(r | {"sampling": sampling, "true_remaining": t_true - r["latest_hours"]})
    return rows


def summarise(rows: list[dict]) -> str:
    out = ["| sampling | parameter | r = forecast / span | forecasts | q: min | q: median | q: max | "
           "truth in 95 % interval |", "|---|---|---|---|---|---|---|---|"]
    for sampling in ("continuous", "demo"):
        for parameter in ("alpha_hat", "x_hat_pct"):
            pred = [r for r in rows if r["sampling"] == sampling and r["parameter"] == parameter
                    and r["crossing_status"] == "predicted" and r["remaining_hours"] > 0]
            for lo, hi in zip(R_BINS[:-1], R_BINS[1:]):
                sel = [r for r in pred if np.isfinite(r["true_remaining"])
                       and lo <= r["remaining_hours"] / r["span_hours"] < hi]
                if not sel:
                    continue
                q = np.array([r["true_remaining"] / r["remaining_hours"] for r in sel])
                cover = np.mean([r["remaining_hours_low"] <= r["true_remaining"] <= r["remaining_hours_high"] for r in sel])
                out.append(f"| {sampling} | {parameter} | {lo:g}–{hi:g} | {len(sel)} | {q.min():.2f} | "
                           f"{np.median(q):.2f} | {q.max():.2f} | {cover:.0%} |")
            never = [r for r in pred if not np.isfinite(r["true_remaining"])]
            if never:
                ratio = np.array([r["remaining_hours"] / r["span_hours"] for r in never])
                out.append(f"| {sampling} | {parameter} | never crosses: r = {ratio.min():.1f}–{ratio.max():.0f}, "
                           f"{(ratio <= 3).sum()} of them r ≤ 3 | {len(never)} | | | | |")
    return "\n".join(out)


def flattening() -> str:
    """Where the linear trend of the noiseless α̂ departs from the curve by a factor (module doc)."""
    out = ["| age (h) | span fitted (h) | r where the predicted α̂ increment is 1.5× / 2× / 3× the true one |",
           "|---|---|---|"]
    ahead = np.arange(1.0, 100_000.0, 1.0)
    for age in (250, 500, 700, 1000, 1500, 2000, 3000, 5000, 16_700):
        h = window_hours(age, "continuous", 5000.0)
        slope = np.polyfit(h, trajectory(h)[0], 1)[0]
        a_now, a_ahead = trajectory(np.array([float(age)]))[0][0], trajectory(age + ahead)[0]
        factor = slope * ahead / (a_ahead - a_now)
        span = h[-1] - h[0]
        cells = [f"{ahead[np.argmax(factor > q)] / span:.1f}" if (factor > q).any() else "never" for q in (1.5, 2.0, 3.0)]
        out.append(f"| {age:,} | {span:,.0f} | {' / '.join(cells)} |")
    # Table 3 (paper, edge s2): α̂ 1.04 and x̂ 0.1 % at 700 h, 1.17 and 3.7 % at 16,700 h
    r = (16_700 - 700) / 700
    a_pred, x_pred = 1.0 + 0.04 * (16_700 / 700), 0.1 * 16_700 / 700
    out.append(f"\nTable 3 extrapolated from 0–700 h to 16,700 h (r = {r:.0f}): α̂ {a_pred:.2f} predicted, 1.17 "
               f"measured (increment ×{(a_pred - 1.04) / 0.13:.1f}); x̂ {x_pred:.1f} % predicted, 3.7 % measured "
               f"(increment ×{(x_pred - 0.1) / 3.6:.2f})")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    # defaults: the median resid_sd of the demo's parameter_trends (48 edges), 2026-11-26
    ap.add_argument("--alpha-sd", type=float, default=0.0003, help="window-to-window scatter of α̂ [-]")
    ap.add_argument("--x-sd", type=float, default=0.015, help="window-to-window scatter of x̂ [%% of x_max]")
    args = ap.parse_args()
    t0 = time.perf_counter()
    print(flattening() + "\n")
    rows = run(args.seeds, args.alpha_sd, args.x_sd)
    print(summarise(rows))
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(f"\n{len(rows)} forecasts; wall {time.perf_counter() - t0:.1f} s, CPU {ru.ru_utime + ru.ru_stime:.1f} s")


if __name__ == "__main__":
    main()

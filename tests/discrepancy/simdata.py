"""Synthetic lake data with a hidden effect: simulated in-process with ``model``'s effect switched
on, recorded through the sensor models, laid out as the canonical lake frame. The workflow under
test is not told which effect (if any) is in the data."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl

from model import TABLE1, measure, simulate_windows
from model.effects import Effects
from model.params import GEOMETRY_FAMILIES, ControllerParams, LoadParams, PlantParams, TrajectoryParams
from transforms.discrepancy.nuisance import NUISANCES, SCATTER, NuisancePriors, apply_nuisances, nuisance_sigmas, nuisance_values

T0 = datetime(2025, 3, 1, 0, 0, tzinfo=timezone.utc)


def simulate_lake(effects: Effects | None, *, n_windows: int = 4, window_s: float = 10.0, seed: int = 0,
                  valve_id: str = "V1", params: PlantParams = TABLE1, start: datetime = T0) -> pl.DataFrame:
    """``n_windows`` hourly windows of one valve as lake rows (valve_id, date, timestamp_utc, ps_pa,
    pr_pa, p1_pa, p2_pa, x_spool_m, x_cyl_m, x_ref_m)."""
    res = simulate_windows(params, [params.nominal_condition] * n_windows, window_s, seed, effects=effects)
    m = measure(res, params.sensors, np.random.default_rng([seed, 99]))
    frames = []
    n = res.n_samples
    for w in range(n_windows):
        t0 = start + timedelta(hours=w)
        t_us = int((t0 - datetime(1970, 1, 1, tzinfo=timezone.utc)).total_seconds() * 1e6) + np.arange(n) * 1000
        ts = pl.Series("timestamp_utc", t_us).cast(pl.Datetime("us", "UTC"))
        frames.append(pl.DataFrame({
            "valve_id": [valve_id] * n,
            "date": ts.dt.date(),
            "timestamp_utc": ts,
            "ps_pa": m.ps[w], "pr_pa": m.pr[w], "p1_pa": m.p1[w], "p2_pa": m.p2[w],
            "x_spool_m": m.x_spool[w], "x_cyl_m": m.x_cyl[w], "x_ref_m": m.x_ref[w],
        }))
    return pl.concat(frames)


def perturbed_plant(seed: int, clip: float = 1.5, family: str = "eq3", stream: int = 4242) -> tuple[PlantParams, np.ndarray]:
    """A valve that is not its design data (Table 1): every scatter nuisance off nominal by
    z ~ N(0, 1) default prior σ, clipped at ±``clip``, drawn from (``seed``, ``stream``); the edges
    of ``family`` (:data:`model.params.GEOMETRY_FAMILIES`). Returns (plant, z over every nuisance)."""
    nom = TABLE1.nominal_condition
    rng = np.random.default_rng([seed, stream])
    z = np.zeros(len(NUISANCES))
    z[:len(SCATTER)] = np.clip(rng.normal(size=len(SCATTER)), -clip, clip)
    plant, cond = apply_nuisances(TABLE1, nom, nuisance_values(TABLE1, nom) + nuisance_sigmas(TABLE1, nom, NuisancePriors()) * z)
    return replace(plant, nominal_condition=cond, geometry=GEOMETRY_FAMILIES[family]), z


def study_conditions(plant: PlantParams) -> PlantParams:
    """``plant`` on the robustness study's operation (bench/discrepancy_robustness.py): slow
    minimum-jerk moves (0.12–0.2 / 0.06–0.11 m/s, accelerations of a few 0.1 m/s², so the inertia is
    weak in the motion equation), dwells 0.3–1 s, another controller (K_p 0.055, T_i 0.6 s) and
    0.3 load changes/s."""
    return replace(plant, trajectory=TrajectoryParams(profile="minimum_jerk", v_extend_m_s=(0.12, 0.2), v_retract_m_s=(0.06, 0.11), dwell_s=(0.3, 1.0)),
                   controller=ControllerParams(kp_m_per_m=0.055, ti_s=0.6), load=LoadParams(rate_per_s=0.3))

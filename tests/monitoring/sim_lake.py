"""Simulated lake frames: the model's closed loop through its sensors, as the lake holds them."""

import dataclasses
from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl

from model import TABLE1, ValveCondition, measure, simulate_windows
from transforms.params import MonitorParams

START = datetime(2025, 1, 1, tzinfo=timezone.utc)


def simulated_lake(
    conditions: list[ValveCondition], seed: int, valve_id: str = "V1", duration_s: float = 10.0, sensors=None, trajectory=None,
    geometry=None,
) -> pl.DataFrame:
    """One 10 s window per condition, an hour apart, with Table 1 sensors (noise, quantisation).

    ``trajectory``: a :class:`model.TrajectoryParams` instead of Table 1's default moves;
    ``geometry``: a :class:`model.ValveGeometry` instead of Table 1's (another valve family).
    Window i draws its inputs from (seed, i) alone, so two condition lists give the same
    reference trajectories, loads and supply (twins). A window longer than 10 s (a continuous
    recording) keeps Table 1's supply drift at most 10 bar over the whole window (the drift rate
    is drawn for a 10 s window; over 20 min it would reach the 250 bar sensor limit)."""
    plant = TABLE1 if trajectory is None else dataclasses.replace(TABLE1, trajectory=trajectory)
    if geometry is not None:
        plant = dataclasses.replace(plant, geometry=geometry)
    if duration_s > 10.0:
        drift = min(plant.supply.p_s_drift_max_pa_s, 10e5 / duration_s)
        plant = dataclasses.replace(plant, supply=dataclasses.replace(plant.supply, p_s_drift_max_pa_s=drift))
    res = simulate_windows(plant, conditions, duration_s, seed)
    m = measure(res, sensors or TABLE1.sensors, np.random.default_rng(seed))
    n_w, n_s = m.p1.shape
    t0 = np.array([int((START + timedelta(hours=i)).timestamp() * 1e6) for i in range(n_w)])
    t_us = (t0[:, None] + np.round(m.t_s * 1e6).astype(np.int64)).ravel()
    frame = {
        "valve_id": [valve_id] * (n_w * n_s),
        "timestamp_utc": pl.Series(t_us).cast(pl.Datetime("us", "UTC")),
        "ps_pa": m.ps.ravel(), "pr_pa": m.pr.ravel(), "p1_pa": m.p1.ravel(), "p2_pa": m.p2.ravel(),
        "x_spool_m": m.x_spool.ravel(), "x_cyl_m": m.x_cyl.ravel(),
    }  # fmt: skip
    return pl.DataFrame(frame)


def table1_params(**settings) -> MonitorParams:
    """MonitorParams of the Table 1 positioning unit with the nominal underlaps."""
    c, g = TABLE1.cylinder, TABLE1.geometry
    return MonitorParams.from_design(
        piston_diameter_m=c.piston_diameter_m, rod_diameter_m=c.rod_diameter_m, v01_m3=c.v01_m3,
        v02_m3=c.v02_m3, bulk_modulus_pa=TABLE1.fluid.bulk_modulus_pa, density_kg_m3=TABLE1.fluid.density_kg_m3,
        underlap_m=TABLE1.nominal_condition.underlap_m, x_max_m=g.x_max_m, sample_period_s=1e-3, **settings,
    )  # fmt: skip

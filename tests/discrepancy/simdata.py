"""Synthetic lake data with a hidden effect: simulated in-process with ``model``'s effect switched
on, recorded through the sensor models, laid out as the canonical lake frame. The workflow under
test is not told which effect (if any) is in the data."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl

from model import TABLE1, measure, simulate_windows
from model.effects import Effects
from model.params import PlantParams

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

"""transforms/standstill.py: Eq. 9 per window, held to the plain numpy definition sample by sample
and to an analytic case."""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np
import polars as pl
import pytest

from schemas.fields import STANDSTILL_FIELDS, polars_schema
from transforms.standstill import (
    MIN_SAMPLES,
    SETTLE_S,
    STANDSTILL_SPOOL_M,
    STANDSTILL_VELOCITY_M_S,
    VELOCITY_HALF_SPAN_S,
    standstill_rows,
)
from transforms.windows import window_starts

T0 = datetime(2025, 3, 1, tzinfo=timezone.utc)
KW = dict(max_gap_s=0.005, commissioned=datetime(2025, 1, 1, tzinfo=timezone.utc), computed_at=T0, window_s=2.0)


def numpy_rows(frame: pl.DataFrame, *, max_gap_s, commissioned, computed_at, window_s) -> pl.DataFrame:
    """The module's definition in plain numpy, window by window (the reference)."""
    t_us = frame["timestamp_utc"].dt.epoch("us").to_numpy()
    starts = np.r_[window_starts(t_us, max_gap_s * 1e6, window_s), t_us.size]
    c = {k: frame[k].to_numpy() for k in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")}
    rows = []
    for a, b in zip(starts[:-1], starts[1:]):
        if b - a < MIN_SAMPLES:
            continue
        t = t_us[a:b] * 1e-6
        dt = float(np.median(np.diff(t)))
        k = max(1, int(round(VELOCITY_HALF_SPAN_S / dt)))
        if b - a <= 2 * k:
            continue
        v = np.full(b - a, np.inf)
        v[k:-k] = (c["x_cyl_m"][a + 2 * k:b] - c["x_cyl_m"][a:b - 2 * k]) / (t[2 * k:] - t[:-2 * k])
        ps, pr, p1, p2, x = (c[n][a:b] for n in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m"))
        still = (np.abs(v) < STANDSTILL_VELOCITY_M_S) & (np.abs(x) < STANDSTILL_SPOOL_M)
        idx = np.arange(still.size)
        age = np.where(still, idx - np.maximum.accumulate(np.where(~still, idx, -1)), 0)
        use = (age * dt >= SETTLE_S) & (ps > p1) & (p2 > pr)
        if use.sum() < MIN_SAMPLES:
            continue
        r = (p1[use] - pr[use]) / (ps[use] - p1[use]) - (ps[use] - p2[use]) / (p2[use] - pr[use])
        start = frame["timestamp_utc"][int(a)]
        rows.append({
            "valve_id": frame["valve_id"][0], "window_start": start, "window_end": frame["timestamp_utc"][int(b) - 1],
            "operating_hours": (start - commissioned).total_seconds() / 3600.0, "n_samples": int(use.sum()),
            "ps_bar": float(np.median(ps[use])) / 1e5, "pr_bar": float(np.median(pr[use])) / 1e5,
            "p1_bar": float(np.median(p1[use])) / 1e5, "p2_bar": float(np.median(p2[use])) / 1e5,
            "x_spool_mm": float(np.median(x[use])) * 1e3, "eq9_residual": float(np.median(r)), "computed_at": computed_at,
        })  # fmt: skip
    return pl.DataFrame(rows, schema=polars_schema(STANDSTILL_FIELDS))


def lake_frame(seed: int) -> pl.DataFrame:
    """Six 2 s windows at 1 kHz, then a gap and a short run: the cylinder rests and moves in
    stretches, the spool wanders around its centre, the pressures are noisy and now and then
    break ps > p1 or p2 > pr; one sample is missing and one step is jittered."""
    rng = np.random.default_rng(seed)
    n = 12_000
    t_us = np.arange(n, dtype=np.int64) * 1000
    t_us = np.r_[t_us[:3000], t_us[3001:], t_us[-1] + 20_000 + np.arange(700) * 1000]
    t_us[5000] += 300
    m = t_us.size
    moving = np.repeat(rng.random(m // 400 + 1) < 0.4, 400)[:m]
    x_cyl = np.cumsum(np.where(moving, 2e-5, 0.0)) + rng.normal(0, 2e-7, m)
    x_spool = np.repeat(rng.choice([0.0, 0.2e-3], m // 500 + 1, p=[0.8, 0.2]), 500)[:m] + rng.normal(0, 0.3e-4, m)
    ps = 200e5 + rng.normal(0, 1e5, m)
    pr = rng.normal(1e5, 0.3e5, m)
    p1 = 33e5 + rng.normal(0, 2e5, m)
    p2 = 146e5 + rng.normal(0, 2e5, m)
    p1[rng.random(m) < 0.01] = 201e5  # ps > p1 broken now and then
    return pl.DataFrame({
        "valve_id": "V1", "timestamp_utc": pl.Series((T0.timestamp() * 1e6 + t_us).astype(np.int64)).cast(pl.Datetime("us", "UTC")),
        **{k: v.astype(np.float32) for k, v in {"ps_pa": ps, "pr_pa": pr, "p1_pa": p1, "p2_pa": p2, "x_spool_m": x_spool, "x_cyl_m": x_cyl}.items()},
    })  # fmt: skip


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rows_equal_the_numpy_definition(seed):
    frame = lake_frame(seed)
    got = standstill_rows(frame, **KW)
    assert got.height >= 3  # windows with rows and windows without
    assert got.equals(numpy_rows(frame, **KW))
    # a frame of two chunks (a window carried over from the previous read) gives the same rows
    two = pl.concat([frame.slice(0, 4000), frame.slice(4000)], rechunk=False)
    assert two["p1_pa"].n_chunks() == 2 and standstill_rows(two, **KW).equals(got)


def test_resting_valve_with_p1_plus_p2_equal_ps_has_residual_zero():
    m = 3000
    t = pl.Series((T0.timestamp() * 1e6 + np.arange(m) * 1000).astype(np.int64)).cast(pl.Datetime("us", "UTC"))
    p1 = np.full(m, 40e5, np.float32)
    frame = pl.DataFrame({"valve_id": "V1", "timestamp_utc": t, "ps_pa": np.full(m, 200e5, np.float32), "pr_pa": np.zeros(m, np.float32),
                          "p1_pa": p1, "p2_pa": np.float32(200e5) - p1, "x_spool_m": np.zeros(m, np.float32), "x_cyl_m": np.zeros(m, np.float32)})  # fmt: skip
    got = standstill_rows(frame, **{**KW, "window_s": None})
    assert got.height == 1
    row = got.row(0, named=True)
    assert row["eq9_residual"] == 0.0 and row["p1_bar"] == pytest.approx(40.0) and row["p2_bar"] == pytest.approx(160.0)
    # every sample counts once the velocity stencil (±10 ms) is inside it and 0.2 s have passed
    assert 2700 < row["n_samples"] < m - 200 and got.equals(numpy_rows(frame, **{**KW, "window_s": None}))

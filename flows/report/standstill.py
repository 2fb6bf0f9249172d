"""Eq. 9 at standstill, per monitoring window, from the sensor lake (table ``standstill_checks``).

Where the cylinder stands still with the spool near its centre, the paper's Eq. 9 compares
(p1 − pr)/(ps − p1) with (ps − p2)/(p2 − pr); with pr ≈ 0 this is p1 + p2 = ps. It is a quick
indicator that needs no fit: a healthy valve of Table 1 rests near a residual of −0.17 (not 0:
model.md, the radial clearance acts like unequal extra underlaps on the two ports), the paper's
broken edge 1r near −1.4. The report compares it with the value the valve's design gives at
rest (:func:`expected_residual`) against a tolerance (``bounds.eq9_tolerance``).

A sample counts as standstill when

* the cylinder velocity, a central difference of X over ±``VELOCITY_HALF_SPAN_S``, is below
  ``STANDSTILL_VELOCITY_M_S`` in magnitude,
* the spool is within ``STANDSTILL_SPOOL_M`` of centre (Eq. 9 assumes x ≈ 0: the healthy rest
  position is −0.036 mm inside the 0.04 mm underlap, the broken one +0.01 mm),
* both conditions have held for ``SETTLE_S`` already (the chamber pressures have settled), and
* ps > p1 and p2 > pr (the ratios are defined).

A window with at least ``MIN_SAMPLES`` such samples gives one row: the medians of the pressures,
of x and of the per-sample residual.
"""

from __future__ import annotations

import math
from datetime import datetime

import numpy as np
import polars as pl

from schemas.fields import STANDSTILL_FIELDS, polars_schema
from transforms.windows import window_starts

STANDSTILL_VELOCITY_M_S = 1e-3
"""|dX/dt| below this is standstill (the monitor's step-3 rule uses 5 mm/s to drop data; Eq. 9
needs the cylinder truly at rest). [m/s]"""
VELOCITY_HALF_SPAN_S = 0.01
"""Half span of the central difference for dX/dt (averages position noise over 20 ms). [s]"""
STANDSTILL_SPOOL_M = 0.1e-3
"""|x| below this is "x close to 0" (paper Sec. 5.1). [m]"""
SETTLE_S = 0.2
"""How long standstill must have lasted before samples count (pressure transients decay). [s]"""
MIN_SAMPLES = 100
"""Fewest standstill samples for a window's row."""
STANDSTILL_COLUMNS: tuple[str, ...] = ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m")
"""The lake columns Eq. 9 reads (besides ``timestamp_utc`` and ``valve_id``)."""


def _run_age(mask: np.ndarray) -> np.ndarray:
    """For each sample, how many consecutive True samples end at it (0 where False)."""
    idx = np.arange(mask.size)
    last_false = np.maximum.accumulate(np.where(~mask, idx, -1))
    return np.where(mask, idx - last_false, 0)


def standstill_rows(
    frame: pl.DataFrame, *, max_gap_s: float, commissioned: datetime, computed_at: datetime, window_s: float | None = None
) -> pl.DataFrame:
    """Eq. 9 rows (:data:`schemas.fields.STANDSTILL_FIELDS`) of one valve's lake rows.

    ``frame`` is the canonical sensor frame of one valve, sorted by time; windows are the
    monitor's: runs without a gap longer than ``max_gap_s``, cut by the clock every ``window_s``
    (:func:`transforms.windows.window_starts`; None: whole runs).
    """
    schema = polars_schema(STANDSTILL_FIELDS)
    if frame.height < 2:
        return pl.DataFrame(schema=schema)
    valve_id = frame["valve_id"][0]
    t_us = frame["timestamp_utc"].dt.epoch("us").to_numpy()
    starts = np.r_[window_starts(t_us, max_gap_s * 1e6, window_s), t_us.size]
    cols = {c: frame[c].to_numpy() for c in STANDSTILL_COLUMNS}
    rows = []
    for a, b in zip(starts[:-1], starts[1:]):
        if b - a < MIN_SAMPLES:
            continue
        t = t_us[a:b] * 1e-6
        dt = float(np.median(np.diff(t)))
        k = max(1, int(round(VELOCITY_HALF_SPAN_S / dt)))
        if b - a <= 2 * k:
            continue
        X = cols["x_cyl_m"][a:b]
        v = np.full(b - a, np.inf)
        v[k:-k] = (X[2 * k:] - X[: -2 * k]) / (t[2 * k:] - t[: -2 * k])
        ps, pr, p1, p2, x = (cols[c][a:b] for c in ("ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m"))
        still = (np.abs(v) < STANDSTILL_VELOCITY_M_S) & (np.abs(x) < STANDSTILL_SPOOL_M)
        use = (_run_age(still) * dt >= SETTLE_S) & (ps > p1) & (p2 > pr)
        n = int(use.sum())
        if n < MIN_SAMPLES:
            continue
        r = (p1[use] - pr[use]) / (ps[use] - p1[use]) - (ps[use] - p2[use]) / (p2[use] - pr[use])
        start = frame["timestamp_utc"][int(a)]
        rows.append({
            "valve_id": valve_id,
            "window_start": start,
            "window_end": frame["timestamp_utc"][int(b) - 1],
            "operating_hours": (start - commissioned).total_seconds() / 3600.0,
            "n_samples": n,
            "ps_bar": float(np.median(ps[use])) / 1e5,
            "pr_bar": float(np.median(pr[use])) / 1e5,
            "p1_bar": float(np.median(p1[use])) / 1e5,
            "p2_bar": float(np.median(p2[use])) / 1e5,
            "x_spool_mm": float(np.median(x[use])) * 1e3,
            "eq9_residual": float(np.median(r)),
            "computed_at": computed_at,
        })  # fmt: skip
    return pl.DataFrame(rows, schema=schema) if rows else pl.DataFrame(schema=schema)


def expected_residual(valve, export) -> float:
    """Eq. 9 residual of the valve's design at rest (F_R = 0, nominal supply), from Eq. 3/4.

    The residual hardly depends on the load or on where in the static-friction band the
    cylinder stuck (Table 1: −0.164 … −0.171 over ±d_s and 190–210 bar), so the simulator's
    plant parameters for this valve serve. Falls back to Table 1's −0.17 if the rest state cannot
    be solved.
    """
    from flows.simulate.archive import plant_params_for_valve
    from model.standstill import eq9_residual, standstill

    try:
        params = plant_params_for_valve(valve, export)
        rest = standstill(params)
        value = float(eq9_residual(rest.p1_pa, rest.p2_pa, params.supply.p_s_nominal_pa, params.supply.p_r_nominal_pa))
    except Exception:  # noqa: BLE001 - a design the model cannot bring to rest: use Table 1
        return TABLE1_RESIDUAL
    return value if math.isfinite(value) else TABLE1_RESIDUAL


TABLE1_RESIDUAL = -0.17
"""Eq. 9 residual of Table 1's healthy valve at rest (model.standstill, p_s = 200 bar)."""

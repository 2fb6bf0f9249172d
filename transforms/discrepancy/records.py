"""Records for the discrepancy workflow: contiguous runs of one valve's lake rows as numpy arrays,
with Savitzky–Golay smoothed values and derivatives, and the operating regions of each sample.

A *record* is a window of the monitoring (a contiguous run of samples, no step longer than the
gap limit), cut into pieces of at most ``max_record_s``. Savitzky–Golay values use the weights
of :func:`transforms.derivatives.savgol_weights` (the monitoring's filter); they are NaN within
half a stencil of a record's ends.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import polars as pl

from transforms.derivatives import savgol_weights
from transforms.discrepancy.settings import DiscrepancySettings

__all__ = [
    "REGIONS",
    "Record",
    "operating_regions",
    "prepare_record",
    "savgol",
    "split_records",
]

SIGNAL_COLUMNS = {"ps": "ps_pa", "pr": "pr_pa", "p1": "p1_pa", "p2": "p2_pa", "x": "x_spool_m", "X": "x_cyl_m"}
"""Record signal → lake column."""

REGIONS = (
    "all",
    "extending",
    "retracting",
    "standstill",
    "pressure_low",
    "pressure_mid",
    "pressure_high",
)
"""Operating regions of the gap and residual reports (:func:`operating_regions`)."""


@dataclass
class Record:
    """One contiguous record of a valve.

    Attributes
    ----------
    valve_id : str
    start_us, end_us : int
        Time stamps of the first and last sample (µs since the epoch, UTC).
    dt : float
        Sample period. [s]
    raw : dict of ndarray
        Recorded ``ps``, ``pr``, ``p1``, ``p2`` [Pa], ``x`` (spool) and ``X`` (cylinder) [m].
    sg : dict of ndarray
        Savitzky–Golay values (:func:`prepare_record`): ``ps``, ``pr``, ``p1``, ``p2``, ``x``,
        ``X`` smoothed; ``v`` = dX/dt [m/s], ``a`` = d²X/dt² [m/s²], ``dp1``, ``dp2`` [Pa/s].
    """

    valve_id: str
    start_us: int
    end_us: int
    dt: float
    raw: dict[str, np.ndarray]
    sg: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.raw["p1"].shape[0])

    @property
    def t(self) -> np.ndarray:
        """Time since the record's first sample. [s]"""
        return np.arange(self.n) * self.dt


def split_records(lake_one_valve: pl.DataFrame, settings: DiscrepancySettings) -> list[Record]:
    """Contiguous records of one valve's lake rows (sorted by time), at most
    ``settings.max_records`` of them, evenly spaced over the rows when there are more."""
    if lake_one_valve.height == 0:
        return []
    frame = lake_one_valve.sort("timestamp_utc")
    valve_ids = frame["valve_id"].unique().to_list()
    if len(valve_ids) != 1:
        raise ValueError(f"split_records needs the rows of one valve, got {valve_ids}")
    ts = frame["timestamp_utc"].cast(pl.Datetime("us", "UTC")).to_physical().to_numpy().astype(np.int64)
    steps = np.diff(ts)
    if settings.sample_period_s is not None:
        dt = float(settings.sample_period_s)
    else:
        pos = steps[steps > 0]
        if pos.size == 0:
            return []
        dt = float(np.median(pos)) * 1e-6
    cuts = np.flatnonzero(steps > settings.gap_limit_periods * dt * 1e6) + 1
    starts = np.r_[0, cuts]
    stops = np.r_[cuts, ts.size]
    arrays = {k: frame[c].to_numpy().astype(float) for k, c in SIGNAL_COLUMNS.items()}
    n_min = int(round(settings.min_record_s / dt))
    n_max = int(round(settings.max_record_s / dt))
    pieces: list[tuple[int, int]] = []
    for a, b in zip(starts, stops):
        while b - a >= n_min:
            e = min(b, a + n_max)
            if e - a >= n_min:
                pieces.append((int(a), int(e)))
            a = e
    if len(pieces) > settings.max_records:
        pick = np.unique(np.round(np.linspace(0, len(pieces) - 1, settings.max_records)).astype(int))
        pieces = [pieces[i] for i in pick]
    vid = str(valve_ids[0])
    out = []
    for a, b in pieces:
        raw = {k: v[a:b].copy() for k, v in arrays.items()}
        if not all(np.all(np.isfinite(v)) for v in raw.values()):
            continue
        out.append(Record(vid, int(ts[a]), int(ts[b - 1]), dt, raw))
    return out


def savgol(y: np.ndarray, window: int, order: int, deriv: int, dt: float) -> np.ndarray:
    """Savitzky–Golay value (deriv 0) or derivative of a uniformly sampled signal; NaN within
    half a stencil of either end."""
    w = savgol_weights(window, order, deriv)
    h = window // 2
    out = np.full(y.shape, np.nan)
    if y.size < window:
        return out
    # savgol_weights are ordered oldest sample first (a dot product over the stencil)
    out[h:-h] = np.convolve(y, w[::-1], mode="valid") / dt**deriv
    return out


def prepare_record(rec: Record, settings: DiscrepancySettings) -> Record:
    """Fill ``rec.sg`` (see :class:`Record`); returns the record."""
    L, o, dt = settings.savgol_window, settings.savgol_order, rec.dt
    sg = {k: savgol(v, L, o, 0, dt) for k, v in rec.raw.items()}
    sg["v"] = savgol(rec.raw["X"], L, o, 1, dt)
    sg["a"] = savgol(rec.raw["X"], L, o, 2, dt)
    sg["dp1"] = savgol(rec.raw["p1"], L, o, 1, dt)
    sg["dp2"] = savgol(rec.raw["p2"], L, o, 1, dt)
    rec.sg = sg
    return rec


def operating_regions(v: np.ndarray, p1: np.ndarray, p2: np.ndarray, ps: np.ndarray, settings: DiscrepancySettings) -> dict[str, np.ndarray]:
    """Boolean masks of :data:`REGIONS` per sample.

    Motion: ``extending`` v_X > v_standstill, ``retracting`` v_X < −v_standstill,
    ``standstill`` otherwise. Pressure level of the mean chamber pressure p̄ = (p1 + p2)/2 against
    the supply: ``pressure_low`` p̄ < 0.4 p_s, ``pressure_high`` p̄ ≥ 0.6 p_s, ``pressure_mid``
    between. Samples with NaN inputs belong to no region."""
    ok = np.isfinite(v) & np.isfinite(p1) & np.isfinite(p2) & np.isfinite(ps)
    vs = settings.v_standstill_m_s
    with np.errstate(invalid="ignore"):
        ratio = 0.5 * (p1 + p2) / ps
        return {
            "all": ok,
            "extending": ok & (v > vs),
            "retracting": ok & (v < -vs),
            "standstill": ok & (np.abs(v) <= vs),
            "pressure_low": ok & (ratio < 0.4),
            "pressure_mid": ok & (ratio >= 0.4) & (ratio < 0.6),
            "pressure_high": ok & (ratio >= 0.6),
        }

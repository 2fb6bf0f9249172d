"""Records for the discrepancy workflow: contiguous runs of one valve's lake rows as numpy arrays,
with Savitzky–Golay smoothed values and derivatives, and the operating regions of each sample.

A *record* is a window of the monitoring (a contiguous run of samples, no step longer than the
gap limit; with a window length ``settings.window_s``, a long run -- a continuous recording -- is cut by
the clock as :func:`transforms.windows.window_starts` cuts it, a snapshot is one window), cut into
pieces of at most ``max_record_s``. So a record never straddles a monitoring window's edge.
Savitzky–Golay values use the weights of :func:`transforms.derivatives.savgol_weights` (the
monitoring's filter); they are NaN within half a stencil of a record's ends.

Which records a span holds is decided from its time stamps alone (:func:`record_pieces`,
:func:`pick_evenly`), so a reader can choose them from the time column read in chunks of whole
windows and then read only the chosen records' rows (``flows.discrepancy.lake_records``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import polars as pl

from model.params import SpoolParams
from transforms.derivatives import savgol_weights
from transforms.discrepancy.settings import DiscrepancySettings
from transforms.discrepancy.states import cylinder_states, spool_from_reference
from transforms.windows import window_starts

__all__ = [
    "REGIONS",
    "Record",
    "noise_rms",
    "operating_regions",
    "pick_evenly",
    "prepare_record",
    "record_from_rows",
    "record_pieces",
    "savgol",
    "split_records",
]

SIGNAL_COLUMNS = {"ps": "ps_pa", "pr": "pr_pa", "p1": "p1_pa", "p2": "p2_pa", "x": "x_spool_m", "X": "x_cyl_m"}
"""Record signal → lake column."""
REFERENCE_COLUMN = ("x_ref", "x_ref_m")
"""The spool reference (optional; the record holds it where every sample has it)."""

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
        Recorded ``ps``, ``pr``, ``p1``, ``p2`` [Pa], ``x`` (spool) and ``X`` (cylinder) [m];
        ``x_ref`` (the spool reference) [m] where recorded.
    sg : dict of ndarray
        Savitzky–Golay values (:func:`prepare_record`): ``ps``, ``pr``, ``p1``, ``p2`` smoothed,
        ``dp1``, ``dp2`` [Pa/s]; ``x``, ``X`` the positions, ``v`` = dX/dt [m/s], ``a`` = d²X/dt²
        [m/s²], reconstructed (:mod:`transforms.discrepancy.states`) or Savitzky–Golay.
    noise : dict of (float, int)
        (sum of squares, count) of each recorded signal's noise (:func:`noise_rms`, on the
        Savitzky–Golay values), for the noise floors and the reconstruction.
    pos : dict of ndarray
        The positions ``x``, ``X`` [m] the equations and the replays' restarts take in place of
        the recorded ones (:meth:`position`): the reconstructed ones, or none (the recorded).
    """

    valve_id: str
    start_us: int
    end_us: int
    dt: float
    raw: dict[str, np.ndarray]
    sg: dict[str, np.ndarray] = field(default_factory=dict)
    pos: dict[str, np.ndarray] = field(default_factory=dict)
    noise: dict[str, tuple[float, int]] = field(default_factory=dict)

    def position(self, key: str) -> np.ndarray:
        """The spool (``"x"``) or cylinder (``"X"``) position the equations take [m]."""
        return self.pos.get(key, self.raw[key])

    @property
    def n(self) -> int:
        return int(self.raw["p1"].shape[0])

    @property
    def t(self) -> np.ndarray:
        """Time since the record's first sample. [s]"""
        return np.arange(self.n) * self.dt


def record_pieces(ts_us: np.ndarray, dt: float, settings: DiscrepancySettings) -> list[tuple[int, int]]:
    """Index ranges ``[a, b)`` of the records in one valve's sorted time stamps (µs since the
    epoch, int64), in time order: the windows of :func:`transforms.windows.window_starts` (gap
    limit ``gap_limit_periods`` · ``dt`` [s], length ``settings.window_s``, None: whole runs) cut
    from their first sample into pieces of ``max_record_s``; pieces shorter than
    ``min_record_s`` are left out. A window's pieces depend on its own time stamps only, so the
    pieces of a run of whole windows are those the whole array gives there."""
    ts_us = np.asarray(ts_us, dtype=np.int64)
    if ts_us.size == 0:
        return []
    starts = window_starts(ts_us, settings.gap_limit_periods * dt * 1e6, settings.window_s)
    stops = np.r_[starts[1:], ts_us.size]
    n_min = int(round(settings.min_record_s / dt))
    n_max = int(round(settings.max_record_s / dt))
    pieces: list[tuple[int, int]] = []
    for a, b in zip(starts, stops):
        while b - a >= n_min:
            e = min(b, a + n_max)
            if e - a >= n_min:
                pieces.append((int(a), int(e)))
            a = e
    return pieces


def pick_evenly(n_pieces: int, max_records: int) -> np.ndarray:
    """Indices of the pieces diagnosed: all of them, or ``max_records`` evenly spaced over them."""
    if n_pieces <= max_records:
        return np.arange(n_pieces)
    return np.unique(np.round(np.linspace(0, n_pieces - 1, max_records)).astype(int))


def record_from_rows(rows: pl.DataFrame, valve_id: str, dt: float) -> Record | None:
    """The record of some time-sorted lake rows (one piece), None if a signal is not finite."""
    raw = {k: rows[c].to_numpy().astype(float) for k, c in SIGNAL_COLUMNS.items()}
    if not all(np.all(np.isfinite(v)) for v in raw.values()):
        return None
    key, column = REFERENCE_COLUMN
    if column in rows.columns:
        ref = rows[column].cast(pl.Float64).fill_null(float("nan")).to_numpy()
        if np.all(np.isfinite(ref)):
            raw[key] = ref
    ts = rows["timestamp_utc"].cast(pl.Datetime("us", "UTC")).to_physical()
    return Record(valve_id, int(ts[0]), int(ts[-1]), dt, raw)


def split_records(lake_one_valve: pl.DataFrame, settings: DiscrepancySettings) -> list[Record]:
    """Contiguous records of one valve's lake rows (:func:`record_pieces`), at most ``settings.max_records`` of them,
    evenly spaced over the pieces when there are more (:func:`pick_evenly`)."""
    if lake_one_valve.height == 0:
        return []
    frame = lake_one_valve.sort("timestamp_utc", maintain_order=True)
    valve_ids = frame["valve_id"].unique().to_list()
    if len(valve_ids) != 1:
        raise ValueError(f"split_records needs the rows of one valve, got {valve_ids}")
    ts = frame["timestamp_utc"].cast(pl.Datetime("us", "UTC")).to_physical().to_numpy().astype(np.int64)
    if settings.sample_period_s is not None:
        dt = float(settings.sample_period_s)
    else:
        steps = np.diff(ts)
        pos = steps[steps > 0]
        if pos.size == 0:
            return []
        dt = float(np.median(pos)) * 1e-6
    pieces = record_pieces(ts, dt, settings)
    vid = str(valve_ids[0])
    out = []
    for i in pick_evenly(len(pieces), settings.max_records):
        a, b = pieces[i]
        rec = record_from_rows(frame.slice(a, b - a), vid, dt)
        if rec is not None:
            out.append(rec)
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


def noise_rms(raw: np.ndarray, smooth: np.ndarray, window: int, order: int) -> tuple[float, int]:
    """(sum of squares, count) of the recorded noise of one signal: raw − its Savitzky–Golay
    smoothing ``smooth`` (``window``, ``order``), scaled by 1/(1 − h₀), h₀ the smoother's central
    coefficient (the residual of a projection keeps 1 − h₀ of white noise's variance)."""
    h0 = float(savgol_weights(window, order, 0)[window // 2])
    d = raw - smooth
    ok = np.isfinite(d)
    return float(np.sum(d[ok] ** 2)) / (1.0 - h0), int(ok.sum())


def prepare_record(rec: Record, settings: DiscrepancySettings, spool: SpoolParams | None = None) -> Record:
    """Fill ``rec.sg`` and ``rec.pos`` (see :class:`Record`; the positions reconstructed with
    ``settings.reconstruct_spool`` and ``reconstruct_cylinder``, the spool through Eq. 1 with
    ``spool``, default the nameplate's); returns the record."""
    L, o, dt = settings.savgol_window, settings.savgol_order, rec.dt
    sg = {k: savgol(v, L, o, 0, dt) for k, v in rec.raw.items() if k != "x_ref"}
    sg["v"] = savgol(rec.raw["X"], L, o, 1, dt)
    sg["a"] = savgol(rec.raw["X"], L, o, 2, dt)
    sg["dp1"] = savgol(rec.raw["p1"], L, o, 1, dt)
    sg["dp2"] = savgol(rec.raw["p2"], L, o, 1, dt)
    rec.sg = sg
    rec.noise = {k: noise_rms(rec.raw[k], sg[k], L, o) for k in SIGNAL_COLUMNS}
    sd = {k: float(np.sqrt(ss / n)) if n else 0.0 for k, (ss, n) in rec.noise.items()}
    rec.pos = {}
    if settings.reconstruct_spool:
        x = spool_from_reference(rec.raw["x"], rec.raw.get("x_ref"), dt, spool or SpoolParams(), sd["x"], settings.spool_offset_s)
        if x is not None:
            sg["x"] = rec.pos["x"] = x
    if settings.reconstruct_cylinder and rec.n > 3:
        X, v, a = cylinder_states(rec.raw["X"], dt, sd["X"])
        sg["X"] = rec.pos["X"] = X
        sg["v"], sg["a"] = v, a
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

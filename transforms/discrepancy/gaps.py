"""The gap between a replayed model and the measurements, per signal and operating region.

Per signal s ∈ {p1, p2, X} and region, the gap is the root mean square of (replayed reading −
recorded signal) over the replayed samples of the region (in Pa resp. m). The single number
reported as ``gap_before``/``gap_after`` is the *normalised gap*

    gap = sqrt( ( (e_p1 / 1 bar)² + (e_p2 / 1 bar)² + (e_X / 1 mm)² ) / 3 )

over all replayed samples: the RMS of the three signals' errors in bar and mm. 1 bar and 1 mm
are the scales at which the two kinds of error matter about equally to the monitoring (1 bar of
chamber pressure is ~1 % of the Eq. 7 pressure drop; 1 mm of position is ~0.2 % of the stroke,
what a 1 % flow error accumulates over a 2.5 s replay segment at 0.04 m/s). Recorded noise
(~0.05 bar, 1 µm) puts a floor of ~0.04 under it.

The same record is also replayed split in two (:func:`model.replay.replay`'s ``drive``), so that
each effect is judged where it acts and an error in the load estimate cannot hide or invent it:

* the **hydraulic gap** (signals ``p1_hydraulic``, ``p2_hydraulic``): p1, p2 replayed from the
  recorded spool position, supply, return and the recorded cylinder motion (the positions
  Savitzky–Golay smoothed; no load, mass or friction), sqrt(((e_p1/1 bar)² + (e_p2/1 bar)²)/2); leakage, air, the supply line and the sensor
  effects act here;
* the **mechanical gap** (signal ``X_mechanical``): X replayed from the recorded pressures with
  the load estimate, mass and friction (the viscous friction and the mass moved by up to 1 % and
  2 % by what the load leaves along v_X and the acceleration: ``rows._mechanical_model``),
  restarted from the measured state every ``mechanical_segment_s``, at the start of every
  move and after every load step the estimate found, e_X/1 mm over the moving samples (|v_X| >
  ``v_move_m_s``: while the cylinder sticks the load does not show, so when it breaks away is
  the load estimate's, not the motion's) away from the steps (within ``step_guard_samples`` of a
  step the estimate holds no sample: ``rows._mechanical_restarts``); mass and friction act here.

Their **noise floors** are what the sensor noise alone leaves through the replay, on the same
scales (``rows.noise_floors``; each channel's noise RMS from its high-frequency part,
:func:`transforms.discrepancy.records.noise_rms`), by Monte Carlo: for the hydraulic gap the
recorded noise of p1, p2 together with what fresh noise on every recorded channel (the positions
too) leaves in the hydraulic replay; for the mechanical one the X noise together with what fresh
noise on the recorded pressures and X leaves in the mechanical replay, which integrates the
force twice (~10 µm on Table 1's sensors, not the X channel's 1 µm).
"""

from __future__ import annotations

import numpy as np

__all__ = ["GAP_SCALES", "GAP_SIGNALS", "NOISE_GAP", "SPLIT_GAPS", "GapAccumulator", "normalised_gap"]

GAP_SIGNALS = ("p1", "p2", "X")
GAP_SCALES = {"p1": 1.0e5, "p2": 1.0e5, "X": 1.0e-3, "p1_hydraulic": 1.0e5, "p2_hydraulic": 1.0e5, "X_mechanical": 1.0e-3}
"""Normalising scale of each signal's RMS error in the normalised gap: 1 bar, 1 bar, 1 mm."""
GAP_UNITS = {"p1": "Pa", "p2": "Pa", "X": "m", "p1_hydraulic": "Pa", "p2_hydraulic": "Pa", "X_mechanical": "m"}
SPLIT_GAPS = {"hydraulic": ("p1_hydraulic", "p2_hydraulic"), "mechanical": ("X_mechanical",)}
"""The split gaps and their signals (module docstring)."""
RECORDED_OF = {"p1": "p1", "p2": "p2", "X": "X", "p1_hydraulic": "p1", "p2_hydraulic": "p2", "X_mechanical": "X"}
"""The recorded signal each replayed one is compared with."""
NOISE_GAP = 0.2
"""A normalised gap above this is more than recorded noise and the load estimate leave (exact
model on Table 1's sensors: 0.04–0.2, docs/discrepancy.md)."""


def normalised_gap(rms: dict[str, float]) -> float:
    """sqrt(mean over p1, p2, X of (rms / scale)²) (module docstring)."""
    return float(np.sqrt(np.mean([(rms[s] / GAP_SCALES[s]) ** 2 for s in GAP_SIGNALS])))


class GapAccumulator:
    """Sums of squared errors per (signal, region) over several records."""

    def __init__(self) -> None:
        self.sse: dict[tuple[str, str], float] = {}
        self.n: dict[tuple[str, str], int] = {}

    def add(self, signal: str, error: np.ndarray, regions: dict[str, np.ndarray]) -> None:
        """Add one record's errors of ``signal`` (NaN where not replayed) for every region."""
        ok = np.isfinite(error)
        for name, mask in regions.items():
            m = ok & mask
            key = (signal, name)
            self.sse[key] = self.sse.get(key, 0.0) + float(np.sum(error[m] ** 2))
            self.n[key] = self.n.get(key, 0) + int(m.sum())

    def rms(self, signal: str, region: str = "all") -> float:
        """RMS error of ``signal`` in ``region`` (NaN without samples)."""
        n = self.n.get((signal, region), 0)
        return float(np.sqrt(self.sse[(signal, region)] / n)) if n else float("nan")

    def gap(self, region: str = "all") -> float:
        """The normalised gap in ``region``."""
        return normalised_gap({s: self.rms(s, region) for s in GAP_SIGNALS})

    def split_gap(self, kind: str, region: str = "all") -> float:
        """The hydraulic or mechanical gap (``SPLIT_GAPS``) in ``region``: the RMS of its signals'
        errors on the gap scales."""
        sig = SPLIT_GAPS[kind]
        return float(np.sqrt(np.mean([(self.rms(s, region) / GAP_SCALES[s]) ** 2 for s in sig])))

    def rows(self) -> list[dict]:
        """One dict per (signal, region): signal, region, rms (SI), unit, n_samples."""
        return [
            {"signal": s, "region": r, "rms": self.rms(s, r), "unit": GAP_UNITS[s], "n_samples": self.n[(s, r)]}
            for (s, r) in sorted(self.n)
        ]

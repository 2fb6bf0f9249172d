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
"""

from __future__ import annotations

import numpy as np

__all__ = ["GAP_SCALES", "GAP_SIGNALS", "NOISE_GAP", "GapAccumulator", "normalised_gap"]

GAP_SIGNALS = ("p1", "p2", "X")
GAP_SCALES = {"p1": 1.0e5, "p2": 1.0e5, "X": 1.0e-3}
"""Normalising scale of each signal's RMS error in the normalised gap: 1 bar, 1 bar, 1 mm."""
GAP_UNITS = {"p1": "Pa", "p2": "Pa", "X": "m"}
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

    def rows(self) -> list[dict]:
        """One dict per (signal, region): signal, region, rms (SI), unit, n_samples."""
        return [
            {"signal": s, "region": r, "rms": self.rms(s, r), "unit": GAP_UNITS[s], "n_samples": self.n[(s, r)]}
            for (s, r) in sorted(self.n)
        ]

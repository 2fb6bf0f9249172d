"""The opening-area characteristic Â(u): piecewise linear on knots, linear beyond the end knots.

:class:`Characteristic` is what step 4a fits (:mod:`transforms.baseline`) and step 4b shifts and
scales (:mod:`transforms.fit`; the fit may evaluate a little outside the commissioning range).
The nominal characteristic α_nominal·A(u) is computed by the flows layer from the model and
handed in as arrays (:meth:`Characteristic.from_arrays`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Characteristic", "scaled_shifted"]


@dataclass(frozen=True, eq=False)
class Characteristic:
    """Piecewise-linear Â(u): values at strictly increasing knots, linear extrapolation."""

    knots_u_m: np.ndarray
    values_m2: np.ndarray

    def __post_init__(self) -> None:
        k = np.array(self.knots_u_m, dtype=np.float64, copy=True).reshape(-1)
        v = np.array(self.values_m2, dtype=np.float64, copy=True).reshape(-1)
        if k.shape != v.shape:
            raise ValueError(f"knots ({k.shape[0]}) and values ({v.shape[0]}) differ in length")
        if k.shape[0] < 2:
            raise ValueError("a characteristic needs at least two knots")
        if not (np.isfinite(k).all() and np.isfinite(v).all()):
            raise ValueError("knots and values must be finite")
        if np.any(np.diff(k) <= 0):
            raise ValueError("knots must be strictly increasing")
        k.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "knots_u_m", k)
        object.__setattr__(self, "values_m2", v)

    @classmethod
    def from_arrays(cls, u_m, values_m2) -> Characteristic:
        """From a sampled curve (e.g. the nominal α·A(u) on a grid); sorted by u if needed."""
        u = np.asarray(u_m, dtype=np.float64).reshape(-1)
        v = np.asarray(values_m2, dtype=np.float64).reshape(-1)
        if u.shape != v.shape:
            raise ValueError("u and values differ in length")
        order = np.argsort(u, kind="stable")
        return cls(u[order], v[order])

    @classmethod
    def from_dict(cls, d: dict) -> Characteristic:
        return cls(np.asarray(d["knots_u_m"]), np.asarray(d["values_m2"]))

    def to_dict(self) -> dict[str, list[float]]:
        return {"knots_u_m": self.knots_u_m.tolist(), "values_m2": self.values_m2.tolist()}

    @property
    def u_range(self) -> tuple[float, float]:
        return float(self.knots_u_m[0]), float(self.knots_u_m[-1])

    @property
    def segment_slopes(self) -> np.ndarray:
        return np.diff(self.values_m2) / np.diff(self.knots_u_m)

    def _segment(self, u: np.ndarray) -> np.ndarray:
        j = np.searchsorted(self.knots_u_m, u, side="right") - 1
        return np.clip(j, 0, self.knots_u_m.shape[0] - 2)

    def evaluate(self, u) -> np.ndarray:
        """Â(u); linear extrapolation with the end segments."""
        u = np.asarray(u, dtype=np.float64)
        j = self._segment(u)
        return self.values_m2[j] + self.segment_slopes[j] * (u - self.knots_u_m[j])

    def slope(self, u) -> np.ndarray:
        """dÂ/du (right-continuous at the knots)."""
        u = np.asarray(u, dtype=np.float64)
        return self.segment_slopes[self._segment(u)]

    def __call__(self, u) -> np.ndarray:
        return self.evaluate(u)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Characteristic):
            return NotImplemented
        return np.array_equal(self.knots_u_m, other.knots_u_m) and np.array_equal(self.values_m2, other.values_m2)

    def __hash__(self) -> int:
        return hash((self.knots_u_m.tobytes(), self.values_m2.tobytes()))


def scaled_shifted(characteristic: Characteristic, alpha: float, x_m: float) -> Characteristic:
    """α·Â(u + x) as a characteristic (the knots move by −x; Eq. 8's model of a changed edge)."""
    return Characteristic(characteristic.knots_u_m - x_m, alpha * characteristic.values_m2)

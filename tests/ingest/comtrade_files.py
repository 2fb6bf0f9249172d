"""COMTRADE recordings (IEEE C37.111) written for the tests: a ``.cfg`` and its ``.dat`` in any of
the four data file types, with analog channels scaled ``a·raw + b`` (primary or secondary) and
digital channels; the scaled values are returned so that the same samples can be written as CSV."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

RAW_DTYPE = {"ASCII": np.int64, "BINARY": np.int16, "BINARY32": np.int32, "FLOAT32": np.float32}


@dataclass
class Analog:
    ch_id: str
    unit: str
    raw: np.ndarray
    a: float = 1.0
    b: float = 0.0
    ps: str = "P"
    primary: float = 1.0
    secondary: float = 1.0

    def scaled(self) -> np.ndarray:
        """What the recording means: ``a·raw + b``, on the primary side."""
        v = self.a * self.raw.astype(np.float64) + self.b
        return v * (self.primary / self.secondary) if self.ps == "S" else v


@dataclass
class Recording:
    analogs: list[Analog]
    digitals: list[tuple[str, np.ndarray]] = field(default_factory=list)
    rate_hz: float = 10.0
    start: str = "01/03/2025,13:00:00.000000"
    rev: str = "1999"
    time_code: str | None = None
    stamps: np.ndarray | None = None
    """Time stamps (µs units × timemult); with them, ``nrates = 0`` (time stamps critical)."""
    timemult: float = 1.0

    @property
    def n(self) -> int:
        return len(self.analogs[0].raw)


def write_comtrade(cfg: Path, rec: Recording, ft: str) -> Path:
    """Write ``cfg`` and the ``.dat`` beside it."""
    n, na, nd = rec.n, len(rec.analogs), len(rec.digitals)
    lines = [f"STATION,REC1,{rec.rev}", f"{na + nd},{na}A,{nd}D"]
    for k, c in enumerate(rec.analogs, start=1):
        lo, hi = (-32767, 32767)
        lines.append(f"{k},{c.ch_id},,,{c.unit},{c.a!r},{c.b!r},0,{lo},{hi},{c.primary!r},{c.secondary!r},{c.ps}")
    for k, (ch_id, _) in enumerate(rec.digitals, start=1):
        lines.append(f"{k},{ch_id},,,0")
    lines.append("50")
    lines += ["0", f"0,{n}"] if rec.stamps is not None else ["1", f"{rec.rate_hz!r},{n}"]
    lines += [rec.start, rec.start, ft, repr(rec.timemult)]
    if rec.rev == "2013" and rec.time_code is not None:
        lines += [f"{rec.time_code},{rec.time_code}", "0,0"]
    cfg.write_text("\r\n".join(lines) + "\r\n")
    stamps = rec.stamps if rec.stamps is not None else np.round(np.arange(n) * 1e6 / rec.rate_hz).astype(np.int64)
    dat = cfg.with_suffix(".dat")
    if ft == "ASCII":
        cols = [np.arange(1, n + 1).astype(str), stamps.astype(str)] + [c.raw.astype(np.int64).astype(str) for c in rec.analogs] + [b.astype(np.int64).astype(str) for _, b in rec.digitals]
        dat.write_text("\r\n".join(",".join(row) for row in zip(*cols)) + "\r\n")
        return cfg
    words = math.ceil(nd / 16)
    dtype = np.dtype([("n", "<u4"), ("t", "<u4"), ("a", {"BINARY": "<i2", "BINARY32": "<i4", "FLOAT32": "<f4"}[ft], (na,)), ("d", "<u2", (words,))])
    out = np.zeros(n, dtype=dtype)
    out["n"], out["t"] = np.arange(1, n + 1), stamps
    for j, c in enumerate(rec.analogs):
        out["a"][:, j] = c.raw
    for k, (_, bits) in enumerate(rec.digitals):
        out["d"][:, k // 16] |= (bits.astype(np.uint16) << (k % 16)).astype(np.uint16)
    out.tofile(dat)
    return cfg

"""Recordings of the reference plant as the lake holds them (the canonical sensor frame of
docs/architecture.md), and several windows of one valve."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from typing import Sequence

import numpy as np
import polars as pl

from .params import RefPlant
from .recording import RefRecording, simulate

#: Column order of the canonical sensor frame.
COLUMNS = ("valve_id", "date", "timestamp_utc", "ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m", "x_ref_m")
_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)


def to_lake_frame(recordings: RefRecording | Sequence[RefRecording], valve_id: str, start: datetime,
                  spacing: timedelta = timedelta(hours=1)) -> pl.DataFrame:
    """The recorded signals as lake rows: valve_id (Utf8), date (Date, UTC), timestamp_utc
    (Datetime µs UTC), ps_pa, pr_pa, p1_pa, p2_pa, x_spool_m, x_cyl_m, x_ref_m (Float32).

    One recording starts at ``start`` (timezone-aware); a sequence of recordings gives window i at
    ``start + i * spacing`` (snapshots an hour apart by default), sorted by time."""
    if start.tzinfo is None:
        raise ValueError("start must be timezone-aware (UTC)")
    recs = [recordings] if isinstance(recordings, RefRecording) else list(recordings)
    frames = []
    for i, r in enumerate(recs):
        t0 = int(round((start + i * spacing - _EPOCH).total_seconds() * 1e6))
        ts = pl.Series("timestamp_utc", t0 + np.round(r.t_s * 1e6).astype(np.int64)).cast(pl.Datetime("us", "UTC"))
        frames.append(pl.DataFrame({
            "valve_id": pl.Series([valve_id] * r.n_samples, dtype=pl.Utf8),
            "date": ts.dt.date(),
            "timestamp_utc": ts,
            **{f"{name}": pl.Series(getattr(r, sig), dtype=pl.Float32) for name, sig in
               (("ps_pa", "ps"), ("pr_pa", "pr"), ("p1_pa", "p1"), ("p2_pa", "p2"),
                ("x_spool_m", "x_spool"), ("x_cyl_m", "x_cyl"), ("x_ref_m", "x_ref"))},
        }))
    return pl.concat(frames).sort("timestamp_utc").select(COLUMNS)


def simulate_windows(plant: RefPlant, n_windows: int, seed: int, *, duration_s: float = 10.0, **kwargs) -> list[RefRecording]:
    """``n_windows`` snapshot windows of one valve, window i drawn from seed (seed, i) alone:
    ``simulate(plant, duration_s, seed * 1000 + i, **kwargs)``."""
    return [simulate(plant, duration_s, int(seed) * 1000 + i, **kwargs) for i in range(n_windows)]

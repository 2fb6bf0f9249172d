"""A wide batch that already is the lake's rows, checked and converted in one pass per column.

Most wide exports of a continuous recording hold, batch after batch, one row per grid instant:
every cell filled, every time a grid instant exactly one sample period after the previous, every
value plausible. For such a batch the rules of ``docs/ingest.md`` (quarantine, de-duplication,
gaps, interpolation) have nothing to do, and its lake rows are its rows: the time in µs and each
tag's value in SI as float32. :func:`gridded_columns` tells whether a batch is one and, if it
is, gives those rows — the time column in one pass (:func:`_on_grid`: on the grid, one period
apart, to µs) and each tag column in one pass (:func:`_to_lake`: the SI factor, the physical
range in SI as float64 and as the float32 the lake stores, the cast). It changes no state: the
caller (``transforms.ingest.stream``) then gives the rows exactly as the general path would, or,
on None, takes the batch by the general path, which finds, quarantines and names what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import polars as pl

from schemas.plant_config import ExportSpec
from transforms.ingest.samples import FUTURE_TOLERANCE_NS, TagTable, bad_quality
from transforms.ingest.text_rows import ROW_FAULT_COLUMN
from transforms.ingest.timestamps import UTC_NS, parse_timestamps


@numba.njit(cache=True, nogil=True)
def _on_grid(t_ns: np.ndarray, period_ns: int, t_us: np.ndarray) -> bool:
    """``t_us[i] = t_ns[i] // 1000``, and whether every time is a grid instant one period after
    the one before it (no branch in the loop: the compiler vectorises it)."""
    ok = len(t_ns) == 0 or t_ns[0] % period_ns == 0
    for i in range(len(t_ns)):
        t_us[i] = t_ns[i] // 1000
    for i in range(1, len(t_ns)):
        ok &= t_ns[i] - t_ns[i - 1] == period_ns
    return ok


@numba.njit(cache=True, nogil=True)
def _to_lake(values: np.ndarray, factor: float, lo: float, hi: float, out: np.ndarray) -> bool:
    """``out[i] = float32(values[i] * factor)``, and whether every SI value lies in ``[lo, hi]``,
    as the float64 of the general path's check and as the float32 the lake's schema checks (NaN
    and ±inf fail; no branch in the loop: the compiler vectorises it, ~6× faster)."""
    lo32, hi32 = np.float32(lo), np.float32(hi)
    ok = True
    for i in range(len(values)):
        v = values[i] * factor
        w = np.float32(v)
        ok &= (lo <= v) & (v <= hi) & (lo32 <= w) & (w <= hi32) & (lo <= np.float64(w)) & (np.float64(w) <= hi)
        out[i] = w
    return ok


def lake_value(v_si: float, tid: int, tags: TagTable) -> bool:
    """Whether a value in SI (float64) passes :func:`_to_lake`'s checks (a sample carried from
    the batch before)."""
    w = np.float32(v_si)
    lo, hi = tags.lo[tid], tags.hi[tid]
    return bool(lo <= v_si <= hi and np.float32(lo) <= w <= np.float32(hi) and lo <= float(w) <= hi)


@dataclass(frozen=True)
class GriddedColumns:
    """A wide batch's rows as lake rows (:func:`gridded_columns`)."""

    t_ns: np.ndarray
    """The rows' times (UTC ns), one period apart on the grid, after a slot 0 one period before
    the first row (where a sample held from the batch before belongs)."""
    t_us: np.ndarray
    """The same in µs (the lake's time)."""
    columns: dict[int, np.ndarray]
    """Tag id → its values in SI as float32, slot 0 (left to the caller) and one per row, in the
    batch's column order."""
    raw: dict[int, np.ndarray]
    """Tag id → its last two values as read (float64), carried to the next batch."""


def gridded_columns(df: pl.DataFrame, export: ExportSpec, timezone: str, tags: TagTable, period_ns: int, now_ns: int, origin_ns: int | None) -> GriddedColumns | None:
    """The batch's rows as lake rows, if the batch is already the lake's grid (module doc): a
    time column without an empty cell, the quality code of every row good, a numeric column
    without an empty cell for every other column, each a tag of the plant, at least two rows,
    times on the grid one period apart within the plausible times of every tag, each value in
    its lake column's range. None otherwise (nothing is changed)."""
    ts_name, q_name = export.timestamp_column, export.quality_column
    if df.height < 2 or ts_name not in df.columns or ROW_FAULT_COLUMN in df.columns:
        return None
    ids = tags.ids
    names = [c for c in df.columns if c not in (ts_name, q_name)]
    if not names or any(c not in ids or df[c].null_count() or not df[c].dtype.is_numeric() for c in names):
        return None
    if q_name and (q_name not in df.columns or bad_quality(df[q_name], export.good_quality) is not None):
        return None
    raw_ts = df[ts_name]
    if raw_ts.null_count():
        return None
    ts = parse_timestamps(raw_ts, export.timestamp_format, timezone, unreadable="null", origin_ns=origin_ns, ambiguous=export.ambiguous_time)
    if ts.null_count():
        return None
    t_ns = ts.cast(UTC_NS).to_physical().to_numpy()
    tids = [ids[c] for c in names]
    if t_ns[0] < tags.commissioned_ns[tids].max() or t_ns[-1] > now_ns + FUTURE_TOLERANCE_NS:
        return None
    n = len(t_ns)
    held = np.empty(n + 1, dtype=np.int64)
    held[0], held[1:] = t_ns[0] - period_ns, t_ns
    t_us = np.empty(n + 1, dtype=np.int64)
    if not _on_grid(held, period_ns, t_us):
        return None
    columns, raw = {}, {}
    for c, tid in zip(names, tids):
        col = df[c].cast(pl.Float64)
        out = np.empty(n + 1, dtype=np.float32)
        a = 1
        for chunk in col.get_chunks():  # (a column read by row groups is not copied into one first)
            values = chunk.to_numpy()
            if not _to_lake(values, float(tags.factors[tid]), float(tags.lo[tid]), float(tags.hi[tid]), out[a : a + len(values)]):
                return None
            a += len(values)
        columns[tid], raw[tid] = out, col.tail(2).to_numpy()
    return GriddedColumns(held, t_us, columns, raw)

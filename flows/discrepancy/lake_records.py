"""The discrepancy records of one valve's span of the lake, read in bounded memory.

A continuous valve-day is 86.4 M lake rows; reading a span whole and cutting it
(:func:`transforms.discrepancy.records.split_records`) would hold all of them. Instead
:func:`lake_records`

1. reads the span's time column only, in chunks of whole windows
   (:func:`flows.monitor.flow.span_chunks`: about ``CHUNK_ROWS`` rows a chunk, a long day in
   spans of whole windows) and lists the record pieces of each chunk
   (:func:`transforms.discrepancy.records.record_pieces` -- a chunk of whole windows has the pieces
   the whole span has there) as ``(first, last time stamp, rows)``: three numbers per piece;
2. picks at most ``max_records`` pieces evenly spaced (:func:`transforms.discrepancy.records.pick_evenly`);
3. reads the rows of each picked piece alone (``read_lake`` with the piece's time bounds).

So memory holds one chunk of time stamps and one record, whatever the span; the records are
those ``split_records`` gives on the whole span (tests/discrepancy/test_lake_records.py).
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from flows.common.lake import read_lake
from transforms.discrepancy.records import Record, pick_evenly, record_from_rows, record_pieces
from transforms.discrepancy.settings import DiscrepancySettings

_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
_US = timedelta(microseconds=1)


def piece_table(warehouse: Path, valve_id: str, start: datetime | None, end: datetime | None, settings: DiscrepancySettings) -> tuple[np.ndarray, int]:
    """The record pieces of the valve's lake rows in [start, end), from the time stamps alone:
    an int64 array of rows ``(first time stamp, last time stamp [µs], rows with the first time
    stamp before the piece, rows)`` in time order, and the number of lake rows in the span."""
    from flows.monitor.flow import span_chunks

    dt = float(settings.sample_period_s)
    out, n_rows = [], 0
    for chunk in span_chunks(warehouse, valve_id, settings.gap_limit_periods * dt, start, end, None, (), settings.window_s):
        ts = chunk["timestamp_utc"].to_physical().to_numpy().astype(np.int64)
        n_rows += ts.size
        ab = np.array(record_pieces(ts, dt, settings), dtype=np.int64).reshape(-1, 2)
        a, b = ab[:, 0], ab[:, 1]
        lead = a - np.searchsorted(ts, ts[a], side="left")  # equal time stamps just before a piece
        out.append(np.column_stack([ts[a], ts[b - 1], lead, b - a]))  # 32 bytes a piece
    return (np.concatenate(out) if out else np.empty((0, 4), dtype=np.int64)), n_rows


def lake_records(warehouse: Path, valve_id: str, start: datetime | None, end: datetime | None, settings: DiscrepancySettings) -> tuple[list[Record], int]:
    """The records of the valve's lake rows in [start, end) (module doc): those of
    :func:`transforms.discrepancy.records.split_records` on the span's rows, read piece by
    piece. ``settings.sample_period_s`` must be set. Returns (records, lake rows in the span)."""
    if settings.sample_period_s is None:
        raise ValueError("lake_records needs settings.sample_period_s")
    dt = float(settings.sample_period_s)
    pieces, n_rows = piece_table(warehouse, valve_id, start, end, settings)
    out = []
    for i in pick_evenly(len(pieces), settings.max_records):
        first, last, lead, n = (int(v) for v in pieces[i])
        rows = read_lake(warehouse, [valve_id], _EPOCH + first * _US, _EPOCH + (last + 1) * _US).collect().sort("timestamp_utc", maintain_order=True)
        rec = record_from_rows(rows.slice(lead, n), valve_id, dt)
        if rec is not None:
            out.append(rec)
    return out, n_rows

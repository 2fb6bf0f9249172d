"""A partition's new rows merged with what the lake already holds for it.

Rows are keyed by ``timestamp_utc`` (one valve, one day). A new row at a time the partition
does not have is added. A new row equal to the stored one (every column, nulls equal) changes
nothing, so ingesting an export again, or an export that overlaps an earlier one, adds no
duplicates. A new row that differs from the stored one at the same time is a *lake conflict*,
resolved by ``export.duplicate_rule`` like a conflict inside one export: ``"last"`` – the
later ingest wins (the new row replaces the stored one), ``"first"`` – the stored row stays,
``"error"`` – the ingest is refused, naming valve, time and column.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import polars as pl

from transforms.ingest.errors import IngestError


@dataclass
class Merged:
    """The merged partition and what the merge did."""

    frame: pl.DataFrame
    rows_added: int
    lake_conflicts: int
    changed: bool
    """False when the stored partition already equals the merge (nothing to write)."""


def _ts(frame: pl.DataFrame) -> np.ndarray:
    return frame["timestamp_utc"].to_physical().to_numpy()


def merge_partition(existing: pl.DataFrame | None, new: pl.DataFrame, rule: str, tags_by_column: dict[str, str] | None = None) -> Merged:
    """Merge ``new`` rows into a stored partition (module doc).

    Parameters
    ----------
    existing : DataFrame or None
        The stored partition (sorted by time, unique times), None if there is none.
    new : DataFrame
        The new rows of the same valve and date (sorted, unique times), same schema.
    rule : str
        ``export.duplicate_rule``.
    tags_by_column : dict, optional
        Lake column → tag, for the error message.
    """
    if existing is None or existing.height == 0:
        return Merged(new, new.height, 0, new.height > 0)
    if existing.equals(new):
        return Merged(existing, 0, 0, False)
    te, tn = _ts(existing), _ts(new)
    pos = np.searchsorted(te, tn)
    pos_c = np.minimum(pos, len(te) - 1)
    in_existing = (pos < len(te)) & (te[pos_c] == tn)
    rows_added = int((~in_existing).sum())
    conflicts = 0
    if in_existing.any():
        idx_new = np.flatnonzero(in_existing)
        old = existing[pos_c[idx_new]]
        cand = new[idx_new]
        value_cols = [c for c in new.columns if c not in ("timestamp_utc",)]
        differs = pl.select(pl.any_horizontal([cand[c].ne_missing(old[c]) for c in value_cols])).to_series()
        conflicts = int(differs.sum())
        if conflicts and rule == "error":
            k = int(differs.arg_true()[0])
            col = next(c for c in value_cols if cand[c].ne_missing(old[c])[k])
            when = cand["timestamp_utc"][k].isoformat().replace("+00:00", "Z")
            raise IngestError(
                f"valve {cand['valve_id'][k]} at {when}: column {col} is {old[col][k]!r} in the lake but "
                f"{cand[col][k]!r} in this export; export.duplicate_rule is 'error'",
                tag=(tags_by_column or {}).get(col),
            )
    if rows_added == 0 and (conflicts == 0 or rule == "first"):
        return Merged(existing, 0, conflicts, False)
    if rule == "first":
        merged = pl.concat([existing, new.filter(pl.Series(~in_existing))])
    else:
        replaced = np.zeros(len(te), dtype=bool)
        replaced[pos_c[in_existing]] = True
        merged = pl.concat([existing.filter(pl.Series(~replaced)), new])
    return Merged(merged.sort("timestamp_utc"), rows_added, conflicts, True)

"""A file's quarantined samples on disk while the file is read, so that memory does not grow with
them (a file quarantined wholesale under ``export.max_bad_share = 1``, a PI export full of
digital states): beyond :data:`SPILL_ROWS` rows in memory they go to a temporary Parquet file
(outside the warehouse, removed after the file is recorded or refused); ``record_file`` inserts
them in the file's DuckDB transaction."""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import polars as pl

from schemas.fields import QUARANTINE_FIELDS, polars_schema, validate_table

SPILL_ROWS = 1_000_000
"""Quarantined samples held in memory per file (~0.1 GB) before they are written out."""


def quarantine_rows(frame: pl.DataFrame, extra: dict) -> pl.DataFrame:
    """A stream's quarantine frame → validated rows of table ``quarantine`` (``extra``: file_hash,
    source_file, run_id, ingested_at)."""
    rows = frame.with_columns(**{k: pl.lit(v) for k, v in extra.items()})
    rows = rows.select([f.name for f in QUARANTINE_FIELDS]).cast(dict(polars_schema(QUARANTINE_FIELDS)))
    validate_table(rows, "QUARANTINE_SCHEMA")
    return rows


@dataclass
class QuarantineRows:
    """One file's quarantine rows: those in memory and the Parquet files the others went to."""

    frame: pl.DataFrame
    spilled: list[Path] = field(default_factory=list)

    def remove(self) -> None:
        """Delete the spilled files (after they were recorded, or the file was refused)."""
        if self.spilled:
            shutil.rmtree(self.spilled[0].parent, ignore_errors=True)


class QuarantineSpill:
    """Collects a file's quarantine rows batch by batch, writing them out beyond :data:`SPILL_ROWS`."""

    def __init__(self, extra: dict):
        self.extra = extra
        self.rows = QuarantineRows(pl.DataFrame(schema=polars_schema(QUARANTINE_FIELDS)))

    def take(self, frames: list[pl.DataFrame], final: bool = False) -> None:
        """Write ``frames`` (a stream's quarantine frames, then cleared) out once they hold
        :data:`SPILL_ROWS` rows; with ``final`` keep what is left in memory."""
        n = sum(f.height for f in frames)
        if final:
            self.rows.frame = quarantine_rows(pl.concat(frames), self.extra) if n else self.rows.frame
            frames.clear()
            return
        if n < SPILL_ROWS:
            return
        folder = self.rows.spilled[0].parent if self.rows.spilled else Path(tempfile.mkdtemp(prefix="valvemon-quarantine-"))
        path = folder / f"part-{len(self.rows.spilled):05d}.parquet"
        quarantine_rows(pl.concat(frames), self.extra).write_parquet(path)
        self.rows.spilled.append(path)
        frames.clear()

"""One export frame → lake partitions, quarantine, gaps and counts (no I/O).

:func:`process_export` is everything the ingest does to a file between reading it and writing
the lake: samples (:mod:`.samples`), per-tag sorting, duplicates and grid (:mod:`.grid`),
per-valve assembly, UTC-day split and validation (:mod:`.frames`). It is the file taken as one
batch by :class:`transforms.ingest.stream.ExportStream`, which the ingest feeds batch by batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import polars as pl

from schemas.plant_config import PlantConfig
from transforms.ingest.frames import Partition, split_days
from transforms.ingest.samples import TagTable
from transforms.ingest.stream import ExportCounts, ExportStream, tags_by_column

__all__ = ["ExportCounts", "ExportResult", "process_export", "tags_by_column"]


@dataclass
class ExportResult:
    """The lake content, quarantine and gaps of one export."""

    partitions: list[Partition]
    quarantine: pl.DataFrame
    gaps: pl.DataFrame
    counts: ExportCounts


def process_export(df: pl.DataFrame, config: PlantConfig, *, first_line: int = 2, tags: TagTable | None = None) -> ExportResult:
    """Turn one export, as read, into validated lake partitions.

    Parameters
    ----------
    df : DataFrame
        The export in file order, columns as the file names them (layout per
        ``config.export.layout``); values may be text or numbers.
    config : PlantConfig
        The plant.
    first_line : int
        Line number of ``df``'s first row: 2 for a CSV with a header line, 1 for Parquet rows.
    tags : TagTable, optional
        ``TagTable.from_config(config)``, when the caller already has it.

    Raises
    ------
    IngestError
        For everything the ingest refuses (see :mod:`transforms.ingest.samples`, duplicate rule
        ``"error"``, a failed pandera check); names the line, tag, time and what was expected.
    """
    stream = ExportStream(config, tags)
    frames = stream.feed(df, first_line=first_line, final=True)
    partitions = [Partition(f["valve_id"][0], day, part) for f in frames for day, part in split_days(f)]
    return ExportResult(partitions, stream.quarantine_frame(), stream.gap_frame(), stream.counts)

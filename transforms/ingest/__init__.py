"""Pure parsing and normalisation of historian exports for the sensor lake (no I/O).

The flows read a file into a polars frame and hand it to :func:`process_export`, which returns
validated lake partitions, the quarantined samples, the gaps and the counts; the flows then
merge each partition with the stored one (:func:`merge_partition`) and write it. Method and
rules: ``docs/ingest.md``.
"""

from transforms.ingest.errors import IngestError
from transforms.ingest.export import ExportCounts, ExportResult, process_export, tags_by_column
from transforms.ingest.frames import Partition, assemble_valve, empty_sensor_frame, split_days, validate_raw_rows, validate_sensor_frame
from transforms.ingest.grid import Grid, prepare_tag, to_grid
from transforms.ingest.merge import Merged, merge_partition
from transforms.ingest.samples import QUARANTINE_COLUMNS, Samples, TagTable, check_required_signals, samples_of
from transforms.ingest.timestamps import localize, parse_timestamps

__all__ = [
    "IngestError",
    "ExportCounts",
    "ExportResult",
    "process_export",
    "tags_by_column",
    "Partition",
    "assemble_valve",
    "empty_sensor_frame",
    "split_days",
    "validate_raw_rows",
    "validate_sensor_frame",
    "Grid",
    "prepare_tag",
    "to_grid",
    "Merged",
    "merge_partition",
    "QUARANTINE_COLUMNS",
    "Samples",
    "TagTable",
    "check_required_signals",
    "samples_of",
    "localize",
    "parse_timestamps",
]

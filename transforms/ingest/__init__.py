"""Pure parsing and normalisation of historian exports for the sensor lake (no I/O).

The flows read a file batch by batch (``flows.ingest.formats``) and feed the batches to
:class:`transforms.ingest.stream.ExportStream`, which gives validated lake rows, the quarantined
samples, the gaps and the counts (:func:`process_export`: a frame as one batch); the flows then
merge the rows with the stored ones (:func:`merge_partition`) and write them. Method and rules:
``docs/ingest.md``.
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

"""One export frame → lake partitions, quarantine, gaps and counts (no I/O).

:func:`process_export` is everything the ingest does to a file between reading it and writing
the lake: samples (:mod:`.samples`), per-tag sorting, duplicates and grid (:mod:`.grid`),
per-valve assembly, UTC-day split and validation (:mod:`.frames`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from datetime import datetime

import numba
import numpy as np
import polars as pl

from schemas.fields import REQUIRED_SIGNALS, SIGNAL_COLUMN
from schemas.plant_config import PlantConfig
from transforms.ingest.frames import Partition, assemble_valve, split_days, validate_raw_rows, validate_sensor_frame
from transforms.ingest.grid import Grid, prepare_tag, to_grid
from transforms.ingest.samples import TagTable, check_required_signals, samples_of

GAP_COLUMNS = {
    "valve_id": pl.String,
    "signal": pl.String,
    "tag": pl.String,
    "gap_start": pl.Datetime("us", "UTC"),
    "gap_end": pl.Datetime("us", "UTC"),
    "duration_s": pl.Float64,
}


@dataclass
class ExportCounts:
    """What an export held and what became of it (see ``docs/ingest.md``, "Counts")."""

    rows_in: int = 0
    samples_in: int = 0
    quarantined: int = 0
    duplicates: int = 0
    conflicts: int = 0
    gaps: int = 0
    rows_out: int = 0
    accepted: int = 0
    """Samples left after quarantine and de-duplication (samples_in − quarantined − duplicates − conflicts)."""
    time_start: datetime | None = None
    time_end: datetime | None = None
    valves: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class ExportResult:
    """The lake content, quarantine and gaps of one export."""

    partitions: list[Partition]
    quarantine: pl.DataFrame
    gaps: pl.DataFrame
    counts: ExportCounts


@numba.njit(cache=True, nogil=True)
def _deinterleave(tag_id: np.ndarray, t_ns: np.ndarray, values: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """Rows in a fixed order of ``k`` tags → each tag's times and values (rows ``j, j+k, …``), in
    one pass that also checks the order; False (and partly filled arrays) where it breaks."""
    m = len(tag_id) // k
    t_cols = np.empty((k, m), dtype=t_ns.dtype)
    v_cols = np.empty((k, m), dtype=values.dtype)
    for i in range(m):
        for j in range(k):
            r = i * k + j
            if tag_id[r] != tag_id[j]:
                return t_cols, v_cols, False
            t_cols[j, i] = t_ns[r]
            v_cols[j, i] = values[r]
    return t_cols, v_cols, True


def split_by_tag(tag_id: np.ndarray, t_ns: np.ndarray, values: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray, slice | np.ndarray]]:
    """Each tag's times and values, in file order: ``(tag id, t_ns, values, row selector)``.

    Two common layouts are split without a gather: rows grouped by tag (PI: one block per
    tag, slices) and rows interleaved in a fixed tag order (Ignition "tall", archives: one row
    per tag and instant, one de-interleaving pass). Anything else is grouped by a stable sort.
    """
    n = len(tag_id)
    if n == 0:
        return []
    differs = tag_id[1:] != tag_id[:-1]
    n_blocks = int(np.count_nonzero(differs)) + 1
    if n_blocks <= 65_536:
        change = np.flatnonzero(differs) + 1
        starts = np.r_[0, change]
        if len(np.unique(tag_id[starts])) == len(starts):  # one contiguous block per tag
            stops = np.r_[change, n]
            return [(int(tag_id[a]), t_ns[a:b], values[a:b], slice(int(a), int(b))) for a, b in zip(starts, stops)]
    first_repeat = tag_id[1 : min(n, 65_537)] == tag_id[0]
    k = int(np.argmax(first_repeat)) + 1 if first_repeat.any() else n
    if n % k == 0 and len(np.unique(tag_id[:k])) == k:
        t_cols, v_cols, interleaved = _deinterleave(tag_id, t_ns, values, k)
        if interleaved:
            return [(int(tag_id[j]), t_cols[j], v_cols[j], slice(j, n, k)) for j in range(k)]
    order = np.argsort(tag_id, kind="stable")
    sorted_ids = tag_id[order]
    bounds = np.r_[0, np.flatnonzero(sorted_ids[1:] != sorted_ids[:-1]) + 1, n]
    return [(int(sorted_ids[a]), t_ns[order[a:b]], values[order[a:b]], order[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]


def tags_by_column(config: PlantConfig, valve_id: str) -> dict[str, str]:
    """Lake column → historian tag of one valve."""
    v = config.valve(valve_id)
    return {SIGNAL_COLUMN[s]: t.tag for s, t in v.tags.items()}


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
    tags = tags or TagTable.from_config(config)
    export = config.export
    grid = Grid.from_export(export.sample_rate_hz, export.max_gap_s)
    samples = samples_of(df, config, tags, first_line=first_line)
    valves = check_required_signals(samples.tags_present, config)
    acc = samples.accepted
    validate_raw_rows(acc)
    counts = ExportCounts(rows_in=samples.rows_in, samples_in=samples.samples_in, quarantined=samples.quarantine.height, valves=tuple(valves))

    tag_id = acc["tag"].to_physical().to_numpy()
    t_all = acc["timestamp_utc"].to_physical().to_numpy()
    v_all = acc["value_si"].to_numpy()
    line_all = acc["line"].to_numpy()

    gridded: dict[str, dict] = {}
    gap_frames = []
    first_ns, last_ns = [], []  # of each tag's sorted samples: the accepted samples' time range
    for tid, t_tag, v_tag, sel in split_by_tag(tag_id, t_all, v_all):
        tag, valve_id, signal = tags.tags[tid], tags.valve_ids[tid], tags.signals[tid]
        series = prepare_tag(t_tag, v_tag, lambda sel=sel: line_all[sel], export.duplicate_rule, tag)
        counts.duplicates += series.duplicates
        counts.conflicts += series.conflicts
        counts.accepted += len(series.t_ns)
        first_ns.append(int(series.t_ns[0]))
        last_ns.append(int(series.t_ns[-1]))
        g = to_grid(series.t_ns, series.values, grid)
        gridded.setdefault(valve_id, {})[signal] = g
        if len(g.gap_start_ns):
            counts.gaps += len(g.gap_start_ns)
            gap_frames.append(
                pl.DataFrame(
                    {
                        "valve_id": [valve_id] * len(g.gap_start_ns),
                        "signal": [signal] * len(g.gap_start_ns),
                        "tag": [tag] * len(g.gap_start_ns),
                        "gap_start": pl.Series(g.gap_start_ns // 1000).cast(pl.Datetime("us", "UTC")),
                        "gap_end": pl.Series(g.gap_end_ns // 1000).cast(pl.Datetime("us", "UTC")),
                        "duration_s": (g.gap_end_ns - g.gap_start_ns) / 1e9,
                    },
                    schema=GAP_COLUMNS,
                )
            )

    if first_ns:
        counts.time_start, counts.time_end = pl.Series([min(first_ns), max(last_ns)], dtype=pl.Int64).cast(acc.schema["timestamp_utc"]).to_list()

    frames = []
    for valve_id in valves:
        signals = gridded.get(valve_id, {})
        if not all(s in signals for s in REQUIRED_SIGNALS):
            continue  # every sample of a required signal was quarantined: no lake rows
        frames.append(assemble_valve(valve_id, signals))
        counts.rows_out += frames[-1].height
    if frames:  # every partition, in one pass (one pandera call per partition costs ~5× more)
        validate_sensor_frame(pl.concat(frames), {v: tags_by_column(config, v) for v in valves})
    partitions = [Partition(f["valve_id"][0], day, part) for f in frames for day, part in split_days(f)]
    gaps = pl.concat(gap_frames) if gap_frames else pl.DataFrame(schema=GAP_COLUMNS)
    return ExportResult(partitions, samples.quarantine, gaps, counts)

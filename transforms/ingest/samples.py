"""An export frame (long or wide, as read) → accepted samples in SI, and the quarantined rest.

A *sample* is one value of one tag at one time. A long export has one sample per row; a wide
export one per non-empty tag cell. Each sample is either accepted (timestamp in UTC ns, value
converted to SI) or quarantined with a reason:

============== ======================================================================
reason         when
============== ======================================================================
bad_quality    the quality column is configured and the row's code is not in
               ``export.good_quality``
missing_tag    a long export's row without a tag
missing_value  a long export's row without a value (an empty wide cell is no sample)
non_numeric    the value is text that is no number, e.g. PI digital states ``I/O Timeout``,
               ``Bad Input``, ``Shutdown``
non_finite     NaN or ±inf
============== ======================================================================

Refused outright (:class:`IngestError`): a missing column, a tag that is not in the plant
configuration, a row without a readable timestamp, a local time that does not exist, and a valve
of the export that lacks one of its required signals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import polars as pl

from schemas.fields import REQUIRED_SIGNALS
from schemas.plant_config import ExportSpec, PlantConfig
from transforms.ingest.errors import IngestError
from transforms.ingest.timestamps import UTC_NS, parse_timestamps

QUARANTINE_COLUMNS = ("line", "tag", "timestamp_raw", "value_raw", "quality", "reason")
"""Columns of a file's quarantine frame (the flows add file, hash, run and time)."""


@dataclass(frozen=True)
class TagTable:
    """The plant's historian tags with their valve, signal and SI factor, indexed by tag id."""

    tags: tuple[str, ...]
    valve_ids: tuple[str, ...]
    signals: tuple[str, ...]
    factors: np.ndarray

    @classmethod
    def from_config(cls, config: PlantConfig) -> TagTable:
        rows = [(t.tag, v.id, s, v.si_factor(s)) for v in config.valves for s, t in v.tags.items()]
        tags, valves, signals, factors = zip(*rows)
        return cls(tags, valves, signals, np.asarray(factors, dtype=np.float64))

    @property
    def ids(self) -> dict[str, int]:
        return {t: i for i, t in enumerate(self.tags)}


@dataclass
class Samples:
    """What one export holds, before it is put on the lake's grid."""

    accepted: pl.DataFrame
    """``line, tag, tag_id, timestamp_utc (ns, UTC), value_si``, file order."""
    quarantine: pl.DataFrame
    """``line, tag, timestamp_raw, value_raw, quality, reason`` (:data:`QUARANTINE_COLUMNS`)."""
    rows_in: int
    """Data rows of the file (blank lines not counted)."""
    samples_in: int
    """Samples of the file: accepted + quarantined."""
    tags_present: frozenset[str]
    """Tags that occur in the file (as a value of the tag column or as a column)."""


def _require_columns(df: pl.DataFrame, wanted: dict[str, str]) -> None:
    for key, name in wanted.items():
        if name not in df.columns:
            found = ", ".join(repr(c) for c in df.columns[:12])
            raise IngestError(f"missing column {name!r} (export.{key}); the file's columns are {found}")


def _value_checks(col: pl.Series, decimal: str) -> tuple[pl.Series, pl.Series, pl.Series, pl.Series]:
    """Numeric values and three masks: missing, non-numeric, non-finite."""
    if col.dtype == pl.Null:
        col = col.cast(pl.Float64)
    if col.dtype.is_numeric() or col.dtype == pl.Boolean:
        values = col.cast(pl.Float64)
        missing = values.is_null()
        non_numeric = pl.Series(np.zeros(len(col), dtype=bool))
    else:
        text = col.cast(pl.String).str.strip_chars()
        if decimal == ",":
            text = text.str.replace(",", ".", literal=True)
        values = text.cast(pl.Float64, strict=False)
        missing = text.is_null() | (text.str.len_bytes() == 0)
        non_numeric = values.is_null() & ~missing
    non_finite = ~values.is_finite().fill_null(True)
    return values, missing, non_numeric, non_finite


def _raw_text(col: pl.Series) -> pl.Series:
    return col.cast(pl.String) if col.dtype != pl.String else col


def _quarantine_frame(
    lines: pl.Series, tag: pl.Series, ts_raw: pl.Series, value_raw: pl.Series, quality: pl.Series | None, reason: pl.Series
) -> pl.DataFrame:
    n = len(lines)
    return pl.DataFrame(
        {
            "line": lines.cast(pl.Int64),
            "tag": tag.cast(pl.String),
            "timestamp_raw": _raw_text(ts_raw),
            "value_raw": _raw_text(value_raw),
            "quality": pl.Series([None] * n, dtype=pl.String) if quality is None else _raw_text(quality),
            "reason": reason,
        }
    )


def empty_quarantine() -> pl.DataFrame:
    return pl.DataFrame(schema={c: (pl.Int64 if c == "line" else pl.String) for c in QUARANTINE_COLUMNS})


def _reason(missing_tag, bad_quality, missing, non_numeric, non_finite) -> pl.Expr:
    expr = pl.when(pl.lit(missing_tag)).then(pl.lit("missing_tag")) if missing_tag is not None else None
    for mask, name in ((bad_quality, "bad_quality"), (missing, "missing_value"), (non_numeric, "non_numeric"), (non_finite, "non_finite")):
        if mask is None:
            continue
        expr = pl.when(pl.lit(mask)).then(pl.lit(name)) if expr is None else expr.when(pl.lit(mask)).then(pl.lit(name))
    return expr.otherwise(pl.lit(None, dtype=pl.String))


def _drop_blank(df: pl.DataFrame, first_line: int) -> tuple[pl.DataFrame, pl.Series]:
    """Drop all-null rows (blank lines); the line number of every remaining row."""
    lines = pl.int_range(first_line, first_line + df.height, dtype=pl.Int64, eager=True)
    if df.width == 0 or df.height == 0:
        return df, lines
    blank = df.select(pl.all_horizontal(pl.all().is_null())).to_series()
    if blank.any():
        keep = ~blank
        return df.filter(keep), lines.filter(keep)
    return df, lines


def long_samples(df: pl.DataFrame, export: ExportSpec, timezone: str, tags: TagTable, *, first_line: int = 2) -> Samples:
    """Samples of a long export: one row per tag and time.

    Parameters
    ----------
    df : DataFrame
        The file as read, in file order; a blank line may appear as an all-null row. Extra
        columns are ignored.
    export : ExportSpec
        Column names, timestamp format, quality codes, decimal mark.
    timezone : str
        ``plant.timezone`` for timestamps without an offset.
    tags : TagTable
        The plant's tags.
    first_line : int
        Line number of the frame's first row (2 below a CSV header, 1 for Parquet rows).
    """
    wanted = {"timestamp_column": export.timestamp_column, "tag_column": export.tag_column, "value_column": export.value_column}
    if export.quality_column:
        wanted["quality_column"] = export.quality_column
    _require_columns(df, wanted)
    df, lines = _drop_blank(df.select(list(wanted.values())), first_line)
    n = df.height
    tag_s = df[export.tag_column].cast(pl.String)
    tag_id = tag_s.replace_strict(tags.ids, default=None, return_dtype=pl.Int32)
    unknown = tag_id.is_null() & tag_s.is_not_null()
    if unknown.any():
        i = int(unknown.arg_true()[0])
        raise IngestError(f"unknown tag {tag_s[i]!r}: no valve of the plant configuration has it", line=int(lines[i]))
    ts_raw = df[export.timestamp_column]
    ts = parse_timestamps(ts_raw, export.timestamp_format, timezone, groups=tag_id, lines=lines, tags=tag_s)
    if ts.null_count():
        i = int(ts.is_null().arg_true()[0])
        raise IngestError("missing timestamp", line=int(lines[i]), tag=tag_s[i])
    values, missing, non_numeric, non_finite = _value_checks(df[export.value_column], export.decimal)
    missing_tag = tag_s.is_null()
    bad_quality = None
    if export.quality_column:
        bad_quality = ~df[export.quality_column].cast(pl.String).is_in(list(export.good_quality)).fill_null(False)
    masks = (missing_tag, bad_quality, missing, non_numeric, non_finite)
    rejected = pl.select(pl.any_horizontal([pl.lit(m) for m in masks if m is not None])).to_series()
    tags_present = frozenset(tag_s.drop_nulls().unique().to_list())
    if rejected.any():
        sub = rejected.arg_true()
        reason = pl.select(_reason(*(None if m is None else m.gather(sub) for m in masks))).to_series()
        quarantine = _quarantine_frame(
            lines.gather(sub),
            tag_s.gather(sub),
            ts_raw.gather(sub),
            df[export.value_column].gather(sub),
            df[export.quality_column].gather(sub) if export.quality_column else None,
            reason,
        )
        ok = ~rejected
        lines, tag_s, tag_id, ts, values = lines.filter(ok), tag_s.filter(ok), tag_id.filter(ok), ts.filter(ok), values.filter(ok)
    else:
        quarantine = empty_quarantine()
    accepted = _accepted(lines, tag_s, tag_id, ts, values, tags)
    return Samples(accepted, quarantine, n, n, tags_present)


def _accepted(lines: pl.Series, tag_s: pl.Series, tag_id: pl.Series, ts: pl.Series, values: pl.Series, tags: TagTable) -> pl.DataFrame:
    value_si = values.to_numpy() * tags.factors[tag_id.to_numpy()] if len(tag_id) else np.zeros(0)
    return pl.DataFrame(
        {
            "line": lines.cast(pl.Int64),
            "tag": tag_s.cast(pl.String),
            "tag_id": tag_id.cast(pl.Int32),
            "timestamp_utc": ts.cast(UTC_NS),
            "value_si": pl.Series(value_si, dtype=pl.Float64),
        }
    )


def _is_placeholder(df: pl.DataFrame, name: str) -> bool:
    """An unnamed column that a trailing separator creates and that holds nothing."""
    return (name == "" or name.startswith("_duplicated_")) and df[name].null_count() == df.height


def wide_samples(df: pl.DataFrame, export: ExportSpec, timezone: str, tags: TagTable, *, first_line: int = 2) -> Samples:
    """Samples of a wide export: a time column (and optionally a quality column) and a column per tag.

    An empty cell is no sample. A row whose quality code is bad quarantines every sample in it.
    Parameters as :func:`long_samples`.
    """
    wanted = {"timestamp_column": export.timestamp_column}
    if export.quality_column:
        wanted["quality_column"] = export.quality_column
    _require_columns(df, wanted)
    tag_columns = [c for c in df.columns if c not in wanted.values() and not _is_placeholder(df, c)]
    ids = tags.ids
    for c in tag_columns:
        if c not in ids:
            raise IngestError(f"unknown tag {c!r} (column {df.columns.index(c) + 1}): no valve of the plant configuration has it")
    df, lines = _drop_blank(df.select([*wanted.values(), *tag_columns]), first_line)
    n = df.height
    ts_raw = df[export.timestamp_column]
    ts = parse_timestamps(ts_raw, export.timestamp_format, timezone, lines=lines)
    if ts.null_count():
        i = int(ts.is_null().arg_true()[0])
        raise IngestError("missing timestamp", line=int(lines[i]))
    bad_quality = None
    if export.quality_column:
        bad_quality = ~df[export.quality_column].cast(pl.String).is_in(list(export.good_quality)).fill_null(False)
    accepted, quarantined = [], []
    samples_in = 0
    present_tags = []
    for c in tag_columns:
        values, missing, non_numeric, non_finite = _value_checks(df[c], export.decimal)
        present = ~missing
        n_present = int(present.sum())
        if n_present == 0:
            continue
        present_tags.append(c)
        samples_in += n_present
        masks = (None, None if bad_quality is None else bad_quality & present, None, non_numeric, non_finite)
        rejected = pl.select(pl.any_horizontal([pl.lit(m) for m in masks if m is not None])).to_series()
        if rejected.any():
            sub = rejected.arg_true()
            quarantined.append(
                _quarantine_frame(
                    lines.gather(sub),
                    pl.Series([c] * len(sub), dtype=pl.String),
                    ts_raw.gather(sub),
                    df[c].gather(sub),
                    df[export.quality_column].gather(sub) if export.quality_column else None,
                    pl.select(_reason(*(None if m is None else m.gather(sub) for m in masks))).to_series(),
                )
            )
        keep = present & ~rejected
        k = int(keep.sum())
        tid = ids[c]
        accepted.append(
            _accepted(
                lines.filter(keep) if k < n else lines,
                pl.Series([c], dtype=pl.String).gather(np.zeros(k, dtype=np.int64)),
                pl.Series(np.full(k, tid, dtype=np.int32)),
                ts.filter(keep) if k < n else ts,
                values.filter(keep) if k < n else values,
                tags,
            )
        )
    present_all = frozenset(tag_columns)
    acc = pl.concat(accepted) if accepted else _accepted(*(pl.Series([], dtype=d) for d in (pl.Int64, pl.String, pl.Int32, UTC_NS, pl.Float64)), tags)
    quarantine = pl.concat(quarantined) if quarantined else empty_quarantine()
    return Samples(acc, quarantine, n, samples_in, present_all)


def samples_of(df: pl.DataFrame, config: PlantConfig, tags: TagTable | None = None, *, first_line: int = 2) -> Samples:
    """Samples of an export in the configured layout (``export.layout``)."""
    tags = tags or TagTable.from_config(config)
    reader = long_samples if config.export.layout == "long" else wide_samples
    return reader(df, config.export, config.timezone, tags, first_line=first_line)


def check_required_signals(tags_present: frozenset[str], config: PlantConfig) -> list[str]:
    """The valves an export covers; refuses one that lacks a required signal.

    A valve is covered when any of its tags occurs in the export; it must then have every
    required signal (``x_ref`` is optional).
    """
    covered = []
    for v in config.valves:
        have = {s for s, t in v.tags.items() if t.tag in tags_present}
        if not have:
            continue
        for s in REQUIRED_SIGNALS:
            if s not in have:
                raise IngestError(f"valve {v.id}: required signal {s} (tag {v.tags[s].tag}) is missing from the export", tag=v.tags[s].tag)
        covered.append(v.id)
    return covered

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

import numba
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
    def enum(self) -> pl.Enum:
        """The tags as a polars Enum: its physical code is the tag id."""
        return pl.Enum(list(self.tags))

    @property
    def ids(self) -> dict[str, int]:
        return {t: i for i, t in enumerate(self.tags)}


@dataclass
class Samples:
    """What one export holds, before it is put on the lake's grid."""

    accepted: pl.DataFrame
    """``line, tag (Enum of the plant's tags), timestamp_utc (ns, UTC), value_si``, file order."""
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


def _value_checks(col: pl.Series, decimal: str) -> tuple[pl.Series, pl.Series | None, pl.Series | None, pl.Series | None]:
    """Numeric values and three masks: missing, non-numeric, non-finite (None: no such value)."""
    if col.dtype == pl.Null:
        col = col.cast(pl.Float64)
    if col.dtype.is_numeric() or col.dtype == pl.Boolean:
        values = col.cast(pl.Float64)
        missing = values.is_null() if values.null_count() else None
        non_numeric = None
    else:
        text = col.cast(pl.String).str.strip_chars()
        if decimal == ",":
            text = text.str.replace(",", ".", literal=True)
        values = text.cast(pl.Float64, strict=False)
        missing = text.is_null() | (text.str.len_bytes() == 0)
        non_numeric = values.is_null() & ~missing
    non_finite = ~values.is_finite().fill_null(True)
    if not non_finite.any():
        non_finite = None
    return values, missing, non_numeric, non_finite


def _text(col: pl.Series) -> pl.Series:
    return col if col.dtype == pl.String else col.cast(pl.String)


def _bad_quality(col: pl.Series, good: tuple[str, ...]) -> pl.Series | None:
    """Rows whose quality code is not one of ``export.good_quality`` (a missing code is bad);
    None when no row is bad."""
    if isinstance(col.dtype, pl.Enum):  # judged per code, not per row
        good_codes = [i for i, c in enumerate(col.dtype.categories.to_list()) if c in good]
        if len(good_codes) == len(col.dtype.categories) and not col.null_count():
            return None
        ok = col.to_physical().is_in(good_codes)
    elif col.dtype == pl.String and len(good) == 1:
        ok = col == good[0]  # one good code (the usual case): a comparison, no hashing
    elif isinstance(col.dtype, pl.Categorical) or col.dtype == pl.String:
        ok = col.is_in(list(good))
    else:
        ok = col.cast(pl.String).is_in(list(good))
    return ~ok.fill_null(False)


def _quarantine_frame(
    lines: pl.Series, tag: pl.Series, ts_raw: pl.Series, value_raw: pl.Series, quality: pl.Series | None, reason: pl.Series
) -> pl.DataFrame:
    n = len(lines)
    return pl.DataFrame(
        {
            "line": lines.cast(pl.Int64),
            "tag": _text(tag),
            "timestamp_raw": _text(ts_raw),
            "value_raw": _text(value_raw),
            "quality": pl.repeat(None, n, dtype=pl.String, eager=True) if quality is None else _text(quality),
            "reason": reason,
        }
    )


def empty_quarantine() -> pl.DataFrame:
    return pl.DataFrame(schema={c: (pl.Int64 if c == "line" else pl.String) for c in QUARANTINE_COLUMNS})


def _reason(missing_tag, bad_quality, missing, non_numeric, non_finite) -> pl.Expr:
    """The first reason that applies, in the order of the table in the module doc."""
    expr = None
    for mask, name in ((missing_tag, "missing_tag"), (bad_quality, "bad_quality"), (missing, "missing_value"), (non_numeric, "non_numeric"), (non_finite, "non_finite")):
        if mask is None:
            continue
        expr = pl.when(pl.lit(mask)).then(pl.lit(name)) if expr is None else expr.when(pl.lit(mask)).then(pl.lit(name))
    return expr.otherwise(pl.lit(None, dtype=pl.String))


def _any(masks) -> pl.Series | None:
    used = [m for m in masks if m is not None]
    if len(used) == 1:
        return used[0]
    return pl.select(pl.any_horizontal([pl.lit(m) for m in used])).to_series() if used else None


def _drop_blank(df: pl.DataFrame, first_line: int) -> tuple[pl.DataFrame, pl.Series]:
    """Drop all-null rows (blank lines); the line number of every remaining row."""
    lines = pl.int_range(first_line, first_line + df.height, dtype=pl.Int64, eager=True)
    if df.width == 0 or df.height == 0 or not any(df[c].null_count() for c in df.columns):
        return df, lines
    blank = df.select(pl.all_horizontal(pl.all().is_null())).to_series()
    if blank.any():
        keep = ~blank
        return df.filter(keep), lines.filter(keep)
    return df, lines


def _tag_enum(col: pl.Series, tags: TagTable) -> pl.Series:
    """The tag column as an Enum of the plant's tags (null for a missing or unknown tag)."""
    if isinstance(col.dtype, pl.Enum) and tuple(col.dtype.categories.to_list()) == tags.tags:
        return col
    return _text(col).cast(tags.enum, strict=False)


@numba.njit(cache=True, nogil=True)
def _to_si(values: np.ndarray, tag_id: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """``values * factors[tag_id]`` in one pass (numpy's gather and multiply take ~3× as long)."""
    out = np.empty(len(values))
    for i in range(len(values)):
        out[i] = values[i] * factors[tag_id[i]]
    return out


@numba.njit(cache=True, nogil=True)
def _code_counts(codes: np.ndarray, n: int) -> np.ndarray:
    """How often each of the codes ``0 … n-1`` occurs (``np.bincount`` first widens them to int64)."""
    counts = np.zeros(n, dtype=np.int64)
    for c in codes:
        counts[c] += 1
    return counts


def _accepted(lines: pl.Series, tag: pl.Series, ts: pl.Series, values: pl.Series, tags: TagTable) -> pl.DataFrame:
    value_si = _to_si(values.to_numpy(), tag.to_physical().to_numpy(), tags.factors)
    return pl.DataFrame(
        {
            "line": lines.cast(pl.Int64),
            "tag": tag,
            "timestamp_utc": ts.cast(UTC_NS),
            "value_si": pl.Series(value_si, dtype=pl.Float64),
        }
    )


def _empty_accepted(tags: TagTable) -> pl.DataFrame:
    return pl.DataFrame(schema={"line": pl.Int64, "tag": tags.enum, "timestamp_utc": UTC_NS, "value_si": pl.Float64})


def long_samples(df: pl.DataFrame, export: ExportSpec, timezone: str, tags: TagTable, *, first_line: int = 2) -> Samples:
    """Samples of a long export: one row per tag and time.

    Parameters
    ----------
    df : DataFrame
        The file as read, in file order; a blank line may appear as an all-null row. Extra
        columns are ignored. The tag column may be text or already an Enum of the plant's tags.
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
    tag_raw = df[export.tag_column]
    tag = _tag_enum(tag_raw, tags)
    missing_tag = None
    if tag.null_count():
        missing_tag = tag_raw.is_null() | (_text(tag_raw).str.strip_chars().str.len_bytes() == 0)
        unknown = tag.is_null() & ~missing_tag
        if unknown.any():
            i = int(unknown.arg_true()[0])
            raise IngestError(f"unknown tag {tag_raw[i]!r}: no valve of the plant configuration has it", line=int(lines[i]))
        if not missing_tag.any():
            missing_tag = None
    tag_id = tag.to_physical()
    ts_raw = df[export.timestamp_column]
    ts = parse_timestamps(ts_raw, export.timestamp_format, timezone, groups=tag_id, lines=lines, tags=tag)
    if ts.null_count():
        i = int(ts.is_null().arg_true()[0])
        raise IngestError("missing timestamp", line=int(lines[i]), tag=tag[i])
    values, missing, non_numeric, non_finite = _value_checks(df[export.value_column], export.decimal)
    bad_quality = _bad_quality(df[export.quality_column], export.good_quality) if export.quality_column else None
    masks = (missing_tag, bad_quality, missing, non_numeric, non_finite)
    rejected = _any(masks)
    counts = _code_counts(tag_id.drop_nulls().to_numpy(), len(tags.tags))
    tags_present = frozenset(tags.tags[i] for i in np.flatnonzero(counts))
    if rejected is not None and rejected.any():
        sub = rejected.arg_true()
        quarantine = _quarantine_frame(
            lines.gather(sub),
            tag_raw.gather(sub),
            ts_raw.gather(sub),
            df[export.value_column].gather(sub),
            df[export.quality_column].gather(sub) if export.quality_column else None,
            pl.select(_reason(*(None if m is None else m.gather(sub) for m in masks))).to_series(),
        )
        ok = ~rejected
        lines, tag, ts, values = lines.filter(ok), tag.filter(ok), ts.filter(ok), values.filter(ok)
    else:
        quarantine = empty_quarantine()
    return Samples(_accepted(lines, tag, ts, values, tags), quarantine, n, n, tags_present)


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
    bad_quality = _bad_quality(df[export.quality_column], export.good_quality) if export.quality_column else None
    accepted, quarantined = [], []
    samples_in = 0
    for c in tag_columns:
        values, missing, non_numeric, non_finite = _value_checks(df[c], export.decimal)
        present = None if missing is None else ~missing
        n_present = n if present is None else int(present.sum())
        if n_present == 0:
            continue
        samples_in += n_present
        bad_q = None if bad_quality is None else (bad_quality if present is None else bad_quality & present)
        masks = (None, bad_q, None, non_numeric, non_finite)
        rejected = _any(masks)
        if rejected is not None and rejected.any():
            sub = rejected.arg_true()
            quarantined.append(
                _quarantine_frame(
                    lines.gather(sub),
                    pl.repeat(c, len(sub), dtype=pl.String, eager=True),
                    ts_raw.gather(sub),
                    df[c].gather(sub),
                    df[export.quality_column].gather(sub) if export.quality_column else None,
                    pl.select(_reason(*(None if m is None else m.gather(sub) for m in masks))).to_series(),
                )
            )
        if rejected is None:
            keep = present
        else:
            keep = ~rejected if present is None else present & ~rejected
        k = n if keep is None else int(keep.sum())
        sel = (lambda s: s) if k == n else (lambda s: s.filter(keep))
        accepted.append(_accepted(sel(lines), pl.repeat(c, k, dtype=tags.enum, eager=True), sel(ts), sel(values), tags))
    acc = pl.concat(accepted) if accepted else _empty_accepted(tags)
    quarantine = pl.concat(quarantined) if quarantined else empty_quarantine()
    return Samples(acc, quarantine, n, samples_in, frozenset(tag_columns))


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

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
bad_timestamp  the timestamp is missing or not in ``export.timestamp_format``
clock_step     a wide row at or after a backward step of the file's clock
               (``transforms.ingest.clock``)
implausible_time
               the time is later than the ingest's time + :data:`FUTURE_TOLERANCE_NS`
               or before the ``commissioned`` time of the tag's valve
out_of_range   the value in SI lies outside the physical range of its lake column
               (``schemas.fields.SENSOR_FIELDS``), e.g. a transmitter's 1e308
field_count    a text row whose field count is not the header's: every sample of the row
               (which cell holds which tag is not known), before any other check
truncated      every sample of a text file's last line when it has no line end (the file
               was cut inside it)
============== ======================================================================

``bad_timestamp``, ``implausible_time``, ``out_of_range`` and ``field_count`` are *faults*: counted
per tag (:attr:`Samples.faults`), and a file in which one of them exceeds ``export.max_bad_share``
of a tag's samples is refused (``transforms.ingest.stream``).

A tag no valve of the plant has (a row's tag in the long layout, a column in the wide one) is
read past and counted (:attr:`Samples.other_tags`) under ``export.other_tags = "ignore"``, and
refuses the file under ``"error"``.

Refused outright (:class:`IngestError`): a missing column, an other tag under ``"error"``, a local
time that does not exist, and a valve of the export that lacks one of its required signals.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numba
import numpy as np
import polars as pl

from schemas.fields import FAULT_REASONS, REQUIRED_SIGNALS, SENSOR_FIELDS, SIGNAL_COLUMN
from schemas.plant_config import ExportSpec, PlantConfig
from transforms.arrays import read_only
from transforms.ingest.clock import ClockSteps
from transforms.ingest.errors import IngestError
from transforms.ingest.text_rows import FIELD_COUNT as TEXT_FIELD_COUNT
from transforms.ingest.text_rows import ROW_FAULT_COLUMN
from transforms.ingest.timestamps import UTC_NS, parse_timestamps, unreadable_timestamp

QUARANTINE_COLUMNS = ("line", "tag", "timestamp_raw", "value_raw", "quality", "reason")
"""Columns of a file's quarantine frame (the flows add file, hash, run and time)."""

FUTURE_TOLERANCE_NS = 86_400 * 10**9
"""A sample later than the ingest's time plus this is ``implausible_time`` (one day: more than any
time-zone offset and any drift of a recorder's clock that is merely not synchronised). [ns]"""

BAD_TIMESTAMP, IMPLAUSIBLE_TIME, OUT_OF_RANGE, FIELD_COUNT = (FAULT_REASONS.index(r) for r in ("bad_timestamp", "implausible_time", "out_of_range", "field_count"))
_LIMITS = {f.name: f for f in SENSOR_FIELDS}


@dataclass(frozen=True)
class TagTable:
    """The plant's historian tags with their valve, signal and SI factor, indexed by tag id."""

    tags: tuple[str, ...]
    valve_ids: tuple[str, ...]
    signals: tuple[str, ...]
    factors: np.ndarray
    lo: np.ndarray
    """Lowest plausible value in SI: the ``ge`` of the signal's lake column."""
    hi: np.ndarray
    """Highest plausible value in SI: the ``le`` of the signal's lake column."""
    commissioned_ns: np.ndarray
    """The valve's ``commissioned`` time (UTC ns): earlier samples are implausible."""

    @classmethod
    def from_config(cls, config: PlantConfig) -> TagTable:
        rows = [(t.tag, v.id, s, v.si_factor(s), _LIMITS[SIGNAL_COLUMN[s]], v.commissioned) for v in config.valves for s, t in v.tags.items()]
        tags, valves, signals, factors, limits, commissioned = zip(*rows)
        lo = np.array([-np.inf if f.ge is None else f.ge for f in limits])
        hi = np.array([np.inf if f.le is None else f.le for f in limits])
        since = np.array([round(c.timestamp() * 1e6) * 1000 for c in commissioned], dtype=np.int64)
        return cls(tags, valves, signals, np.asarray(factors, dtype=np.float64), lo, hi, since)

    def check_name(self, tid: int, value_si: float) -> str:
        """The range check of the tag's lake column that ``value_si`` fails, named as the
        sensor-frame schema names it (``ps_pa <= 6e+07 Pa``)."""
        f = _LIMITS[SIGNAL_COLUMN[self.signals[tid]]]
        side = f"<= {f.le:g}" if value_si > self.hi[tid] or value_si != value_si else f">= {f.ge:g}"
        return f"{f.name} {side} {f.unit}".rstrip()

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
    tag_samples: np.ndarray
    """Samples per tag id, quarantined ones included (the base of a fault's share)."""
    faults: np.ndarray
    """Quarantined samples per tag id (rows) and fault (columns, :data:`FAULT_REASONS`)."""
    first_faults: dict[tuple[int, int], str]
    """(tag id, fault) → what is wrong with its first sample of the frame, naming line and tag."""
    other_tags: dict[str, int]
    """Tags (columns) no valve has → their samples, in the order of the frame (read past)."""
    truncated: bool = False
    """The frame ends with a text file's last line that has no line end (a cut file)."""
    blocks: tuple[int, ...] | None = None
    """Wide layout: ``accepted`` is one block of rows per tag, of these heights, in order (each
    block's columns are read without a copy); None: rows in file order (long)."""


def refuse_repeated_columns(names: list[str], *, line: int | None = None) -> None:
    """Refuse a header (``line``: its line in a text file) that names a column twice: which of the
    two holds the tag cannot be told (a decoder would take the first). Unnamed columns (a
    trailing separator) are no names."""
    seen: dict[str, int] = {}
    for j, name in enumerate(names):
        key = name.strip()
        if not key:
            continue
        if key in seen:
            raise IngestError(f"column {key!r} is named twice, columns {seen[key] + 1} and {j + 1}; expected one column per tag", line=line)
        seen[key] = j


def _require_columns(df: pl.DataFrame, wanted: dict[str, str]) -> None:
    for key, name in wanted.items():
        if name not in df.columns:
            found = ", ".join(repr(c) for c in df.columns[:12] if c != ROW_FAULT_COLUMN)
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
    finite = values.is_finite()
    non_finite = None if finite.all() else ~finite.fill_null(True)  # (all() passes nulls)
    return values, missing, non_numeric, non_finite


def _text(col: pl.Series) -> pl.Series:
    return col if col.dtype == pl.String else col.cast(pl.String)


def bad_quality(col: pl.Series, good: tuple[str, ...]) -> pl.Series | None:
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


_MASK_REASONS = ("missing_tag", "bad_timestamp", "clock_step", "bad_quality", "missing_value", "non_numeric", "non_finite")


def _reason(*masks) -> pl.Expr:
    """The first reason that applies, in the order of :data:`_MASK_REASONS` (one mask each, None
    where none applies)."""
    expr = None
    for mask, name in zip(masks, _MASK_REASONS):
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


def _take_broken(df: pl.DataFrame, lines: pl.Series) -> tuple[pl.DataFrame, pl.Series, pl.DataFrame | None, pl.Series | None]:
    """Rows the text reader marked (:data:`ROW_FAULT_COLUMN`: a field count that is not the
    header's, a cut last line) taken out: ``(the other rows, their lines, the marked rows, their
    lines)``; the marked ones are quarantined whole, before any other check."""
    if ROW_FAULT_COLUMN not in df.columns:
        return df, lines, None, None
    bad = df[ROW_FAULT_COLUMN].is_not_null()
    return df.filter(~bad).drop(ROW_FAULT_COLUMN), lines.filter(~bad), df.filter(bad), lines.filter(bad)


def _and_marks(df: pl.DataFrame, columns) -> list[str]:
    """``columns`` and, when the text reader added it, :data:`ROW_FAULT_COLUMN` (a marked row is
    not blank, whatever its cells)."""
    return [*columns, *([ROW_FAULT_COLUMN] if ROW_FAULT_COLUMN in df.columns else [])]


def _cut(broken: pl.DataFrame | None) -> bool:
    """Whether the marked rows hold a cut last line."""
    return broken is not None and bool(broken[ROW_FAULT_COLUMN].eq("truncated").any())


def _present(col: pl.Series) -> pl.Series:
    """Cells that hold something (a wide export's empty cell is no sample)."""
    return col.is_not_null() if col.dtype != pl.String else col.str.strip_chars().str.len_bytes().fill_null(0) > 0


def _tag_enum(col: pl.Series, tags: TagTable) -> pl.Series:
    """The tag column as an Enum of the plant's tags (null for a missing or unknown tag)."""
    if isinstance(col.dtype, pl.Enum) and tuple(col.dtype.categories.to_list()) == tags.tags:
        return col
    return _text(col).cast(tags.enum, strict=False)


@numba.njit(cache=True, nogil=True)
def _to_si(values, tag_id, t_ns, factors, lo, hi, t_lo, t_hi):
    """``values * factors[tag_id]`` and each sample's fault in one pass (numpy's gather and
    multiply alone take ~3× as long): 0 none, 1 ``implausible_time`` (before ``t_lo[tag]`` or
    after ``t_hi``; an empty ``t_ns``: no time is checked), 2 ``out_of_range`` (outside
    ``[lo[tag], hi[tag]]`` in SI). A ``tag_id`` of length 1 is the tag of every sample (a wide
    column). Returns (SI values, faults, how many)."""
    n = len(values)
    out = np.empty(n)
    fault = np.zeros(n, dtype=np.int8)
    bad = 0
    one = len(tag_id) == 1
    timed = len(t_ns) == n
    for i in range(n):
        k = tag_id[0] if one else tag_id[i]
        v = values[i] * factors[k]
        out[i] = v
        if timed and (t_ns[i] < t_lo[k] or t_ns[i] > t_hi):
            fault[i] = 1
            bad += 1
        elif not (lo[k] <= v <= hi[k]):
            fault[i] = 2
            bad += 1
    return out, fault, bad


@numba.njit(cache=True, nogil=True)
def _code_counts(codes: np.ndarray, n: int) -> np.ndarray:
    """How often each of the codes ``0 … n-1`` occurs (``np.bincount`` first widens them to int64)."""
    counts = np.zeros(n, dtype=np.int64)
    for c in codes:
        counts[c] += 1
    return counts


def _iso(t_ns: int) -> str:
    return (datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=int(t_ns) // 1000)).isoformat().replace("+00:00", "Z")


class _Faults:
    """The faults of one frame as they are found: counts per tag and the first of each."""

    def __init__(self, tags: TagTable, now_ns: int):
        self.tags = tags
        self.t_hi = now_ns + FUTURE_TOLERANCE_NS
        self.counts = np.zeros((len(tags.tags), len(FAULT_REASONS)), dtype=np.int64)
        self.first: dict[tuple[int, int], str] = {}
        self._span: tuple[pl.Series, int, int] | None = None

    def _extent(self, ts: pl.Series, t_ns: pl.Series) -> tuple[int, int]:
        """The earliest and latest of the times ``ts`` (``t_ns``: as ns), found once for the
        columns of a wide frame that share them."""
        if self._span is None or self._span[0] is not ts:
            self._span = (ts, t_ns.min(), t_ns.max())
        return self._span[1], self._span[2]

    def bad_timestamps(self, tag_id: np.ndarray, lines: np.ndarray, raw: pl.Series, fmt: str) -> None:
        """Samples whose timestamp cannot be read (arrays of them only)."""
        np.add.at(self.counts[:, BAD_TIMESTAMP], tag_id, 1)
        ids, first = np.unique(tag_id, return_index=True)
        for tid, i in zip(ids, first):
            self.first.setdefault((int(tid), BAD_TIMESTAMP), f"line {lines[i]}: tag {self.tags.tags[tid]}: {unreadable_timestamp(raw[int(i)], fmt)}")

    def field_counts(self, tag_id: np.ndarray, lines: np.ndarray, marks: pl.Series, width: int) -> None:
        """Samples of rows marked :data:`~transforms.ingest.text_rows.FIELD_COUNT` (``marks``: the
        rows' marks; ``tag_id`` -1: no tag of the plant); a cut last line is not one."""
        hit = (marks == TEXT_FIELD_COUNT).to_numpy() & (tag_id >= 0)
        if not hit.any():
            return
        tag_id, lines = tag_id[hit], lines[hit]
        np.add.at(self.counts[:, FIELD_COUNT], tag_id, 1)
        ids, first = np.unique(tag_id, return_index=True)
        for tid, i in zip(ids, first):
            what = f"line {lines[i]}: tag {self.tags.tags[tid]}: the row does not have the header's {width} fields"
            self.first.setdefault((int(tid), FIELD_COUNT), what)

    def checked(self, lines: pl.Series, tag_id: np.ndarray, ts: pl.Series, values: pl.Series, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Values in SI, and the faults per sample (None: none) of accepted samples; ``tag_id``
        per sample, or one for all (a wide column); ``ids``: the tags of the frame. Times are
        checked sample by sample only when the frame's earliest or latest is implausible for
        one of its tags (else the times stay in polars: no copy of a chunked column)."""
        tags = self.tags
        t_ns = ts.cast(UTC_NS).to_physical()
        first, last = self._extent(ts, t_ns) if len(t_ns) else (0, 0)
        if len(t_ns) and (first < tags.commissioned_ns[ids].max() or last > self.t_hi):
            t = t_ns.to_numpy()
        else:
            t = np.zeros(0, dtype=np.int64)
        value_si, fault, bad = _to_si(read_only(values.to_numpy()), read_only(tag_id), read_only(t), tags.factors, tags.lo, tags.hi, tags.commissioned_ns, self.t_hi)
        if not bad:
            return value_si, None
        rows = np.flatnonzero(fault)
        row_tags = tag_id[rows] if len(tag_id) > 1 else np.full(len(rows), tag_id[0])
        kinds = np.where(fault[rows] == 1, IMPLAUSIBLE_TIME, OUT_OF_RANGE)
        np.add.at(self.counts, (row_tags, kinds), 1)
        if not len(t):
            t = t_ns.gather(rows).to_numpy()
            rows_t = np.arange(len(rows))
        else:
            rows_t = rows
        for (tid, kind), j in zip(*np.unique(np.c_[row_tags, kinds], axis=0, return_index=True)):
            r = rows[j]
            self.first.setdefault((int(tid), int(kind)), self._what(int(tid), int(kind), int(lines[int(r)]), int(t[rows_t[j]]), float(value_si[r])))
        return value_si, fault

    def _what(self, tid: int, kind: int, line: int, t_ns: int, value_si: float) -> str:
        tags = self.tags
        tag, valve = tags.tags[tid], tags.valve_ids[tid]
        if kind == OUT_OF_RANGE:  # as the sensor-frame schema said it before samples were checked
            column = SIGNAL_COLUMN[tags.signals[tid]]
            return f"tag {tag}: valve {valve}, column {column} at {_iso(t_ns)}: value {value_si!r} fails check {tags.check_name(tid, value_si)!r} (line {line})"
        if t_ns > self.t_hi:
            return f"line {line}: tag {tag}: time {_iso(t_ns)} is more than a day after the ingest's time {_iso((self.t_hi - FUTURE_TOLERANCE_NS) // 10**9 * 10**9)}"
        return f"line {line}: tag {tag}: time {_iso(t_ns)} is before valve {valve} was commissioned ({_iso(int(tags.commissioned_ns[tid]))})"


def _accepted(lines: pl.Series, tag: pl.Series, ts: pl.Series, value_si: np.ndarray) -> pl.DataFrame:
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


def _rows(raw: dict, sub: pl.Series, reason: pl.Series) -> pl.DataFrame:
    """Quarantine rows of the samples at positions ``sub``; ``raw``: line, tag, timestamp, value
    and quality (or None) of every sample, the tag a Series or one name for all."""
    picked = [c if c is None else pl.repeat(c, len(sub), dtype=pl.String, eager=True) if isinstance(c, str) else c.gather(sub) for c in raw.values()]
    return _quarantine_frame(*picked, reason)


def _set_aside(rejected: pl.Series | None, masks: tuple, raw: dict) -> pl.DataFrame | None:
    """The quarantine rows of the samples ``rejected`` marks, with the first reason that applies
    (``raw`` as :func:`_rows`)."""
    if rejected is None or not rejected.any():
        return None
    sub = rejected.arg_true()
    return _rows(raw, sub, pl.select(_reason(*(None if m is None else m.gather(sub) for m in masks))).to_series())


def _faulted(fault: np.ndarray, kept: pl.Series | None, raw: dict) -> pl.DataFrame:
    """The quarantine rows of the accepted samples the value/time checks fault (``kept``: the
    positions of the accepted samples among all, None: all)."""
    at = np.flatnonzero(fault)
    sub = pl.Series(at) if kept is None else kept.gather(at)
    return _rows(raw, sub, pl.Series(np.where(fault[at] == 1, "implausible_time", "out_of_range"), dtype=pl.String))


def _concat(frames: list[pl.DataFrame | None]) -> pl.DataFrame:
    used = [f for f in frames if f is not None]
    return pl.concat(used) if used else empty_quarantine()


def long_samples(df: pl.DataFrame, export: ExportSpec, timezone: str, tags: TagTable, *, first_line: int = 2, now_ns: int | None = None, origin_ns: int | None = None) -> Samples:
    """Samples of a long export: one row per tag and time.

    Parameters
    ----------
    df : DataFrame
        The file as read, in file order; a blank line may appear as an all-null row. Extra
        columns are ignored. The tag column may be text or already an Enum of the plant's tags.
    export : ExportSpec
        Column names, timestamp format, quality codes, decimal mark, ``other_tags``.
    timezone : str
        ``plant.timezone`` for timestamps without an offset.
    tags : TagTable
        The plant's tags.
    first_line : int
        Line number of the frame's first row (2 below a CSV header, 1 for Parquet rows).
    now_ns : int, optional
        The ingest's time (UTC ns) for ``implausible_time``; default: now.
    origin_ns : int, optional
        The file's start time (UTC ns), which a relative ``timestamp_format`` counts from.
    """
    wanted = {"timestamp_column": export.timestamp_column, "tag_column": export.tag_column, "value_column": export.value_column}
    if export.quality_column:
        wanted["quality_column"] = export.quality_column
    _require_columns(df, wanted)
    width = df.width - (ROW_FAULT_COLUMN in df.columns)
    faults = _Faults(tags, time.time_ns() if now_ns is None else now_ns)
    df, lines = _drop_blank(df.select(_and_marks(df, wanted.values())), first_line)
    rows_in = df.height
    df, lines, broken, broken_lines = _take_broken(df, lines)
    broken_q = None
    if broken is not None:
        q = broken[export.quality_column] if export.quality_column else None
        broken_q = _quarantine_frame(broken_lines, broken[export.tag_column], broken[export.timestamp_column], broken[export.value_column], q, broken[ROW_FAULT_COLUMN])
        broken_ids = _tag_enum(broken[export.tag_column], tags).to_physical().cast(pl.Int64).fill_null(-1).to_numpy()
        faults.field_counts(broken_ids, broken_lines.to_numpy(), broken[ROW_FAULT_COLUMN], width)
    tag_raw = df[export.tag_column]
    tag = _tag_enum(tag_raw, tags)
    missing_tag = None
    other: dict[str, int] = {}
    if tag.null_count():
        missing_tag = tag_raw.is_null() | (_text(tag_raw).str.strip_chars().str.len_bytes() == 0)
        unknown = tag.is_null() & ~missing_tag
        if unknown.any():
            if export.other_tags == "error":
                i = int(unknown.arg_true()[0])
                raise IngestError(f"unknown tag {tag_raw[i]!r}: no valve of the plant configuration has it", line=int(lines[i]))
            other = dict(_text(tag_raw.filter(unknown)).to_frame("tag").group_by("tag", maintain_order=True).len().rows())
            keep = ~unknown
            df, lines, tag_raw, tag, missing_tag = df.filter(keep), lines.filter(keep), tag_raw.filter(keep), tag.filter(keep), missing_tag.filter(keep)
        if not missing_tag.any():
            missing_tag = None
    n = df.height
    tag_id = tag.to_physical()
    ts_raw = df[export.timestamp_column]
    ts = parse_timestamps(
        ts_raw, export.timestamp_format, timezone, groups=tag_id, lines=lines, tags=tag, unreadable="null", origin_ns=origin_ns, ambiguous=export.ambiguous_time
    )
    bad_ts = None
    if ts.null_count():
        bad_ts = ts.is_null() if missing_tag is None else ts.is_null() & ~missing_tag
        if bad_ts.any():
            at = bad_ts.arg_true()
            faults.bad_timestamps(tag_id.gather(at).to_numpy(), lines.gather(at).to_numpy(), ts_raw.gather(at), export.timestamp_format)
        else:
            bad_ts = None
    values, missing, non_numeric, non_finite = _value_checks(df[export.value_column], export.decimal)
    bad_q_rows = bad_quality(df[export.quality_column], export.good_quality) if export.quality_column else None
    masks = (missing_tag, bad_ts, None, bad_q_rows, missing, non_numeric, non_finite)
    rejected = _any(masks)
    counts = _code_counts(tag_id.drop_nulls().to_numpy(), len(tags.tags))
    counts_with_broken = counts + faults.counts[:, FIELD_COUNT]  # a fault's share counts the broken rows' samples in
    tags_present = frozenset(tags.tags[i] for i in np.flatnonzero(counts_with_broken))
    raw = {"line": lines, "tag": tag_raw, "ts": ts_raw, "value": df[export.value_column], "quality": df[export.quality_column] if export.quality_column else None}
    set_aside = _set_aside(rejected, masks, raw)
    kept = None
    if set_aside is not None:
        ok = ~rejected
        kept = ok.arg_true()
        lines, tag, ts, values = lines.filter(ok), tag.filter(ok), ts.filter(ok), values.filter(ok)
    value_si, fault = faults.checked(lines, tag.to_physical().to_numpy(), ts, values, np.flatnonzero(counts))
    faulted = None
    if fault is not None:
        faulted = _faulted(fault, kept, raw)
        ok = pl.Series(fault == 0)
        lines, tag, ts, value_si = lines.filter(ok), tag.filter(ok), ts.filter(ok), value_si[fault == 0]
    n_broken = 0 if broken_q is None else broken_q.height
    return Samples(
        _accepted(lines, tag, ts, value_si), _concat([broken_q, set_aside, faulted]), rows_in, n + n_broken, tags_present, counts_with_broken, faults.counts, faults.first, other, _cut(broken)
    )


def _is_placeholder(df: pl.DataFrame, name: str) -> bool:
    """An unnamed column that a trailing separator creates and that holds nothing."""
    return (name == "" or name.startswith("_duplicated_")) and df[name].null_count() == df.height


def wide_samples(
    df: pl.DataFrame,
    export: ExportSpec,
    timezone: str,
    tags: TagTable,
    *,
    first_line: int = 2,
    now_ns: int | None = None,
    clock: ClockSteps | None = None,
    origin_ns: int | None = None,
) -> Samples:
    """Samples of a wide export: a time column (and optionally a quality column) and a column per tag.

    An empty cell is no sample. A row whose quality code is bad, or whose timestamp cannot be
    read, quarantines every sample in it, and so does a row at or after a step of the file's
    clock (``clock``, which follows the file across its batches; None: not checked).
    Other parameters as :func:`long_samples`.
    """
    wanted = {"timestamp_column": export.timestamp_column}
    if export.quality_column:
        wanted["quality_column"] = export.quality_column
    _require_columns(df, wanted)
    tag_columns = [c for c in df.columns if c not in wanted.values() and c != ROW_FAULT_COLUMN and not _is_placeholder(df, c)]
    ids = tags.ids
    other: dict[str, int] = {}
    for c in tag_columns:
        if c not in ids:
            if export.other_tags == "error":
                raise IngestError(f"unknown tag {c!r} (column {df.columns.index(c) + 1}): no valve of the plant configuration has it")
            other[c] = df.height - df[c].null_count()
    tag_columns = [c for c in tag_columns if c in ids]
    width = df.width - (ROW_FAULT_COLUMN in df.columns)
    df, lines = _drop_blank(df.select(_and_marks(df, [*wanted.values(), *tag_columns])), first_line)
    rows_in = df.height
    df, lines, broken, broken_lines = _take_broken(df, lines)
    n = df.height
    ts_raw = df[export.timestamp_column]
    ts = parse_timestamps(ts_raw, export.timestamp_format, timezone, lines=lines, unreadable="null", origin_ns=origin_ns, ambiguous=export.ambiguous_time).cast(UTC_NS)  # once, not per tag
    bad_ts = ts.is_null() if ts.null_count() else None
    after_step = None if clock is None else clock.after_step(ts.to_physical(), lines)
    faults = _Faults(tags, time.time_ns() if now_ns is None else now_ns)
    bad_q_rows = bad_quality(df[export.quality_column], export.good_quality) if export.quality_column else None
    accepted, quarantined = [], []
    samples_in = 0
    tag_samples = np.zeros(len(tags.tags), dtype=np.int64)
    if broken is not None:  # every non-empty cell of a marked row, under the tag of its column
        q = broken[export.quality_column] if export.quality_column else None
        for c in tag_columns:
            at = _present(broken[c]).arg_true()
            if len(at):
                samples_in += len(at)
                pick = lambda s: None if s is None else s.gather(at)  # noqa: E731
                tag = pl.repeat(c, len(at), dtype=pl.String, eager=True)
                quarantined.append(_quarantine_frame(pick(broken_lines), tag, pick(broken[export.timestamp_column]), pick(broken[c]), pick(q), pick(broken[ROW_FAULT_COLUMN])))
                faults.field_counts(np.full(len(at), ids[c]), pick(broken_lines).to_numpy(), pick(broken[ROW_FAULT_COLUMN]), width)
                tag_samples[ids[c]] += len(at)
    code_dtype = pl.Series(dtype=tags.enum).to_physical().to_numpy().dtype  # as a long frame's codes: one compiled kernel
    for c in tag_columns:
        values, missing, non_numeric, non_finite = _value_checks(df[c], export.decimal)
        present = None if missing is None else ~missing
        n_present = n if present is None else int(present.sum())
        if n_present == 0:
            continue
        samples_in += n_present
        tid = ids[c]
        tag_samples[tid] += n_present
        bad_q = None if bad_q_rows is None else (bad_q_rows if present is None else bad_q_rows & present)
        bad_t = None if bad_ts is None else (bad_ts if present is None else bad_ts & present)
        if bad_t is not None and bad_t.any():
            at = bad_t.arg_true()
            faults.bad_timestamps(np.full(len(at), tid), lines.gather(at).to_numpy(), ts_raw.gather(at), export.timestamp_format)
        bad_c = None if after_step is None else (after_step if present is None else after_step & present)
        masks = (None, bad_t, bad_c, bad_q, None, non_numeric, non_finite)
        rejected = _any(masks)
        raw = {
            "line": lines,
            "tag": c,
            "ts": ts_raw,
            "value": df[c],
            "quality": df[export.quality_column] if export.quality_column else None,
        }
        set_aside = _set_aside(rejected, masks, raw)
        quarantined.append(set_aside)
        if rejected is None:
            keep = present
        else:
            keep = ~rejected if present is None else present & ~rejected
        k = n if keep is None else int(keep.sum())
        sel = (lambda s: s) if k == n else (lambda s: s.filter(keep))
        tag = pl.repeat(c, k, dtype=tags.enum, eager=True)
        col_lines, col_ts = sel(lines), sel(ts)
        value_si, fault = faults.checked(col_lines, np.array([tid], dtype=code_dtype), col_ts, sel(values), np.array([tid]))
        if fault is not None:
            quarantined.append(_faulted(fault, None if keep is None else keep.arg_true(), raw))
            ok = fault == 0
            col_lines, col_ts, value_si = col_lines.filter(pl.Series(ok)), col_ts.filter(pl.Series(ok)), value_si[ok]
            tag = tag.head(len(value_si))
        accepted.append(_accepted(col_lines, tag, col_ts, value_si))
    acc = pl.concat(accepted, rechunk=False) if accepted else _empty_accepted(tags)
    blocks = tuple(a.height for a in accepted)
    return Samples(acc, _concat(quarantined), rows_in, samples_in, frozenset(tag_columns), tag_samples, faults.counts, faults.first, other, _cut(broken), blocks)


def samples_of(
    df: pl.DataFrame,
    config: PlantConfig,
    tags: TagTable | None = None,
    *,
    first_line: int = 2,
    now_ns: int | None = None,
    clock: ClockSteps | None = None,
    origin_ns: int | None = None,
) -> Samples:
    """Samples of an export in the configured layout (``export.layout``); ``clock``: the wide
    layout's clock-step check (:func:`wide_samples`); ``origin_ns``: the file's start time (UTC ns)
    for a relative ``timestamp_format``."""
    tags = tags or TagTable.from_config(config)
    if config.export.layout == "long":
        return long_samples(df, config.export, config.timezone, tags, first_line=first_line, now_ns=now_ns, origin_ns=origin_ns)
    return wide_samples(df, config.export, config.timezone, tags, first_line=first_line, now_ns=now_ns, clock=clock, origin_ns=origin_ns)


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


def tag_blocks(accepted: pl.DataFrame, blocks: tuple[int, ...]) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """A wide layout's accepted samples (:attr:`Samples.blocks`) → each tag's ``(tag id, t_ns,
    values, lines)``, each block's columns as they are (no copy of the whole frame's columns)."""
    out = []
    a = 0
    for n in blocks:
        if n:
            part = accepted.slice(a, n)
            out.append(
                (
                    int(part["tag"][:1].to_physical()[0]),
                    part["timestamp_utc"].to_physical().to_numpy(),
                    part["value_si"].to_numpy(),
                    part["line"].to_numpy(),
                )
            )
        a += n
    return out


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

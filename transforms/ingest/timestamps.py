"""Export timestamps to UTC nanoseconds: ISO-8601, epoch milliseconds, strftime patterns, local time.

``export.timestamp_format`` decides how text is read:

- ``"iso8601"``: ``2025-03-01T12:00:00.1234567Z``, ``…+01:00``, ``…+0100``, ``…+01``, a space
  instead of the ``T``, 0 to 9 fractional digits (PI writes 7). Text without an offset is local
  time in ``plant.timezone``.
- ``"epoch_ms"``: milliseconds since 1970-01-01 UTC (integer or decimal).
- any other string is a chrono/strftime pattern such as ``"%d.%m.%Y %H:%M:%S%.f"``; with
  ``%z``/``%#z``/``%:z`` it carries its offset, otherwise it is local time.
- ``"seconds"`` / ``"milliseconds"``: time since the file's start (``origin_ns``, the start time of
  the file, :func:`parse_start_time`), numbers or text with a decimal point or comma. The elapsed
  time is added to the start in UTC, so a recording across a change of the clocks stays continuous.

Parquet exports may also hold typed timestamps: zoned ones are converted to UTC, naive ones are
local time.

Local time is converted with the IANA rules of ``plant.timezone``. The autumn hour that occurs
twice is resolved by row order, per tag: within one tag's rows in file order, rows of the
repeated hour are summer time until the local time goes backwards, winter time from then on.
A local time inside the spring gap does not exist; the ingest refuses it, naming the row.

Everything stays at nanosecond resolution here; the lake's µs grid comes later (``grid``).
"""

from __future__ import annotations

import re

import numpy as np
import polars as pl
import pyarrow as pa

from transforms.ingest.errors import IngestError
from transforms.ingest.iso8601 import parse_iso_column

UTC_NS = pl.Datetime("ns", "UTC")

_OFFSET_AT_END = re.compile(r"(Z|[+-]\d\d(:?\d\d)?)$")
_ZONED_DIRECTIVES = ("%z", "%#z", "%:z", "%::z")


def _iso_formats(sample: str) -> list[tuple[str, bool]]:
    """Candidate chrono formats for ISO-8601 text, the likeliest (as ``sample`` looks) first."""
    sample = sample.strip()
    seps = [" ", "T"] if len(sample) > 10 and sample[10] == " " else ["T", " "]
    zoned_first = bool(_OFFSET_AT_END.search(sample))
    zoned = [(f"%Y-%m-%d{s}%H:%M:%S%.f%#z", True) for s in seps]
    naive = [(f"%Y-%m-%d{s}%H:%M:%S%.f", False) for s in seps]
    return zoned + naive if zoned_first else naive + zoned


RELATIVE_UNIT_NS = {"seconds": 10**9, "milliseconds": 10**6}
"""Nanoseconds per unit of a relative ``timestamp_format`` (``schemas.plant_config.RELATIVE_TIME_FORMATS``)."""

_NAME_DIRECTIVES = {
    "Y": r"\d{4}", "y": r"\d{2}", "m": r"\d{2}", "d": r"\d{2}", "H": r"\d{2}", "M": r"\d{2}", "S": r"\d{2}",
    "j": r"\d{3}", "b": r"[A-Za-z]{3}", "f": r"\d{1,9}", "3f": r"\d{3}", "6f": r"\d{6}", "9f": r"\d{9}",
    ".f": r"(?:\.\d{1,9})?", ".3f": r"\.\d{3}", ".6f": r"\.\d{6}", ".9f": r"\.\d{9}",
    "z": r"[+-]\d{4}", ":z": r"[+-]\d\d:\d\d", "#z": r"(?:Z|[+-]\d\d(?::?\d\d)?)", "%": "%",
}  # fmt: skip
"""strftime directives a start time in a file's name may use, and the text each matches."""
_DIRECTIVE = re.compile(r"%(\.?\d?f|[:#]?z|[A-Za-z%])")


def name_pattern(fmt: str) -> re.Pattern:
    """The regular expression of the text a strftime pattern writes (``"%Y%m%dT%H%M%S"`` →
    ``\\d{4}\\d{2}\\d{2}T…``), to find a start time inside a file's name.

    Raises
    ------
    IngestError
        A directive a name cannot be searched for (only those of :data:`_NAME_DIRECTIVES`).
    """
    out, at = [], 0
    for m in _DIRECTIVE.finditer(fmt):
        out.append(re.escape(fmt[at : m.start()]))
        key = m.group(1)
        if key not in _NAME_DIRECTIVES:
            raise IngestError(f"export.start_time_format {fmt!r}: %{key} cannot be searched for in a file's name (use {', '.join('%' + k for k in _NAME_DIRECTIVES if k != '%')})")
        out.append(_NAME_DIRECTIVES[key])
        at = m.end()
    out.append(re.escape(fmt[at:]))
    return re.compile("".join(out))


def start_in_name(name: str, fmt: str) -> str | None:
    """The first part of a file's name written in the strftime pattern ``fmt``; None if none."""
    m = name_pattern(fmt).search(name)
    return None if m is None else m.group(0)


def parse_start_time(text: str, fmt: str, timezone: str, *, ambiguous: str = "refuse") -> int:
    """A file's start time (``export.start_time_format``; local time in ``timezone`` unless the
    pattern has an offset) → UTC ns; one in the repeated autumn hour as ``ambiguous`` says
    (``export.ambiguous_time``, :func:`localize`).

    Raises
    ------
    IngestError
        Text that does not match the pattern, a local time that does not exist, or one that is
        ambiguous under ``"refuse"``.
    """
    raw = pl.Series([text.strip()])
    try:
        parsed = raw.str.to_datetime(fmt, time_unit="ns", strict=False)
    except pl.exceptions.PolarsError:
        parsed = pl.Series([None], dtype=pl.Datetime("ns"))
    if parsed[0] is None:
        raise IngestError(f"start time {text.strip()!r} does not match export.start_time_format {fmt!r}")
    if parsed.dtype.time_zone:
        return int(parsed.dt.convert_time_zone("UTC").to_physical()[0])
    try:
        return int(localize(parsed, timezone, ambiguous=ambiguous).to_physical()[0])
    except IngestError as exc:
        raise IngestError(exc.detail) from None  # the caller names the line


def _example(fmt: str) -> str:
    if fmt in RELATIVE_UNIT_NS:
        return f"{fmt} since the file's start time, e.g. 0.001" if fmt == "seconds" else f"{fmt} since the file's start time, e.g. 1.5"
    if fmt == "iso8601":
        return "e.g. 2025-03-01T12:00:00.123Z or 2025-03-01 13:00:00.123+01:00"
    if fmt == "epoch_ms":
        return "milliseconds since 1970-01-01 UTC, e.g. 1740830400123"
    return f"the pattern {fmt!r}"


def _line(lines: pl.Series | None, i: int) -> int:
    return i + 1 if lines is None else int(lines[i])


def unreadable_timestamp(text: object, fmt: str) -> str:
    """What is wrong with a timestamp the ingest cannot read (``text`` as in the file)."""
    if text is None or (isinstance(text, str) and not text.strip()):
        return "missing timestamp"
    return f"timestamp {str(text)!r} does not match export.timestamp_format {fmt!r} (expected {_example(fmt)})"


def _first_failure(raw: pl.Series, ok: pl.Series, lines: pl.Series | None, fmt: str, tags: pl.Series | None) -> IngestError:
    i = int((~ok.fill_null(False)).arg_true()[0])
    return IngestError(unreadable_timestamp(raw[i], fmt), line=_line(lines, i), tag=None if tags is None else tags[i])


def localize(
    naive: pl.Series,
    timezone: str,
    *,
    groups: pl.Series | None = None,
    lines: pl.Series | None = None,
    tags: pl.Series | None = None,
    ambiguous: str = "refuse",
) -> pl.Series:
    """Naive local wall-clock times → UTC, the repeated autumn hour resolved by row order.

    Within a sequence (a group), a time in the repeated hour is the first pass (summer time)
    before the times go back and the second pass after; a sequence that never goes back is the
    first pass when it has times before that hour, the second when it has times only after it.
    A sequence of times all inside the hour (a single start time is one) cannot be told by its
    order: ``ambiguous`` (``export.ambiguous_time``) says ``"earlier"``, ``"later"`` or
    ``"refuse"``.

    Parameters
    ----------
    naive : Series of Datetime without time zone
        Local times in file order (nulls stay null).
    timezone : str
        IANA name of the plant's time zone.
    groups : Series, optional
        Key of independent row sequences (the tag, in a long export); row order is judged
        within each group. None: the whole column is one sequence (a wide export).
    lines : Series, optional
        Line number of each element, for error messages (default: position + 1).
    tags : Series of str, optional
        Tag of each element, named in error messages.
    ambiguous : str
        ``"refuse"``, ``"earlier"`` or ``"later"``: a time in the repeated hour the order cannot tell.

    Raises
    ------
    IngestError
        For a time inside the spring gap (it does not exist in ``timezone``), and under
        ``"refuse"`` for a time in the repeated hour the order cannot tell, naming both instants.
    """
    naive = naive.cast(pl.Datetime("ns"))
    if timezone == "UTC":
        return naive.dt.replace_time_zone("UTC")
    zoned = naive.dt.replace_time_zone(timezone, ambiguous="null", non_existent="null")
    unresolved = zoned.is_null() & naive.is_not_null()
    if not unresolved.any():
        return zoned.dt.convert_time_zone("UTC")
    pos = unresolved.arg_true()
    grp = pl.Series(np.zeros(len(naive), dtype=np.int64)) if groups is None else groups
    sub = pl.DataFrame({"pos": pos, "grp": grp.gather(pos), "naive": naive.gather(pos)})
    earliest = sub["naive"].dt.replace_time_zone(timezone, ambiguous="earliest", non_existent="null")
    if earliest.null_count():
        i = int(sub["pos"][int(earliest.is_null().arg_true()[0])])
        raise IngestError(
            f"local time {naive[i]} does not exist in {timezone} (clocks jump forward at the start of summer time)",
            line=_line(lines, i),
            tag=None if tags is None else tags[i],
        )
    clear = pl.DataFrame({"grp": grp, "naive": naive}).filter(zoned.is_not_null()).group_by("grp").agg(
        first=pl.col("naive").min(), last=pl.col("naive").max()
    )  # fmt: skip
    key = [pl.col("grp"), pl.col("naive").dt.year()]
    folded = (
        sub.with_columns(went_back=(pl.col("naive") < pl.col("naive").cum_max().shift(1)).fill_null(False).over(key))
        .with_columns(fold=pl.col("went_back").cast(pl.Int8).cum_max().over(key) > 0, folds=pl.col("went_back").any().over(key))
        .join(clear, on="grp", how="left", maintain_order="left")
        .with_columns(
            before=(pl.col("first") < pl.col("naive").min().over(key)).fill_null(False),
            after=(pl.col("last") > pl.col("naive").max().over(key)).fill_null(False),
        )
        .with_columns(told=pl.col("folds") | pl.col("before") | pl.col("after"))
    )
    if ambiguous == "refuse" and not folded["told"].all():
        j = int((~folded["told"]).arg_true()[0])
        i = int(folded["pos"][j])
        one = folded["naive"].gather([j])
        both = [_iso_utc(one.dt.replace_time_zone(timezone, ambiguous=a)) for a in ("earliest", "latest")]
        raise IngestError(
            f"local time {naive[i]} is in the hour {timezone} repeats when the clocks go back: it is {both[0]} (summer time) or {both[1]}, "
            "and nothing in the file tells which; set export.ambiguous_time = \"earlier\" or \"later\" if the plant knows",
            line=_line(lines, i),
            tag=None if tags is None else tags[i],
        )
    later = pl.when(pl.col("folds")).then(pl.col("fold")).when(pl.col("before")).then(False).when(pl.col("after")).then(True).otherwise(ambiguous == "later")
    resolved = folded.select(
        pl.col("naive").dt.replace_time_zone(timezone, ambiguous=pl.when(later).then(pl.lit("latest")).otherwise(pl.lit("earliest")), non_existent="raise")
    ).to_series()
    return zoned.scatter(pos, resolved).dt.convert_time_zone("UTC")


def _iso_utc(t: pl.Series) -> str:
    return t.dt.convert_time_zone("UTC").dt.strftime("%Y-%m-%dT%H:%M:%S%.fZ")[0].replace(".000000000Z", "Z")


def parse_timestamps(
    raw: pl.Series,
    fmt: str,
    timezone: str,
    *,
    groups: pl.Series | None = None,
    lines: pl.Series | None = None,
    tags: pl.Series | None = None,
    unreadable: str = "raise",
    origin_ns: int | None = None,
    ambiguous: str = "refuse",
) -> pl.Series:
    """Timestamps of an export (text, epoch numbers or typed) → Datetime(ns, UTC).

    Every non-null element must be readable (``unreadable="raise"``), or an element that is not
    becomes null (``"null"``: the ingest quarantines its row, :func:`unreadable_timestamp` says
    why); nulls stay null (the caller decides about them).

    Parameters
    ----------
    raw : Series
        The export's timestamp column in file order.
    fmt : str
        ``export.timestamp_format``: ``"iso8601"``, ``"epoch_ms"`` or a strftime pattern.
    timezone : str
        ``plant.timezone``, for timestamps without an offset.
    groups, lines, tags
        See :func:`localize`.
    unreadable : str
        ``"raise"`` or ``"null"`` (above).
    origin_ns : int, optional
        The file's start time (UTC ns) that relative timestamps count from.
    ambiguous : str
        ``export.ambiguous_time`` (:func:`localize`).

    Raises
    ------
    IngestError
        Naming the first line whose timestamp cannot be read, or a local time that does not exist.
    """
    dtype = raw.dtype
    if fmt in RELATIVE_UNIT_NS:
        return _relative(raw, fmt, origin_ns, lines=lines, tags=tags, strict=unreadable == "raise")
    if isinstance(dtype, pl.Datetime):
        if dtype.time_zone is not None:
            return raw.dt.convert_time_zone("UTC").cast(UTC_NS)
        return localize(raw, timezone, groups=groups, lines=lines, tags=tags, ambiguous=ambiguous)
    if dtype == pl.Date:
        return localize(raw.cast(pl.Datetime("ns")), timezone, groups=groups, lines=lines, tags=tags, ambiguous=ambiguous)
    if dtype.is_numeric():
        if fmt != "epoch_ms":
            raise IngestError(f"timestamps are numbers, but export.timestamp_format is {fmt!r} (expected 'epoch_ms' for numbers)")
        return _epoch_ms(raw)
    if dtype not in (pl.String, pl.Categorical) and not isinstance(dtype, pl.Enum):
        raise IngestError(f"timestamp column has type {dtype}, expected text, epoch milliseconds or a datetime")
    text = raw.cast(pl.String)
    present = text.is_not_null()
    if fmt == "epoch_ms":
        stripped = text.str.strip_chars()
        out = _epoch_ms(stripped.cast(pl.Int64, strict=False))
        missing = out.is_null() & present
        if missing.any():
            exact = stripped.cast(pl.Decimal(38, 6), strict=False) * 1_000_000
            out = pl.select(pl.coalesce(out, exact.cast(pl.Int64).cast(UTC_NS))).to_series()
        ok = out.is_not_null() | ~present
        if unreadable == "raise" and not ok.all():
            raise _first_failure(text, ok, lines, fmt, tags)
        return out
    if fmt == "iso8601":
        present = text.is_not_null()
        candidates = _iso_formats(text[int(present.arg_max())]) if present.any() else []
        if candidates:
            fast = _arrow_iso(text, zoned=candidates[0][1])
            if fast is not None:
                return fast if candidates[0][1] else localize(fast, timezone, groups=groups, lines=lines, tags=tags, ambiguous=ambiguous)
    else:
        zoned = any(d in fmt for d in _ZONED_DIRECTIVES)
        candidates = [(fmt, zoned)]
    return _parse_text(text, candidates, fmt, timezone, groups=groups, lines=lines, tags=tags, strict=unreadable == "raise", ambiguous=ambiguous)


def _arrow_iso(text: pl.Series, *, zoned: bool) -> pl.Series | None:
    """The whole column at once: the compiled reader of the common shape
    (:func:`transforms.ingest.iso8601.parse_iso_column`, ~10× faster), else Arrow's ISO-8601
    parser; None if any element is not ISO-8601 of that kind (with an offset when ``zoned``,
    without otherwise), so the caller falls back to the format-by-format path, which also
    names the offending line."""
    # string_view chunks: no copy of the text (a whole-column to_arrow would first rechunk it)
    arr = pa.chunked_array([c.to_arrow(compat_level=pl.CompatLevel.newest()) for c in text.get_chunks()], type=pa.string_view())
    parsed = parse_iso_column(arr, zoned=zoned)
    if parsed is None:
        import pyarrow.compute as pc  # noqa: PLC0415 - only here (~40 ms of start-up for every command otherwise)

        try:
            parsed = pc.cast(arr.cast(pa.large_string()), pa.timestamp("ns", "UTC" if zoned else None))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError):
            return None
    out = pl.from_arrow(parsed)
    return out.alias(text.name) if isinstance(out, pl.Series) else None


def _relative(raw: pl.Series, fmt: str, origin_ns: int | None, *, lines: pl.Series | None, tags: pl.Series | None, strict: bool) -> pl.Series:
    """Time since the file's start (numbers, or text with a decimal point or comma) → UTC."""
    if origin_ns is None:
        raise IngestError(f"export.timestamp_format {fmt!r} counts from the file's start, and no start time was given")
    if raw.dtype.is_numeric():
        elapsed = raw.cast(pl.Float64)
        present = raw.is_not_null()
    else:
        text = raw.cast(pl.String).str.strip_chars()
        present = text.is_not_null() & (text.str.len_bytes() > 0)
        elapsed = text.str.replace(",", ".", literal=True).cast(pl.Float64, strict=False)
    ok = elapsed.is_not_null() & elapsed.is_finite().fill_null(False)
    if strict and not (ok | ~present).all():
        raise _first_failure(raw.cast(pl.String), ok | ~present, lines, fmt, tags)
    ns = (elapsed * RELATIVE_UNIT_NS[fmt]).round(0)
    out = pl.when(ok).then(ns).otherwise(None)
    return pl.select(out.cast(pl.Int64) + origin_ns).to_series().cast(UTC_NS).alias(raw.name)


def _epoch_ms(values: pl.Series) -> pl.Series:
    if values.dtype.is_integer():
        ns = values.cast(pl.Int64) * 1_000_000
    else:
        ns = (values.cast(pl.Float64) * 1e6).round(0).cast(pl.Int64)
    return ns.cast(UTC_NS)


def _parse_text(
    text: pl.Series,
    candidates: list[tuple[str, bool]],
    fmt: str,
    timezone: str,
    *,
    groups: pl.Series | None,
    lines: pl.Series | None,
    tags: pl.Series | None,
    strict: bool = True,
    ambiguous: str = "refuse",
) -> pl.Series:
    """Try the candidate formats in turn on the rows still unread; local ones are localised.
    Rows no format reads raise (``strict``) or stay null."""
    n = len(text)
    todo = text.is_not_null().arg_true()
    zoned_out: pl.Series | None = None
    naive_out: pl.Series | None = None
    for pattern, zoned in candidates:
        if len(todo) == 0:
            break
        whole = len(todo) == n
        sub = text if whole else text.gather(todo)
        parsed = sub.str.to_datetime(pattern, time_unit="ns", strict=False)
        if zoned:
            parsed = parsed.dt.convert_time_zone("UTC") if parsed.dtype.time_zone else parsed.dt.replace_time_zone("UTC")
        elif parsed.dtype.time_zone:
            parsed = parsed.dt.replace_time_zone(None)
        ok = parsed.is_not_null()
        n_ok = int(ok.sum())
        if n_ok:
            if whole and n_ok == n:
                placed = parsed
            else:
                placed = pl.repeat(None, n, dtype=parsed.dtype, eager=True).alias(text.name).scatter(todo.filter(ok), parsed.filter(ok))
            if zoned:
                zoned_out = placed if zoned_out is None else pl.select(pl.coalesce(zoned_out, placed)).to_series()
            else:
                naive_out = placed if naive_out is None else pl.select(pl.coalesce(naive_out, placed)).to_series()
        todo = todo.filter(~ok)
    if len(todo) and strict:
        ok = pl.Series([True] * n).scatter(todo, False)
        raise _first_failure(text, ok, lines, fmt, tags)
    if naive_out is not None:
        local = localize(naive_out, timezone, groups=groups, lines=lines, tags=tags, ambiguous=ambiguous)
        return local if zoned_out is None else pl.select(pl.coalesce(zoned_out, local)).to_series()
    if zoned_out is None:
        return pl.repeat(None, n, dtype=UTC_NS, eager=True).alias(text.name)
    return zoned_out.cast(UTC_NS)

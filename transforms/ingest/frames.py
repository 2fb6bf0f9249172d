"""Gridded tags → the canonical sensor frame per valve and UTC day; validation by the registry's
schemas (one polars pass, pandera to name a failure).

A lake row is one valve at one grid instant. It exists where *every required signal*
(``ps, pr, p1, p2, x_spool, x_cyl``) has a value at that instant; ``x_ref`` is filled where its
tag has a value and null elsewhere. Columns, dtypes and order come from
:data:`schemas.fields.SENSOR_FIELDS`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import date
from functools import lru_cache

from typing import TYPE_CHECKING

import numpy as np
import polars as pl

from schemas.fields import (
    RAW_ROW_FIELDS,
    REQUIRED_SIGNALS,
    SENSOR_FIELDS,
    SIGNAL_COLUMN,
    conforms,
    pandera_schema,
    polars_schema,
)
from transforms.ingest.errors import IngestError
from transforms.ingest.grid import Gridded

if TYPE_CHECKING:
    import pandera.errors
    import pandera.polars

SENSOR_POLARS_SCHEMA = polars_schema(SENSOR_FIELDS)
US_PER_DAY = 86_400_000_000


def empty_sensor_frame() -> pl.DataFrame:
    """A sensor frame without rows."""
    return pl.DataFrame(schema=SENSOR_POLARS_SCHEMA)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays of instants are equal: at once when they are the same memory (the tags
    of a wide export share their grid), else element by element."""
    if a.shape == b.shape and a.dtype == b.dtype and a.strides == b.strides and a.__array_interface__["data"][0] == b.__array_interface__["data"][0]:
        return True
    return np.array_equal(a, b)


def assemble_valve(valve_id: str, signals: dict[str, Gridded]) -> pl.DataFrame:
    """One valve's gridded signals → its sensor frame, sorted by time.

    Parameters
    ----------
    valve_id : str
        The valve.
    signals : dict
        Signal name (``"p1"``, …) → that tag on the grid; every required signal present.
    """
    req = [signals[s] for s in REQUIRED_SIGNALS]
    t = req[0].t_us
    aligned = all(_same(g.t_us, t) for g in req[1:])  # the usual case: one grid for all
    if not aligned:
        for g in req[1:]:
            t = np.intersect1d(t, g.t_us, assume_unique=True)
    data: dict[str, object] = {
        "valve_id": pl.repeat(valve_id, len(t), dtype=pl.String, eager=True),
        "date": pl.Series((t // US_PER_DAY).astype(np.int32)).cast(pl.Date),
        "timestamp_utc": pl.Series(t).cast(pl.Datetime("us", "UTC")),
    }
    for s, col in SIGNAL_COLUMN.items():
        g = signals.get(s)
        if g is None:
            data[col] = pl.repeat(None, len(t), dtype=pl.Float32, eager=True)
        elif (aligned and s in REQUIRED_SIGNALS) or _same(g.t_us, t):
            data[col] = np.asarray(g.values, dtype=np.float32)  # (no copy of float32 values: a gridded wide batch)
        else:
            pos = np.searchsorted(g.t_us, t)
            pos_c = np.minimum(pos, max(len(g.t_us) - 1, 0))
            found = (pos < len(g.t_us)) & (g.t_us[pos_c] == t) if len(g.t_us) else np.zeros(len(t), dtype=bool)
            vals = g.values[pos_c].astype(np.float32) if len(g.t_us) else np.zeros(len(t), dtype=np.float32)
            data[col] = pl.Series(col, vals).scatter(np.flatnonzero(~found), None) if not found.all() else vals
    return pl.DataFrame(data).select(SENSOR_POLARS_SCHEMA.names()).cast(dict(SENSOR_POLARS_SCHEMA))


def time_slices(frame: pl.DataFrame, span_us: int) -> list[tuple[int, pl.DataFrame]]:
    """A sensor frame (sorted by time) → ``(k, rows)`` for each span ``[k·span_us, (k+1)·span_us)``
    that holds rows, in order; the edges are found by bisection (no pass over the rows)."""
    if frame.height == 0:
        return []
    t = frame["timestamp_utc"].to_physical()
    first, last = int(t[0]) // span_us, int(t[-1]) // span_us
    if first == last:
        return [(first, frame)]
    ks = np.arange(first, last + 1, dtype=np.int64)
    cuts = np.r_[0, t.search_sorted(pl.Series(ks[1:] * span_us)).to_numpy(), frame.height]  # (a chunked column is not copied)
    return [(int(k), frame.slice(int(a), int(b - a))) for k, a, b in zip(ks, cuts[:-1], cuts[1:]) if b > a]


def split_days(frame: pl.DataFrame) -> list[tuple[date, pl.DataFrame]]:
    """A valve's sensor frame (sorted by time) → one slice per UTC date."""
    return [(part["date"][0], part) for _, part in time_slices(frame, US_PER_DAY)]


def _first_failure(err: pandera.errors.SchemaErrors) -> tuple[str | None, int | None, str, object]:
    """Column, row, check name and failing value of the first failure pandera reports."""
    fc = err.failure_cases
    if not isinstance(fc, pl.DataFrame):
        fc = pl.from_pandas(fc) if hasattr(fc, "to_dict") else pl.DataFrame(fc)
    with_index = fc.filter(pl.col("index").is_not_null()) if "index" in fc.columns else fc
    row = (with_index if with_index.height else fc).row(0, named=True)
    index = row.get("index")
    check = str(row.get("check"))
    for e in getattr(err, "schema_errors", []):
        named = getattr(getattr(e, "check", None), "name", None)
        if named and str(getattr(e.check, "error", "")) == check:
            check = named
            break
    return row.get("column"), None if index is None else int(index), check, row.get("failure_case")


def validate_sensor_frame(frame: pl.DataFrame, tags_by_column: dict[str, dict[str, str]]) -> pl.DataFrame:
    """Validate sensor rows (one or more partitions, of one or more valves) with the sensor-frame
    pandera schema (names, dtypes, physical ranges).

    Parameters
    ----------
    frame : DataFrame
        Collected sensor rows.
    tags_by_column : dict
        Valve → lake column → historian tag, for the message.

    Raises
    ------
    IngestError
        Naming the valve, the tag, the time and the failed check.
    """
    if conforms(frame, SENSOR_FIELDS):  # one pass; pandera (imported only then) names a failure
        return frame
    import pandera.errors  # noqa: PLC0415
    from schemas.fields import SENSOR_SCHEMA  # noqa: PLC0415

    try:
        return SENSOR_SCHEMA.validate(frame, lazy=True)
    except pandera.errors.SchemaErrors as err:
        column, index, check, value = _first_failure(err)
        when, valve = "", "?"
        if index is not None and index < frame.height:
            when = f" at {frame['timestamp_utc'][index].isoformat().replace('+00:00', 'Z')}"
            valve = frame["valve_id"][index]
            if column in frame.columns:
                value = frame[column][index]
        elif frame.height and frame["valve_id"].n_unique() == 1:
            valve = frame["valve_id"][0]
        tag = tags_by_column.get(valve, {}).get(column or "")
        where = f"valve {valve}, column {column}{when}"
        raise IngestError(f"{where}: value {value!r} fails check {check!r}", tag=tag) from None


@lru_cache(maxsize=16)
def raw_row_fields(tags: tuple[str, ...]) -> tuple:
    """The raw-row fields of a plant: ``RAW_ROW_FIELDS`` with ``tag`` an Enum of its tags."""
    return tuple(replace(f, dtype=pl.Enum(list(tags))) if f.name == "tag" else f for f in RAW_ROW_FIELDS)


@lru_cache(maxsize=16)
def raw_row_schema(tags: tuple[str, ...]) -> pandera.polars.DataFrameSchema:
    """The raw-row schema of a plant (:func:`raw_row_fields`)."""
    return pandera_schema(raw_row_fields(tags), "raw_rows")


def validate_raw_rows(accepted: pl.DataFrame) -> None:
    """Validate accepted samples with the plant's raw-row pandera schema (:func:`raw_row_schema`).

    Raises
    ------
    IngestError
        Naming the line, the tag, the time and the failed check.
    """
    frame = accepted.select([f.name for f in RAW_ROW_FIELDS])
    tag_dtype = frame.schema["tag"]
    tags = tuple(tag_dtype.categories.to_list()) if isinstance(tag_dtype, pl.Enum) else None
    fields = RAW_ROW_FIELDS if tags is None else raw_row_fields(tags)
    if conforms(frame, fields):  # one pass; pandera (imported only then) names a failure
        return
    import pandera.errors  # noqa: PLC0415

    schema = pandera_schema(fields, "raw_rows") if tags is None else raw_row_schema(tags)
    try:
        schema.validate(frame, lazy=True)
    except pandera.errors.SchemaErrors as err:
        column, index, check, value = _first_failure(err)
        line = tag = None
        when = ""
        if index is not None and index < frame.height:
            line, tag = int(frame["line"][index]), frame["tag"][index]
            when = f" at {frame['timestamp_utc'][index]}"
        raise IngestError(f"{column}{when}: value {value!r} fails check {check!r} of the raw rows", line=line, tag=tag) from None


@dataclass(frozen=True)
class Partition:
    """One lake partition's new content: a valve on a UTC date."""

    valve_id: str
    date: date
    frame: pl.DataFrame

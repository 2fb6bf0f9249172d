"""The field registry: every column valvemon writes, named once with dtype, unit and range.

The polars, pyarrow and pandera schemas of each table are built from these definitions
(:func:`polars_schema`, :func:`arrow_schema`, :func:`pandera_schema`), so a column cannot mean
one thing in the lake and another in the warehouse.
"""

from __future__ import annotations

from dataclasses import dataclass

import pandera.polars as pa
import polars as pl
import pyarrow as pa_arrow

EDGES: tuple[str, ...] = ("s1", "1r", "s2", "2r")
"""The four control edges, in the order every array and table uses."""

SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref")
"""Signal names of the plant configuration's ``[valves.tags]`` table."""

REQUIRED_SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl")
"""Signals without which a valve cannot be monitored (``x_ref`` is optional)."""

SIGNAL_KIND: dict[str, str] = {
    "ps": "pressure",
    "pr": "pressure",
    "p1": "pressure",
    "p2": "pressure",
    "x_spool": "spool_position",
    "x_cyl": "position",
    "x_ref": "spool_position",
}
"""Kind of each signal, which decides the units it accepts (see :mod:`schemas.units`)."""


@dataclass(frozen=True)
class Field:
    """One column: name (with unit suffix), dtype, unit, meaning and physical range."""

    name: str
    dtype: pl.DataType
    unit: str
    description: str
    nullable: bool = False
    ge: float | None = None
    le: float | None = None
    isin: tuple[str, ...] | None = None


UTC_US = pl.Datetime("us", "UTC")

SIGNAL_COLUMN: dict[str, str] = {
    "ps": "ps_pa",
    "pr": "pr_pa",
    "p1": "p1_pa",
    "p2": "p2_pa",
    "x_spool": "x_spool_m",
    "x_cyl": "x_cyl_m",
    "x_ref": "x_ref_m",
}
"""Canonical lake column of each configured signal."""

SENSOR_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier; also the hive partition key."),
    Field("date", pl.Date, "", "UTC calendar date of the sample; also the hive partition key."),
    Field("timestamp_utc", UTC_US, "", "Sample time, microseconds, UTC."),
    Field("ps_pa", pl.Float64, "Pa", "Supply pressure.", ge=-1e5, le=6e7),
    Field("pr_pa", pl.Float64, "Pa", "Return (tank) pressure.", ge=-1e5, le=6e7),
    Field("p1_pa", pl.Float64, "Pa", "Head-side chamber pressure (port 1).", ge=-1e5, le=6e7),
    Field("p2_pa", pl.Float64, "Pa", "Rod-side chamber pressure (port 2).", ge=-1e5, le=6e7),
    Field("x_spool_m", pl.Float64, "m", "Spool position x; > 0 opens s1 and 2r.", ge=-0.02, le=0.02),
    Field("x_cyl_m", pl.Float64, "m", "Cylinder position X; grows on extension.", ge=-0.1, le=20.0),
    Field("x_ref_m", pl.Float64, "m", "Spool reference from the position controller.", nullable=True, ge=-0.02, le=0.02),
)
"""The lake's canonical sensor frame (``lake/sensors/valve_id=…/date=…``)."""


def polars_schema(fields: tuple[Field, ...]) -> pl.Schema:
    """Polars schema of a table."""
    return pl.Schema({f.name: f.dtype for f in fields})


def arrow_schema(fields: tuple[Field, ...]) -> pa_arrow.Schema:
    """Pyarrow schema of a table, with units and descriptions as field metadata."""
    empty = pl.DataFrame(schema=polars_schema(fields)).to_arrow()
    return pa_arrow.schema(
        [
            pa_arrow.field(
                f.name,
                empty.schema.field(f.name).type,
                nullable=f.nullable,
                metadata={"unit": f.unit, "description": f.description},
            )
            for f in fields
        ]
    )


def _checks(f: Field) -> list[pa.Check]:
    checks = []
    if f.ge is not None:
        checks.append(pa.Check.ge(f.ge, name=f"{f.name} >= {f.ge:g} {f.unit}".rstrip()))
    if f.le is not None:
        checks.append(pa.Check.le(f.le, name=f"{f.name} <= {f.le:g} {f.unit}".rstrip()))
    if f.isin is not None:
        checks.append(pa.Check.isin(list(f.isin)))
    return checks


def pandera_schema(fields: tuple[Field, ...], name: str) -> pa.DataFrameSchema:
    """Pandera schema of a table: names, dtypes, nullability and physical ranges.

    Validate collected frames (``schema.validate(df, lazy=True)``): on a LazyFrame pandera
    checks only names and types.
    """
    return pa.DataFrameSchema(
        {f.name: pa.Column(f.dtype, checks=_checks(f), nullable=f.nullable) for f in fields},
        name=name,
        strict=True,
        ordered=True,
    )


SENSOR_SCHEMA = pandera_schema(SENSOR_FIELDS, "sensor_frame")

"""The field registry builds consistent polars, pyarrow and pandera schemas."""

from datetime import date, datetime, timezone

import pandera.errors
import polars as pl
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schemas.fields import QUARANTINE_FIELDS, QUARANTINE_SCHEMA, SENSOR_FIELDS, SENSOR_SCHEMA, arrow_schema, conforms, polars_schema
from schemas.units import UnitError, si_factor


def _frame(**overrides) -> pl.DataFrame:
    row = {
        "valve_id": "V1", "date": date(2025, 1, 1),
        "timestamp_utc": datetime(2025, 1, 1, tzinfo=timezone.utc),
        "ps_pa": 2e7, "pr_pa": 1e5, "p1_pa": 4e6, "p2_pa": 1.5e7,
        "x_spool_m": 1e-3, "x_cyl_m": 0.3, "x_ref_m": None,
    } | overrides  # fmt: skip
    return pl.DataFrame([row], schema=polars_schema(SENSOR_FIELDS))


def test_valid_frame_passes():
    SENSOR_SCHEMA.validate(_frame())


def test_out_of_range_pressure_is_named():
    with pytest.raises(pandera.errors.SchemaErrors) as err:
        SENSOR_SCHEMA.validate(_frame(p1_pa=9e7), lazy=True)
    assert "p1_pa <= 6e+07 Pa" in str(err.value)


def _passes_pandera(schema, frame: pl.DataFrame) -> bool:
    try:
        schema.validate(frame, lazy=True)
    except (pandera.errors.SchemaErrors, pandera.errors.SchemaError):
        return False
    return True


_EDGE_VALUES = st.sampled_from([None, float("nan"), float("inf"), -float("inf"), 0.0, -1e5, -1.0000001e5, 6e7, 6.0000001e7, 0.02, 0.0200001, -0.1, 20.0, 20.01, 1e308])


@settings(max_examples=40, deadline=None)
@given(
    rows=st.lists(st.tuples(st.sampled_from(["ps_pa", "p2_pa", "x_spool_m", "x_cyl_m", "x_ref_m"]), _EDGE_VALUES), max_size=4),
    height=st.integers(1, 3),
    drop=st.sampled_from([None, "x_ref_m", "valve_id"]),
    reorder=st.booleans(),
    dtype=st.sampled_from([None, pl.Float64]),
)
def test_one_pass_check_agrees_with_pandera(rows, height, drop, reorder, dtype):
    """``conforms`` (the ingest's one-pass check) passes exactly the sensor frames pandera passes:
    nulls, NaN, ±inf and values on and just beyond every bound, a missing column, a column out of
    order, a wrong dtype."""
    frame = pl.concat([_frame()] * height)
    for column, value in rows:
        frame = frame.with_columns(pl.when(pl.int_range(pl.len()) == 0).then(pl.lit(value, dtype=pl.Float32)).otherwise(pl.col(column)).alias(column))
    if dtype is not None:
        frame = frame.with_columns(pl.col("p1_pa").cast(dtype))
    if drop:
        frame = frame.drop(drop)
    if reorder:
        frame = frame.select(frame.columns[::-1])
    assert conforms(frame, SENSOR_FIELDS) == _passes_pandera(SENSOR_SCHEMA, frame)


def test_one_pass_check_of_isin_and_nullable_text():
    """A reason outside the registry's list fails both ways; a null quality (nullable) passes."""
    good = pl.DataFrame(
        {"file_hash": ["h"], "source_file": ["f"], "line": [2], "tag": ["T"], "timestamp_raw": [None], "value_raw": ["x"], "quality": [None],
         "reason": ["non_numeric"], "run_id": ["r"], "ingested_at": [datetime(2025, 1, 1, tzinfo=timezone.utc)]},
        schema=polars_schema(QUARANTINE_FIELDS),
    )  # fmt: skip
    for frame, ok in ((good, True), (good.with_columns(reason=pl.lit("made_up")), False), (good.with_columns(line=pl.lit(0, dtype=pl.Int64)), False)):
        assert conforms(frame, QUARANTINE_FIELDS) is ok
        assert _passes_pandera(QUARANTINE_SCHEMA, frame) is ok


def test_arrow_schema_matches_polars_and_carries_units():
    schema = arrow_schema(SENSOR_FIELDS)
    assert schema.field("timestamp_utc").type == pa.timestamp("us", tz="UTC")
    assert schema.field("p1_pa").metadata[b"unit"] == b"Pa"
    assert _frame().to_arrow().schema.types == schema.types


@pytest.mark.parametrize("unit, kind, factor", [("bar", "pressure", 1e5), ("psi", "pressure", 6894.757293168361), ("MPa", "pressure", 1e6), ("um", "position", 1e-6), ("%", "spool_position", 3.5e-5)])
def test_units(unit, kind, factor):
    assert si_factor(unit, kind, x_max_m=3.5e-3) == pytest.approx(factor)


def test_percent_is_only_for_the_spool():
    with pytest.raises(UnitError):
        si_factor("%", "position", x_max_m=3.5e-3)

"""The field registry builds consistent polars, pyarrow and pandera schemas."""

from datetime import date, datetime, timezone

import pandera.errors
import polars as pl
import pyarrow as pa
import pytest

from schemas.fields import SENSOR_FIELDS, SENSOR_SCHEMA, arrow_schema, polars_schema
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

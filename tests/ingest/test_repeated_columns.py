"""A column name that a header repeats is refused in one line naming the column and both
positions (issue 46, item 3): the decoder would otherwise take the first column as the tag and
list the real one as an other tag ``…_duplicated_0`` that the file does not have. The same
in a long export's header, in a header with several lines (iba ASCII) and in Parquet."""

from __future__ import annotations

import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from flows.common.errors import ValvemonError
from tests.ingest.conftest import ingest, table, write_plant
from tests.ingest.test_row_faults import WIDE, lines_of, plant_of, write


@pytest.mark.parametrize("layout", ["wide", "ascii"])
def test_a_repeated_tag_column_is_refused(tmp_path, layout):
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    sep = "\t" if layout == "ascii" else ","
    t = 0 if layout == "wide" else 1  # the tag line
    names = lines[t].split(sep)
    names[2] = names[1]  # MILL1.V017.PS again where MILL1.PUMP.PS was: 100 % constant 7.5 bar
    lines[t] = sep.join(names)
    path = write(tmp_path / "twice.csv", lines)
    wh = tmp_path / "wh"
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, wh)
    assert str(err.value) == (
        f"{path}: line {t + 1}: column 'MILL1.V017.PS' is named twice, columns 2 and 3; expected one column per tag"
    )
    assert table(wh, "ingest_manifest").height == 0


def test_a_repeated_column_of_a_long_export_is_refused(tmp_path):
    cfg = plant_of(tmp_path, "long")
    lines = lines_of("long")
    lines[0] += ",value"
    lines[1:] = [line + ",1" for line in lines[1:]]
    path = write(tmp_path / "twice.csv", lines)
    with pytest.raises(ValvemonError, match=r"line 1: column 'value' is named twice, columns 3 and 5"):
        ingest(cfg, path, tmp_path / "wh")


def test_a_repeated_column_of_a_parquet_export_is_refused(tmp_path):
    cfg = write_plant(tmp_path, **WIDE)
    ts = pa.array([1_740_787_200_000_000 + i * 1_000_000 for i in range(5)], pa.timestamp("us", "UTC"))
    ones = pa.array([1.0] * 5)
    names = ["Time", *[f"MILL1.V017.{t}" for t in ("PS", "PR", "P1", "P2", "XS", "XC")], "MILL1.V017.P1"]
    path = tmp_path / "twice.parquet"
    pq.write_table(pa.Table.from_arrays([ts, *[ones] * 7], names=names), path)
    with pytest.raises(ValvemonError, match=r"twice.parquet: column 'MILL1.V017.P1' is named twice, columns 4 and 8"):
        ingest(cfg, path, tmp_path / "wh")


def test_trailing_unnamed_columns_are_no_repeat(tmp_path):
    """A header ending in two separators has two unnamed columns: not a repeated name."""
    cfg = plant_of(tmp_path, "wide")
    lines = [line + ",," for line in lines_of("wide")]
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "ok.csv", lines), wh)
    assert table(wh, "ingest_manifest")["quarantined"][0] == 0 and pl.DataFrame(table(wh, "ingest_manifest")).height == 1

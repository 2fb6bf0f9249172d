"""A separator at the end of every data row, or none where the header ends in one, is how the
export writes its rows, not a fault (issue 46, item 2): the rows are read as the clean file's.
A file whose rows are mostly of the wrong width is refused in one line (``field_count`` counts
toward ``export.max_bad_share`` like every other fault) and is not marked as ingested, so the
next run reads it."""

from __future__ import annotations

import pytest
from polars.testing import assert_frame_equal

import flows.ingest.formats
from flows.common.errors import ValvemonError
from tests.ingest.conftest import ingest, lake, table
from tests.ingest.test_row_faults import SECONDS, drop_field, lines_of, plant_of, write


@pytest.mark.parametrize("layout", ["long", "wide", "ascii"])
@pytest.mark.parametrize("habit", ["rows-end-in-a-separator", "header-ends-in-a-separator", "both"])
def test_a_trailing_separator_habit_is_read(tmp_path, monkeypatch, layout, habit):
    monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 2048)  # the habit seen across blocks
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    sep = "\t" if layout == "ascii" else ","
    tag_line = 1 if layout != "ascii" else 2
    habit_lines = list(lines)
    for i in range(len(lines)):
        is_header = i < tag_line
        if (is_header and habit != "rows-end-in-a-separator" and i == tag_line - 1) or (not is_header and habit != "header-ends-in-a-separator"):
            habit_lines[i] += sep
    reference, wh = tmp_path / "reference", tmp_path / "wh"
    ingest(cfg, write(tmp_path / "clean.csv", lines), reference)
    ingest(cfg, write(tmp_path / "habit.csv", habit_lines), wh)
    assert_frame_equal(lake(wh), lake(reference))
    assert lake(wh).height == SECONDS
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert (m["quarantined"], m["field_count"], m["samples_in"]) == (0, 0, SECONDS * 6)


@pytest.mark.parametrize("layout", ["long", "wide"])
def test_a_file_of_rows_of_the_wrong_width_is_refused_and_not_marked_ingested(tmp_path, layout):
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    bad = [lines[0]] + [drop_field(line, 2, ",") for line in lines[1:]]
    path = write(tmp_path / "bad.csv", bad)
    wh = tmp_path / "wh"
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, wh)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: line 2: tag MILL1.V017.")
    assert "field" in message and "export.max_bad_share = 0.05" in message and "100.0%" in message, message
    assert not (wh / "lake").exists() or lake(wh).height == 0
    assert table(wh, "ingest_manifest").height == 0
    write(path, lines)  # the exporter fixed: the same name is read, not skipped
    ingest(cfg, path, wh)
    assert lake(wh).height == SECONDS


def test_a_few_rows_of_the_wrong_width_stay_quarantined_below_the_share(tmp_path):
    """One row of 60 (1.7 % of each tag's samples, under 5 %): read, the row quarantined."""
    cfg = plant_of(tmp_path, "wide")
    lines = lines_of("wide")
    lines[10] = drop_field(lines[10], 2, ",")
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "one.csv", lines), wh)
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert m["field_count"] == 6 and lake(wh).height == SECONDS

"""The report's data-quality section from the ingest's ledger (``flows.report.quality``)."""

from __future__ import annotations

import pytest

from flows.common.errors import ValvemonError
from flows.common.warehouse_db import connect
from flows.report.quality import data_quality, quality_section
from tests.ingest.conftest import DATA, ingest, plant  # noqa: F401  (the fixture)
from tests.ingest.test_faults import T1, _other, long_rows, write_csv


def test_the_section_counts_reasons_files_other_tags_and_refusals(plant, tmp_path):  # noqa: F811
    cfg, _ = plant()
    wh = tmp_path / "wh"
    with connect(wh) as con:
        assert data_quality(con) is None  # nothing ingested yet
    ingest(cfg, DATA / "base_long.csv", wh)
    glitch = write_csv(tmp_path / "glitch.csv", long_rows(edit=lambda i, s, row: row.__setitem__(2, "1e308") if (i, s) == (9, "p1") else None))
    mixed = write_csv(tmp_path / "mixed.csv", long_rows(seconds=20, extra=_other))
    ingest(cfg, [glitch, mixed], wh)
    with pytest.raises(ValvemonError):
        ingest(cfg, write_csv(tmp_path / "2099.csv", long_rows(seconds=30, start=T1.replace(year=2099))), wh)
    with connect(wh, read_only=True) as con:
        q = data_quality(con)
    assert q.totals == {"files": 3, "samples_in": 5 * 6 + 334 * 6 + 20 * 6, "quarantined": 1, "other_samples": 40}
    assert q.by_reason == {"out_of_range": 1}
    assert q.files["source_file"].to_list() == [str(glitch), str(mixed)]
    assert q.refusals.height == 1 and "are at implausible times" in q.refusals["message"][0]
    text = "\n".join(quality_section(q))
    assert "<td>out_of_range</td><td class='num'>1</td>" in text
    assert "MILL1.V099.P1, MILL1.PUMP3.SPEED" in text and "2099.csv: line 2: tag MILL1.V017.PS: time 2099-03-02T00:00:00Z" in text

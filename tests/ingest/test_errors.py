"""Exports the ingest refuses: a one-line ValvemonError naming file, line, tag and what was expected."""

from __future__ import annotations

import gzip

import pytest

from flows.common.errors import ValvemonError
from tests.ingest.conftest import DATA, ingest, lake, table


def _error(cfg, path, wh) -> str:
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, wh)
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def test_spring_gap_local_time_is_refused_with_its_row(plant, tmp_path):
    cfg, _ = plant()
    msg = _error(cfg, DATA / "dst_spring.csv", tmp_path / "wh")
    assert msg.startswith(str(DATA / "dst_spring.csv") + ": line 8: tag MILL1.V017.PS: ")
    assert "local time 2025-03-30 02:30:00 does not exist in Europe/Vienna" in msg


def test_unknown_tag(plant, tmp_path):
    cfg, _ = plant(other_tags="error")
    msg = _error(cfg, DATA / "unknown_tag.csv", tmp_path / "wh")
    assert msg == f"{DATA / 'unknown_tag.csv'}: line 4: unknown tag 'MILL1.V099.P1': no valve of the plant configuration has it"


def test_unknown_tag_column_in_a_wide_export(plant, tmp_path):
    cfg, _ = plant(layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None, other_tags="error")
    path = tmp_path / "wide.csv"
    path.write_text((DATA / "base_wide.csv").read_text().replace("MILL1.V017.PR", "MILL1.V017.PRX"))
    assert "unknown tag 'MILL1.V017.PRX' (column 3)" in _error(cfg, path, tmp_path / "wh")


def test_missing_required_signal(plant, tmp_path):
    cfg, _ = plant()
    msg = _error(cfg, DATA / "missing_signal.csv", tmp_path / "wh")
    assert msg.endswith("tag MILL1.V017.XC: valve V017: required signal x_cyl (tag MILL1.V017.XC) is missing from the export")


def test_truncated_gzip(plant, tmp_path):
    cfg, _ = plant()
    data = gzip.compress((DATA / "base_long.csv").read_bytes())
    path = tmp_path / "cut.csv.gz"
    path.write_bytes(data[: len(data) // 2])
    assert _error(cfg, path, tmp_path / "wh").startswith(f"{path}: truncated or corrupt gzip file")


def test_empty_file(plant, tmp_path):
    cfg, _ = plant()
    path = tmp_path / "empty.csv"
    path.write_bytes(b"")
    assert _error(cfg, path, tmp_path / "wh") == f"{path}: empty file (expected a long export with a header line)"


def test_header_only_file(plant, tmp_path):
    cfg, _ = plant()
    path = tmp_path / "header.csv"
    path.write_text("timestamp,tag,value,quality\n")
    assert _error(cfg, path, tmp_path / "wh") == f"{path}: no data rows (only a header)"


def test_unreadable_parquet(plant, tmp_path):
    cfg, _ = plant()
    assert _error(cfg, DATA / "not_really.parquet", tmp_path / "wh").startswith(f"{DATA / 'not_really.parquet'}: not a readable Parquet export (")


def test_missing_file(plant, tmp_path):
    cfg, _ = plant()
    assert _error(cfg, tmp_path / "nope.csv", tmp_path / "wh") == f"{tmp_path / 'nope.csv'}: no such file or folder"


def test_missing_column_names_the_key(plant, tmp_path):
    cfg, _ = plant(tag_column="Tagname")
    msg = _error(cfg, DATA / "base_long.csv", tmp_path / "wh")
    assert "missing column 'Tagname' (export.tag_column); the file's columns are 'timestamp', 'tag', 'value', 'quality'" in msg


def test_unreadable_timestamp_names_line_and_expected_format(plant, tmp_path):
    """One of the five timestamps of a tag unreadable: 20 %, more than export.max_bad_share."""
    cfg, _ = plant()
    path = tmp_path / "bad_timestamp.csv"
    path.write_text((DATA / "base_long.csv").read_text().replace("2025-03-01T12:00:00.000Z,MILL1.V017.PR", "2025-03-01 noon,MILL1.V017.PR"))
    msg = _error(cfg, path, tmp_path / "wh")
    assert "line 3: tag MILL1.V017.PR: timestamp '2025-03-01 noon' does not match export.timestamp_format 'iso8601' (expected e.g." in msg
    assert msg.endswith("1 of 5 samples of tag MILL1.V017.PR in the file (20.0%) are without a readable timestamp, more than export.max_bad_share = 0.05: a wrong export.timestamp_format? it is 'iso8601'")


def test_duplicate_rule_error_names_tag_time_and_lines(plant, tmp_path):
    cfg, _ = plant(duplicate_rule="error")
    msg = _error(cfg, DATA / "duplicates.csv", tmp_path / "wh")
    assert "line 17: tag MILL1.V017.P1: 2025-03-01T12:00:02.000000000Z has different values (line 17 = 10200000.0, line 22 = 15000000.0)" in msg


def test_out_of_range_value_fails_the_sensor_schema_naming_tag_time_and_check(plant, tmp_path):
    """A supply pressure of 900 bar (a unit mix-up) fails the physical range of ps_pa."""
    cfg, _ = plant()
    path = tmp_path / "spike.csv"
    path.write_text((DATA / "base_long.csv").read_text().replace("MILL1.V017.PS,211.0", "MILL1.V017.PS,900.0"))
    msg = _error(cfg, path, tmp_path / "wh")
    assert msg.startswith(f"{path}: tag MILL1.V017.PS: valve V017, column ps_pa at 2025-03-01T12:00:02Z: value 90000000.0 fails check 'ps_pa <= 6e+07 Pa'")


def test_a_failed_file_leaves_earlier_files_ingested_and_the_run_marked_failed(plant, tmp_path):
    cfg, _ = plant(other_tags="error")
    wh = tmp_path / "wh"
    with pytest.raises(ValvemonError):
        ingest(cfg, [DATA / "base_long.csv", DATA / "unknown_tag.csv"], wh)
    assert lake(wh).height == 5
    runs = table(wh, "ingest_runs")
    assert runs["status"].to_list() == ["failed"] and "unknown tag" in runs["message"][0]
    assert runs["files_ingested"].to_list() == [1]


def test_sample_rate_that_is_no_whole_microsecond_period(plant, tmp_path):
    from schemas.plant_config import ConfigError

    cfg, _ = plant(sample_rate_hz=3000.0, max_gap_s=0.01)
    with pytest.raises(ConfigError, match="sample period of 333.333 µs"):
        ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")

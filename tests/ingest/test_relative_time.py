"""Relative time columns: seconds or milliseconds since the recording's start, the start on a
``start_time`` header line or in the file's name (``export.start_time_format``).

A relative-time export must give the lake of the same samples written as a wide CSV with absolute
UTC times; a file whose start cannot be found or read is refused in one line naming the file and
the line (or its name).
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

import flows.ingest.formats
from flows.common.errors import ValvemonError
from schemas.errors import ConfigError
from tests.ingest.conftest import ingest, lake, table
from tests.ingest.test_recorder_formats import TAG, UNIT, plant_file

RANGES = {"ps": (200, 220), "pr": (1, 3), "p1": (50, 150), "p2": (50, 150), "x_spool": (-1, 1), "x_cyl": (100, 500)}


def samples(n: int, seed: int = 5) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {s: np.round(rng.uniform(*RANGES[s], n), 3) for s in TAG}


def relative_export(path, elapsed: list[str], values: dict, *, start_line: str | None) -> None:
    """A recorder's text export: Windows-1252, CRLF, tab, decimal comma; an info line with the
    start (when ``start_line``), signal ids, tags, descriptions (with a non-ASCII character) and
    units, then the elapsed time and the values."""
    rows = [] if start_line is None else [start_line]
    rows += [
        "\t".join(["[ibaAnalyzer]", *(f"[0:{k}]" for k in range(6))]),
        "\t".join(["Zeit", *TAG.values()]),
        "\t".join(["", *(f"V017 {s} Ø" for s in TAG)]),
        "\t".join(["s", *(UNIT[s] for s in TAG)]),
    ]
    comma = lambda v: repr(float(v)).replace(".", ",")  # noqa: E731
    rows += ["\t".join([t, *(comma(values[s][i]) for s in TAG)]) for i, t in enumerate(elapsed)]
    path.write_bytes(("\r\n".join(rows) + "\r\n").encode("cp1252"))


def wide_csv(path, t_utc_us: np.ndarray, values: dict) -> None:
    t = pl.Series(t_utc_us).cast(pl.Datetime("us", "UTC")).dt.strftime("%Y-%m-%dT%H:%M:%S%.6fZ")
    pl.DataFrame({"Zeit": t} | {TAG[s]: values[s] for s in TAG}).write_csv(path, separator="\t")


def _us(t: datetime) -> int:
    return int(t.timestamp() * 1e6)


RELATIVE = dict(timestamp_column="Zeit", decimal=",", sample_rate_hz=10.0, max_gap_s=0.25)


def csv_lake(tmp_path, t_utc_us: np.ndarray, values: dict) -> pl.DataFrame:
    """The lake of the same samples as a wide CSV with ISO-8601 UTC times."""
    folder = tmp_path / "csv"
    folder.mkdir()
    wide_csv(folder / "same.csv", t_utc_us, values)
    ingest(plant_file(folder, **RELATIVE | {"decimal": "."}, timestamp_format="iso8601"), folder / "same.csv", folder / "wh")
    return lake(folder / "wh")


def test_seconds_since_a_start_time_line_give_the_lake_of_the_wide_csv(tmp_path, monkeypatch):
    """5 min at 10 Hz, seconds with a decimal comma, the start in local time (Vienna, +01:00) on
    the first line; read in blocks of 32 kB, so the start is carried to every block."""
    monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 32_768)
    n = 3000
    values = samples(n)
    elapsed = [f"{i / 10:.3f}".replace(".", ",") for i in range(n)]
    relative_export(tmp_path / "rec.txt", elapsed, values, start_line="Startzeit\t01.03.2025 13:00:00,000")
    cfg = plant_file(
        tmp_path,
        **RELATIVE,
        timestamp_format="seconds",
        header_rows=["start_time", "skip", "tag", "name", "unit"],
        start_time_format="%d.%m.%Y %H:%M:%S,%3f",
    )
    report = ingest(cfg, tmp_path / "rec.txt", tmp_path / "wh")
    got = lake(tmp_path / "wh")
    assert got.height == n and report.quarantined == 0
    assert_frame_equal(got, csv_lake(tmp_path, _us(datetime(2025, 3, 1, 12, tzinfo=timezone.utc)) + np.arange(n) * 100_000, values))


def test_milliseconds_from_the_file_name_run_on_across_the_clock_change(tmp_path):
    """The start from the name (local time, 01:59:00 on the day clocks go forward): the elapsed
    milliseconds are added in UTC, so the recording stays continuous across 02:00 → 03:00; a bad
    time cell is quarantined with its line."""
    n = 1800
    values = samples(n, seed=9)
    elapsed = [str(i * 100) for i in range(n)]
    elapsed[7] = "7OO"  # line 12 (after 4 header lines): letters O for zeros
    path = tmp_path / "REC_V017_20250330T015900.txt"
    relative_export(path, elapsed, values, start_line=None)
    cfg = plant_file(tmp_path, **RELATIVE, timestamp_format="milliseconds", header_rows=["skip", "tag", "name", "unit"], start_time_format="%Y%m%dT%H%M%S")
    ingest(cfg, path, tmp_path / "wh")
    assert table(tmp_path / "wh", "quarantine").select("line", "timestamp_raw", "reason").unique().rows() == [(12, "7OO", "bad_timestamp")]
    t = _us(datetime(2025, 3, 30, 0, 59, tzinfo=timezone.utc)) + np.arange(n) * 100_000
    keep = np.arange(n) != 7
    got = lake(tmp_path / "wh")
    assert got.height == n and got["timestamp_utc"].diff().drop_nulls().unique().to_list() == [timedelta(milliseconds=100)]
    assert_frame_equal(got, csv_lake(tmp_path, t[keep], {s: v[keep] for s, v in values.items()}))


@pytest.mark.parametrize(
    "start_line, name, expected",
    [
        ("Startzeit\t2025-03-01 13:00:00", "rec.txt", "rec.txt: line 1: start time '2025-03-01 13:00:00' does not match export.start_time_format '%d.%m.%Y %H:%M:%S,%3f'"),
        ("Startzeit", "rec.txt", "rec.txt: line 1: expected the recording's start time in the second cell of the 'start_time' line"),
        ("Startzeit\t30.03.2025 02:30:00,000", "rec.txt", "rec.txt: line 1: local time 2025-03-30 02:30:00 does not exist in Europe/Vienna"),
        (None, "rec.txt", "rec.txt: file name 'rec.txt': no start time: no 'start_time' header line (export.header_rows) and no part of the name written in export.start_time_format '%Y%m%dT%H%M%S'"),
        (None, "rec_20251399T250000.txt", "rec_20251399T250000.txt: file name 'rec_20251399T250000.txt': start time '20251399T250000' does not match export.start_time_format '%Y%m%dT%H%M%S'"),
    ],
)
def test_a_file_whose_start_cannot_be_found_or_read_is_refused(tmp_path, start_line, name, expected):
    path = tmp_path / name
    relative_export(path, ["0,0", "0,1"], samples(2), start_line=start_line)
    rows = ["skip", "tag", "name", "unit"]
    fmt = "%Y%m%dT%H%M%S"
    if start_line is not None:
        rows, fmt = ["start_time", *rows], "%d.%m.%Y %H:%M:%S,%3f"
    cfg = plant_file(tmp_path, **RELATIVE, timestamp_format="seconds", header_rows=rows, start_time_format=fmt)
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, tmp_path / "wh")
    assert str(err.value).startswith(f"{tmp_path}/{expected}") and "\n" not in str(err.value)
    assert not (tmp_path / "wh" / "lake").exists()


@pytest.mark.parametrize(
    "export, expected",
    [
        ({"timestamp_format": "seconds"}, "export.start_time_format: required with export.timestamp_format = 'seconds'"),
        ({"start_time_format": "%Y"}, "export.start_time_format: only with a relative export.timestamp_format"),
        ({"header_rows": ["start_time", "tag"]}, "export.header_rows: a 'start_time' line needs a relative export.timestamp_format"),
    ],
)
def test_relative_time_keys_are_checked(tmp_path, export, expected):
    with pytest.raises(ConfigError, match=expected.replace("(", r"\(").replace(".", r"\.")):
        ingest(plant_file(tmp_path, **export), [], tmp_path / "wh")

"""Text rows of the wrong width and cut files: quarantined whole, never read by position.

A line with one field missing in the middle used to be read as if its *last* cell were empty:
every value after the gap moved one column left into the lake. A file cut inside its last line
stored the cut value. Each test compares the lake with the lake of the same file without the bad
line (1 Hz grid, gaps over 2.5 s: the missing second is interpolated from its neighbours), so the
lake holds none of the bad line's values, and reads the quarantine and the manifest.
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path

import polars as pl
import pytest
from polars.testing import assert_frame_equal

import flows.ingest.formats
from tests.ingest.conftest import BASE, ingest, lake, table, write_plant

T = datetime(2025, 3, 2, 0, 0, 0, tzinfo=timezone.utc)
TAGS = {s: f"MILL1.V017.{t}" for s, t in {"ps": "PS", "pr": "PR", "p1": "P1", "p2": "P2", "x_spool": "XS", "x_cyl": "XC"}.items()}
SECONDS = 60
WIDE = dict(layout="wide", timestamp_column="Time", tag_column=None, value_column=None, quality_column=None, good_quality=None)


def _value(signal: str, i: int) -> str:
    return repr(BASE[signal][i % 5] + 0.25 * (i % 7))


def _iso(i: int) -> str:
    return (T + timedelta(seconds=i)).isoformat().replace("+00:00", "Z")


def long_lines() -> list[str]:
    return ["timestamp,tag,value,quality"] + [f"{_iso(i)},{tag},{_value(s, i)},Good" for i in range(SECONDS) for s, tag in TAGS.items()]


def wide_lines(sep: str = ",", header_rows: tuple[str, ...] = ("tag",)) -> list[str]:
    """A wide export with other equipment's columns between the valve's: 15 fields a line."""
    names = ["Time"] + [x for s, tag in TAGS.items() for x in (tag, f"MILL1.PUMP.{s.upper()}")][:12] + ["MILL1.FAN1", "MILL1.FAN2"]
    head = {"tag": names, "unit": [""] * len(names), "skip": [f"[0:{k}]" for k in range(len(names))]}
    lines = [sep.join(head[k]) for k in header_rows]
    for i in range(SECONDS):
        cells = [_iso(i).replace("T", " ").rstrip("Z") if sep == "\t" else _iso(i)]
        for s in TAGS:
            cells += [_value(s, i), "7.5"]
        lines.append(sep.join(cells + ["1", "2"]))
    return lines


def write(path: Path, lines: list[str], *, end: str = "\n") -> Path:
    path.write_text("\n".join(lines) + end)
    return path


def plant_of(tmp_path: Path, layout: str) -> Path:
    if layout == "long":
        return write_plant(tmp_path)
    if layout == "wide":
        return write_plant(tmp_path, **WIDE)
    return write_plant(tmp_path, **WIDE, separator="\t", timestamp_format="%Y-%m-%d %H:%M:%S%.f", header_rows=["skip", "tag", "unit"])


def lines_of(layout: str) -> list[str]:
    return long_lines() if layout == "long" else wide_lines() if layout == "wide" else wide_lines("\t", ("skip", "tag", "unit"))


def lake_without(tmp_path: Path, cfg: Path, lines: list[str], drop: int) -> pl.DataFrame:
    """The lake of the file without its line ``drop`` (1-based)."""
    wh = tmp_path / "reference"
    ingest(cfg, write(tmp_path / "reference.csv", lines[: drop - 1] + lines[drop:]), wh)
    return lake(wh)


def drop_field(line: str, k: int, sep: str) -> str:
    cells = line.split(sep)
    return sep.join(cells[:k] + cells[k + 1 :])


@pytest.mark.parametrize("layout, blocks", [("long", False), ("wide", True), ("ascii", True)], ids=["long", "wide-small-blocks", "ascii-small-blocks"])
def test_a_line_with_a_field_missing_in_the_middle_is_quarantined_whole(tmp_path, monkeypatch, layout, blocks):
    """The issue's line 20010: 15 fields in the header, 14 on the line; today the values after the
    gap move one column left into the lake."""
    if blocks:
        monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 2048)
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    sep = "\t" if layout == "ascii" else ","
    bad = len(lines) // 2 + 1  # the file's line (1-based)
    good = lines[bad - 1]
    lines[bad - 1] = drop_field(good, 2, sep)  # the long layout: the value; wide: a pump column between two valve tags
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "bad.csv", lines), wh)
    assert_frame_equal(lake(wh), lake_without(tmp_path, cfg, lines, bad))
    q = table(wh, "quarantine")
    assert set(q["reason"]) == {"field_count"} and set(q["line"]) == {bad}
    cells = good.split(sep)
    if layout == "long":
        assert q.height == 1 and q["tag"][0] == cells[1]
    else:  # every cell of a plant tag, as the row holds it (shifted)
        assert sorted(q["tag"]) == sorted(TAGS.values())
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert (m["field_count"], m["quarantined"], m["truncated"]) == (q.height, q.height, 0)
    assert m["samples_in"] == SECONDS * 6  # the bad line's samples counted in, as quarantined


@pytest.mark.parametrize("layout", ["long", "wide"])
def test_a_line_with_a_field_too_many_is_quarantined_whole(tmp_path, layout):
    """Before: the whole file was refused for one such line."""
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    bad = 31
    lines[bad - 1] += ",extra"
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "bad.csv", lines), wh)
    assert_frame_equal(lake(wh), lake_without(tmp_path, cfg, lines, bad))
    q = table(wh, "quarantine")
    assert set(q["reason"]) == {"field_count"} and set(q["line"]) == {bad} and q.height == (1 if layout == "long" else 6)


def test_a_quoted_separator_is_no_field(tmp_path):
    cfg = plant_of(tmp_path, "long")
    lines = long_lines()
    lines.insert(10, f'{_iso(1)},"MILL1.V099,NOTE",1.0,Good')  # a tag of other equipment, quoted
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "quoted.csv", lines), wh)
    assert table(wh, "quarantine").height == 0
    assert table(wh, "ingest_manifest")["other_samples"][0] == 1


@pytest.mark.parametrize("layout, cut", [("long", "inside-a-value"), ("wide", "after-a-separator"), ("ascii", "inside-a-value")])
def test_a_file_cut_inside_its_last_line_is_reported_truncated(tmp_path, monkeypatch, layout, cut):
    """The issue's x_cyl 0.009 m next to 0.094 m: the last line's last value cut short (the field
    count is right) or cut after a separator (too few fields); no line end."""
    monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 2048)
    cfg = plant_of(tmp_path, layout)
    lines = lines_of(layout)
    sep = "\t" if layout == "ascii" else ","
    lines[-1] = lines[-1][:-1] if cut == "inside-a-value" else lines[-1][: lines[-1].rindex(sep) + 1]
    wh = tmp_path / "wh"
    path = write(tmp_path / "cut.csv", lines, end="")
    ingest(cfg, path, wh)
    assert_frame_equal(lake(wh), lake_without(tmp_path, cfg, lines, len(lines)))
    q = table(wh, "quarantine")
    assert set(q["reason"]) == {"truncated"} and set(q["line"]) == {len(lines)}
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert m["truncated"] == 1 and m["quarantined"] == q.height > 0


def test_a_complete_file_is_not_truncated_and_costs_no_scan(tmp_path, monkeypatch):
    """A file whose rows all have the header's width and whose last line ends is read as before:
    the text is not scanned (the last column holds no null) and nothing is quarantined."""
    import flows.ingest.formats.text

    def no_scan(*a, **k):
        raise AssertionError("scanned")

    monkeypatch.setattr(flows.ingest.formats.text, "ragged_rows", no_scan)
    cfg = plant_of(tmp_path, "wide")
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "ok.csv", wide_lines()), wh)
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert (m["quarantined"], m["truncated"], m["field_count"]) == (0, 0, 0)
    assert lake(wh).height == SECONDS


def test_the_width_rule_with_a_header_ending_in_a_separator():
    """A header's trailing unnamed column may be left out by a row, but a row that ends in a
    separator must have every field: ``t,2,`` is a field missing in the middle, not ``t,2`` + one
    empty trailing field."""
    from transforms.ingest.text_rows import ragged_rows, width_bounds

    assert width_bounds(["Time", "A", "B", ""]) == (3, 4)
    text = b'Time,A,B,\nt,1,2,\nt,1,2\nt,2,\n\r\nt,1,2,3\n"x,y",1,2,\nt\r\nt,1,2,,'
    rows, counts = ragged_rows(text, ",", 3, 4)
    assert rows.tolist() == [2, 6, 7] and counts.tolist() == [3, 1, 5]

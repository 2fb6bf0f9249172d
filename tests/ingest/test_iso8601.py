"""The compiled ISO-8601 reader (``transforms.ingest.iso8601``) against Arrow's parser.

Wherever the compiled reader accepts a column it must give exactly Arrow's instants; wherever
Arrow refuses one, the compiled reader must give up too (the general path then names the line).
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import polars as pl
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transforms.ingest.iso8601 import parse_iso_column
from transforms.ingest.timestamps import parse_timestamps


def _arrow(arr: pa.Array, zoned: bool) -> pa.Array | None:
    try:
        return pc.cast(arr, pa.timestamp("ns", "UTC" if zoned else None))
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None


def _agree(texts: list[str | None], zoned: bool) -> pa.Array | None:
    arr = pa.array(texts, pa.large_string())
    fast, slow = parse_iso_column(arr, zoned=zoned), _arrow(arr, zoned)
    for layout in (pa.string_view(), pa.string()):  # what polars hands over, and plain Arrow text
        other = parse_iso_column(arr.cast(layout), zoned=zoned)
        assert (other is None) == (fast is None) and (other is None or other.equals(fast)), (layout, texts)
    if slow is None:
        assert fast is None, texts
    if fast is not None:
        assert fast.equals(slow), (texts, fast, slow)
    return fast


ACCEPTED_ZONED = [
    "2025-03-01T12:00:00Z",
    "2025-03-01 12:00:00.1234567+01:00",
    "2025-03-01T12:00:00.123-0130",
    "2025-03-01T12:00:00+01",
    "2025-03-01T12:00:00-00:00",
    "2024-02-29T23:59:59.999999999+23:59",
    "1969-12-31T23:59:59.999999999Z",
    "1678-01-01T00:00:00Z",
    "2261-12-31T23:59:59Z",
]
REFUSED = [
    "2023-02-29T00:00:00Z",  # not a leap year
    "1900-02-29T00:00:00Z",
    "2025-04-31T00:00:00Z",
    "2025-13-01T00:00:00Z",
    "2025-03-01T24:00:00Z",
    "2025-03-01T23:59:60Z",
    "2025-03-01T12:00:00.Z",
    "2025-03-01T12:00:00.1234567891Z",  # ten digits
    "2025-03-01T12:00:00+24:00",
    "2025-03-01T12:00:00+01:60",
    " 2025-03-01T12:00:00Z",
    "2025-03-01T12:00:00Z ",
    "2025-03-01t12:00:00Z",
    "2025-03-01T12:00:00z",
    "2025-03-01T12:00:00+1:00",
    "2025-03-01T12:00Z",
    "2025-03-01",
    "01.03.2025 12:00:00",
    "",
]


@pytest.mark.parametrize("text", ACCEPTED_ZONED)
def test_zoned_shapes_read_as_arrow_does(text):
    out = _agree([text, None, text], zoned=True)
    assert out is not None and out.null_count == 1
    assert _agree([text], zoned=False) is None  # an offset is no naive time


@pytest.mark.parametrize("text", ["2025-03-01T12:00:00", "2025-03-01 12:00:00.5", "2025-03-29T02:30:00.1234567"])
def test_naive_shapes_read_as_arrow_does(text):
    assert _agree([text, text], zoned=False) is not None
    assert _agree([text], zoned=True) is None


@pytest.mark.parametrize("text", REFUSED)
@pytest.mark.parametrize("zoned", [True, False])
def test_what_it_does_not_know_it_leaves_to_arrow(text, zoned):
    assert parse_iso_column(pa.array(["2025-03-01T12:00:00Z" if zoned else "2025-03-01T12:00:00", text]), zoned=zoned) is None
    _agree([text], zoned)


def test_views_of_a_sliced_polars_column_are_read_in_place():
    texts = ["2025-03-01T12:00:00.5Z", None, "2025-03-01 13:00:00.25+01:00", "2025-03-01T12:00:01Z", "2025-03-01T12:00:01.000000001Z"]
    arr = pl.Series(texts).to_arrow(compat_level=pl.CompatLevel.newest()).slice(1)
    assert arr.type == pa.string_view()
    out = parse_iso_column(arr, zoned=True)
    assert out.equals(_arrow(arr.cast(pa.large_string()), True))
    assert out.null_count == 1


def test_a_mix_of_zoned_and_naive_text_gives_up():
    assert parse_iso_column(pa.array(["2025-03-01T12:00:00Z", "2025-03-01T12:00:01"]), zoned=True) is None
    assert parse_iso_column(pa.array(["2025-03-01T12:00:00", "2025-03-01T12:00:01Z"]), zoned=False) is None


def test_consecutive_rows_sharing_the_second_keep_their_own_fraction_and_offset():
    texts = ["2025-03-01T12:00:00.001Z", "2025-03-01T12:00:00.002+01:00", "2025-03-01T12:00:00Z", "2025-03-01T12:00:01.5-02:30"]
    out = _agree(texts, zoned=True)
    assert out is not None
    assert pl.from_arrow(out).cast(pl.Int64).diff().drop_nulls().to_list() != [0, 0, 0]


instants = st.datetimes(min_value=datetime(1700, 1, 1), max_value=datetime(2250, 12, 31))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(instants, st.integers(0, 999_999_999), st.sampled_from(["T", " "]), st.integers(0, 9), st.sampled_from(["Z", "+01:00", "-0530", "+05", ""])), min_size=1, max_size=8)
)
def test_random_text_reads_as_arrow_reads_it(rows):
    texts = []
    for dt, ns, sep, digits, zone in rows:
        frac = f".{ns:09d}"[: digits + 1] if digits else ""
        texts.append(dt.strftime(f"%Y-%m-%d{sep}%H:%M:%S") + frac + zone)
    for zoned in (True, False):
        _agree(texts, zoned)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["same", 3, 18, 24, 28]), st.integers(0, 9)), min_size=1, max_size=12))
def test_equal_and_nearly_equal_neighbours_read_as_arrow_reads_them(edits):
    """An element equal to the one before takes its value unparsed; one that differs from it in a
    single digit (of the year, the second, the fraction's middle or its last digit) is parsed."""
    texts = ["2025-03-01T12:00:00.123456789Z"]
    for position, digit in edits:
        t = texts[-1]
        texts.append(t if position == "same" else t[:position] + str(digit) + t[position + 1 :])
    assert _agree(texts, zoned=True) is not None


def test_parse_timestamps_takes_the_fast_path_with_the_same_result():
    t0 = datetime(2025, 3, 1, 12, tzinfo=timezone.utc)
    texts = [(t0 + timedelta(milliseconds=k // 3)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z" for k in range(3000)]
    got = parse_timestamps(pl.Series("timestamp", texts), "iso8601", "Europe/Vienna")
    expect = pl.from_arrow(pc.cast(pa.array(texts), pa.timestamp("ns", "UTC")))
    assert got.dtype == pl.Datetime("ns", "UTC")
    assert got.to_list() == expect.to_list()
    assert got[2999] == t0 + timedelta(milliseconds=999)

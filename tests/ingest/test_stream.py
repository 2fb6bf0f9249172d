"""Batch by batch equals whole: an export cut into arbitrary batches gives the lake rows, counts,
quarantine and gaps of the whole file (``transforms.ingest.stream.ExportStream``).

The exports are long, 1 Hz grid (max gap 2.5 s), off-grid times, duplicates and conflicts
(also across a batch edge), bad-quality samples, gaps, an optional ``x_ref`` that may start late
or stop early; every tag's times never go back in file order (a time-ordered export).
"""

from __future__ import annotations

from datetime import timedelta

import polars as pl
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from polars.testing import assert_frame_equal

from tests.ingest.conftest import T0
from tests.ingest.test_properties import CONFIG, TAGS
from transforms.ingest import process_export
from transforms.ingest.stream import ExportStream, NotStreamable

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
XREF = "MILL1.V017.XREF"
SCHEMA = {"timestamp": pl.String, "tag": pl.String, "value": pl.Float64, "quality": pl.String}


@st.composite
def ordered_exports(draw):
    """A long export in time order with the irregularities the rules deal with."""
    n = draw(st.integers(1, 14))
    steps = draw(st.lists(st.sampled_from([1, 1, 1, 1, 2, 4]), min_size=n, max_size=n))  # 4 s: a gap
    with_xref = draw(st.sampled_from([None, (0, n), (n // 2, n), (0, max(n // 2, 1))]))
    rows = []
    second = 0
    for i in range(n):
        second += steps[i]
        tags = TAGS + ([XREF] if with_xref and with_xref[0] <= i < with_xref[1] else [])
        for tag in tags:
            ms = draw(st.sampled_from([0, 0, 0, 250, 500]))  # mostly on the grid
            t = (T0 + timedelta(seconds=second, milliseconds=ms)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
            v = draw(st.integers(-400, 400))
            value = v / 256.0 if tag.endswith(("XS", "XREF")) else 100.0 + v / 8.0
            quality = draw(st.sampled_from(["Good"] * 12 + ["Bad"]))
            rows.append((t, tag, value, quality))
            extra = draw(st.sampled_from([None] * 8 + ["dup", "conflict"]))
            if extra == "dup":
                rows.append((t, tag, value, "Good"))
            elif extra == "conflict":
                rows.append((t, tag, value + 1.0, "Good"))
    return pl.DataFrame(rows, schema=SCHEMA, orient="row")


def _streamed(df: pl.DataFrame, cuts: list[int], rule: str):
    stream = ExportStream(CONFIG[rule])
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < df.height)), df.height]
    frames = []
    for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        frames += stream.feed(df.slice(a, b - a), first_line=2 + a, final=k == len(bounds) - 2)
    return frames, stream


@SETTINGS
@given(data=st.data(), df=ordered_exports(), rule=st.sampled_from(["last", "first"]))
def test_any_batches_give_what_the_whole_export_gives(data, df, rule):
    try:
        whole = process_export(df, CONFIG[rule])
    except Exception as exc:  # a refused export (a required tag wholly quarantined, ...): refused the same way in batches
        cuts = data.draw(st.lists(st.integers(1, max(df.height - 1, 1)), max_size=6))
        with pytest.raises(type(exc)):
            _streamed(df, cuts, rule)
        return
    cuts = data.draw(st.lists(st.integers(1, max(df.height - 1, 1)), max_size=8))
    frames, stream = _streamed(df, cuts, rule)
    expected = pl.concat([p.frame for p in whole.partitions]) if whole.partitions else None
    got = pl.concat(frames) if frames else None
    if expected is None:
        assert got is None
    else:
        assert_frame_equal(got, expected)
    assert stream.counts == whole.counts
    # the same rows; in batches they come batch by batch rather than tag by tag
    assert_frame_equal(stream.quarantine_frame().sort("line", "tag"), whole.quarantine.sort("line", "tag"))
    assert_frame_equal(stream.gap_frame().sort("tag", "gap_start"), whole.gaps.sort("tag", "gap_start"))


def _value(tag: str) -> float:
    return 0.25 if tag.endswith("XS") else 100.0


def test_rows_come_as_soon_as_every_signal_has_reached_them():
    rows = [
        ((T0 + timedelta(seconds=s)).strftime("%Y-%m-%dT%H:%M:%S.000Z"), tag, _value(tag), "Good")
        for s in range(6)
        for tag in TAGS
    ]
    df = pl.DataFrame(rows, schema=SCHEMA, orient="row")
    stream = ExportStream(CONFIG["last"])
    first = stream.feed(df.slice(0, 6 * 3 + 2), first_line=2, final=False)  # 3 whole seconds and 2 tags of the 4th
    assert [f.height for f in first] == [2]  # second 2 waits for its latest samples (they may repeat)
    rest = stream.feed(df.slice(20), first_line=22, final=True)
    assert sum(f.height for f in rest) == 4


def test_times_going_back_across_a_batch_edge_are_not_streamable():
    rows = [((T0 + timedelta(seconds=s)).strftime("%Y-%m-%dT%H:%M:%S.000Z"), tag, _value(tag), "Good") for s in (0, 1, 2, 3) for tag in TAGS]
    late = [((T0 + timedelta(seconds=1.5)).strftime("%Y-%m-%dT%H:%M:%S.500Z"), TAGS[0], 100.0, "Good")]
    df = pl.DataFrame(rows + late, schema=SCHEMA, orient="row")
    stream = ExportStream(CONFIG["last"])
    stream.feed(df.slice(0, 24), first_line=2, final=False)
    with pytest.raises(NotStreamable):
        stream.feed(df.slice(24), first_line=26, final=True)


@pytest.mark.parametrize("seed", range(4))
def test_a_tag_at_other_times_is_not_given_the_grid_of_the_tag_before(seed):
    """The grid's pass is shared only by tags at equal times: a wide export's tag that misses
    samples (interpolated across them) or has a gap gets its own grid, the others share one."""
    import numpy as np

    from transforms.ingest.grid import Grid, grid_times, to_grid

    rng = np.random.default_rng(seed)
    grid = Grid.from_export(1000.0, 0.005)
    t = (np.arange(5_000, dtype=np.int64) + 10**9) * 1_000_000  # 1 kHz
    v = rng.normal(size=len(t))
    shared = grid_times(t, grid)
    assert shared.gridded and shared.same_times(t.copy()) and not shared.same_times(t[:-1])
    missing = np.delete(t, rng.integers(1, len(t) - 1, 3))  # three samples missing: interpolated
    gap = np.delete(t, np.arange(2_000, 2_010))  # 10 ms missing: a gap
    for other in (missing, gap):
        w = np.interp(other, t, v)
        assert not shared.same_times(other)
        want, got = to_grid(other, w, grid), to_grid(other, w, grid, grid_times(other, grid))
        assert np.array_equal(want.t_us, got.t_us) and np.array_equal(want.values, got.values)
        assert np.array_equal(want.gap_start_ns, got.gap_start_ns)
    assert len(to_grid(missing, np.interp(missing, t, v), grid).t_us) == len(t)  # interpolated onto every instant
    assert len(to_grid(gap, np.interp(gap, t, v), grid).gap_start_ns) == 1
    g = to_grid(t, v, grid, shared)
    assert g.t_us is shared.t_us and np.array_equal(g.values, v)

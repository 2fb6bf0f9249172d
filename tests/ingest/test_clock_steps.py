"""A recorder clock that steps back inside a time-ordered (wide) export: the rows after the step are
quarantined (``clock_step``) and named, unless ``export.clock_steps = "accept"``; a long export's
rows out of order are still sorted as before.

Before: the rest of the file was stored at the stepped-back times (an hour early in the issue),
nothing counted, nothing said.
"""

from __future__ import annotations

import polars as pl
import pytest
from polars.testing import assert_frame_equal

import flows.ingest.formats
from tests.ingest.conftest import ingest, lake, table, write_plant
from tests.ingest.test_row_faults import SECONDS, TAGS, WIDE, _iso, _value, long_lines, wide_lines, write

STEP_AT, BACK = 40, 30
"""The row (0-based second) from which the clock reads ``BACK`` seconds early."""


def stepped(lines: list[str], first: int, rows_per_second: int = 1) -> list[str]:
    """The export's lines with the clock set back by ``BACK`` s from second ``STEP_AT`` on
    (``first``: index of the first data line)."""
    out = lines[:]
    for k in range(first + STEP_AT * rows_per_second, len(lines)):
        i = (k - first) // rows_per_second
        out[k] = out[k].replace(_iso(i), _iso(i - BACK), 1)
    return out


@pytest.mark.parametrize("blocks", [False, True], ids=["one-block", "small-blocks"])
def test_a_clock_step_in_a_wide_export_quarantines_the_rows_after_it(tmp_path, monkeypatch, capsys, blocks):
    if blocks:
        monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 2048)  # the step in a later batch
    cfg = write_plant(tmp_path, **WIDE)
    lines = stepped(wide_lines(), 1)
    wh, ref = tmp_path / "wh", tmp_path / "ref"
    ingest(cfg, write(tmp_path / "stepped.csv", lines), wh)
    ingest(cfg, write(tmp_path / "before_the_step.csv", lines[: 1 + STEP_AT]), ref)
    assert_frame_equal(lake(wh), lake(ref))  # nothing after the step in the lake
    q = table(wh, "quarantine")
    after = (SECONDS - STEP_AT) * len(TAGS)
    assert q.height == after and set(q["reason"]) == {"clock_step"} and q["line"].min() == 2 + STEP_AT
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert (m["clock_step"], m["quarantined"]) == (after, after)
    err = capsys.readouterr().err
    assert f"stepped.csv: line {2 + STEP_AT}: the clock steps back: time {_iso(STEP_AT - BACK)} after {_iso(STEP_AT - 1)} on an earlier line" in err
    assert f"({BACK - 1:.3f} s earlier); {after} samples" in err


def test_accept_sorts_the_rows_in_as_before(tmp_path):
    cfg = write_plant(tmp_path, **WIDE, clock_steps="accept")
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "stepped.csv", stepped(wide_lines(), 1)), wh)
    m = table(wh, "ingest_manifest").row(0, named=True)
    assert m["quarantined"] == m["clock_step"] == 0
    assert m["conflicts"] == (SECONDS - STEP_AT) * len(TAGS)  # the stepped rows land on earlier seconds
    assert lake(wh).height == STEP_AT  # seconds 0 … 39: the stepped rows overwrote 10 … 29


def test_a_long_export_out_of_order_is_sorted_as_before(tmp_path):
    """The long layout is not checked: the same step, and the rows of a PI export grouped by tag
    (each tag's times start again), are sorted."""
    cfg = write_plant(tmp_path)
    lines = long_lines()
    by_tag = [lines[0]] + sorted(lines[1:], key=lambda row: row.split(",")[1])
    wh = tmp_path / "wh"
    ingest(cfg, [write(tmp_path / "stepped.csv", stepped(lines, 1, len(TAGS))), write(tmp_path / "by_tag.csv", by_tag)], wh)
    m = table(wh, "ingest_manifest")
    assert m["quarantined"].sum() == m["clock_step"].sum() == 0 and m["conflicts"].sum() == (SECONDS - STEP_AT) * len(TAGS)


def test_rows_a_period_out_of_order_are_no_clock_step(tmp_path):
    """Jitter of a period (rows swapped) is sorted, not a step."""
    cfg = write_plant(tmp_path, **WIDE)
    lines = wide_lines()
    lines[11], lines[12] = lines[12], lines[11]
    wh = tmp_path / "wh"
    ingest(cfg, write(tmp_path / "swapped.csv", lines), wh)
    assert table(wh, "quarantine").height == 0
    assert lake(wh).height == SECONDS and lake(wh)["ps_pa"].to_list()[:13] == pytest.approx([float(_value("ps", i)) * 1e5 for i in range(13)], rel=1e-6)
    assert pl.Series(lake(wh)["timestamp_utc"]).is_sorted()


@pytest.mark.parametrize("seed", range(6))
def test_the_clock_follows_batches_as_the_whole_recording_in_one_pass(seed):
    """The one-pass step finder against its definition: a row is a step when it is more than the
    limit earlier than the running maximum of the plausible, readable times before it (earlier
    batches included); implausible and unreadable times neither step nor move the clock."""
    import numpy as np

    from transforms.ingest.clock import _NONE, ClockSteps

    rng = np.random.default_rng(seed)
    n, limit, allowed = 2_000, 4_000, 10**12
    t = np.cumsum(rng.integers(0, 2_000, n)).astype(np.int64) + 10**9
    t[rng.random(n) < 0.02] = allowed + 1  # implausible: ignored
    nulls = rng.random(n) < 0.02
    if seed % 2:  # a step back somewhere after the first batch edge
        k = int(rng.integers(700, n))
        t[k:] -= 10**6 * 3
    shown = np.where(t > allowed, _NONE, t)
    before = np.maximum.accumulate(np.r_[_NONE, np.where(nulls, _NONE, shown)[:-1]])
    want = np.flatnonzero(~nulls & (shown != _NONE) & (shown + limit < before))
    assert bool(len(want)) == bool(seed % 2)
    clock = ClockSteps(limit, allowed)
    series = pl.Series(t).cast(pl.Datetime("ns", "UTC")).scatter(np.flatnonzero(nulls), None)
    lines = pl.Series(np.arange(n) + 2)
    marked = []
    for a in range(0, n, 600):
        m = clock.after_step(series.slice(a, 600), lines.slice(a, 600))
        marked.append(np.zeros(min(600, n - a), dtype=bool) if m is None else m.to_numpy())
    marked = np.concatenate(marked)
    if len(want):
        i = int(want[0])
        assert clock.line == i + 2 and clock.step_to_ns == t[i] and clock.latest_ns == before[i]
        assert not marked[:i].any() and marked[i:].all()
    else:
        assert clock.line is None and not marked.any()
        assert clock.latest_ns == max(_NONE, int(np.where(nulls, _NONE, shown).max()))

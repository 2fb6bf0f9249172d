"""transforms/retention.py: the retention decision and thinning, held to brute force (hypothesis)."""

from __future__ import annotations

from datetime import date, datetime, timedelta, timezone

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schemas.plant_config import RetentionSpec
from transforms.retention import (
    HOUR_US,
    KEEP,
    REASON_COMMISSIONING,
    REASON_NO_FITS,
    REASON_PART_FITTED,
    REASON_THINNED,
    REASON_UNCHECKED,
    PartitionScan,
    decide,
    fitted_cover,
    hour_firsts,
    kept_ranges,
    kept_row_groups,
    protected_days,
    thin_mask,
    uncovered_samples,
)

DAY = date(2025, 3, 10)
DAY_US = int(datetime(2025, 3, 10, tzinfo=timezone.utc).timestamp() * 1e6)
DAY_LEN_US = 24 * HOUR_US


@st.composite
def runs(draw, max_runs: int = 6) -> np.ndarray:
    """Sorted sample times (µs) of one day: a few runs of 1 kHz samples anywhere in it."""
    out = []
    for _ in range(draw(st.integers(1, max_runs))):
        start = draw(st.integers(0, DAY_LEN_US - 1))
        n = draw(st.integers(1, 40))
        period = draw(st.sampled_from([1000, 250_000, 60_000_000]))
        out.append(DAY_US + start + period * np.arange(n, dtype=np.int64))
    t = np.unique(np.concatenate(out))
    return t[t < DAY_US + DAY_LEN_US]


@st.composite
def windows_for(draw, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fitted windows: some spans of the samples (whole or in parts), plus unrelated ones."""
    s, e = [], []
    for _ in range(draw(st.integers(0, 5))):
        i = draw(st.integers(0, t.size - 1))
        j = draw(st.integers(i, t.size - 1))
        s.append(int(t[i]))
        e.append(int(t[j]))
    for _ in range(draw(st.integers(0, 2))):
        a = draw(st.integers(DAY_US - HOUR_US, DAY_US + DAY_LEN_US))
        s.append(a)
        e.append(a + draw(st.integers(0, HOUR_US)))
    if draw(st.booleans()):  # a window covering everything
        s.append(int(t[0]) - draw(st.integers(0, 10)))
        e.append(int(t[-1]) + draw(st.integers(0, 10)))
    return np.array(s, np.int64), np.array(e, np.int64)


def brute_uncovered(t, s, e) -> int:
    return sum(1 for x in t.tolist() if not any(a <= x <= b for a, b in zip(s.tolist(), e.tolist())))


def scan_of(t, s, e, splits, keep_s=None) -> PartitionScan:
    """A scan fed in batches cut at ``splits``, in a shuffled batch order (files in any order)."""
    cuts = sorted({min(c, t.size) for c in splits})
    batches = np.split(t, cuts)
    order = list(range(len(batches)))[::-1]
    scan = PartitionScan(fitted_cover(s, e))
    for k in order:
        scan.add(batches[k])
    if keep_s is not None:
        scan.rows_kept = 0
        for k in order:
            scan.count_kept(batches[k], keep_s)
    return scan


specs = st.builds(
    RetentionSpec,
    keep_days=st.integers(1, 30),
    mode=st.sampled_from(["drop", "thin"]),
    thin_keep_s_per_hour=st.sampled_from([0.001, 1.0, 10.0, 600.0]),
)


@given(st.data())
@settings(max_examples=100, deadline=None)
def test_uncovered_samples_is_brute_force(data):
    t = data.draw(runs())
    s, e = data.draw(windows_for(t))
    expected = brute_uncovered(t, s, e)
    assert uncovered_samples(np.random.default_rng(0).permutation(t), fitted_cover(s, e)) == expected
    assert uncovered_samples(t, fitted_cover(s, e)) == expected  # sorted: runs of windows, binary searches


@given(st.data(), specs, st.integers(0, 60), st.booleans())
@settings(max_examples=150, deadline=None)
def test_acts_only_on_old_fitted_checked_unprotected_partitions(data, spec, age, checked):
    t = data.draw(runs())
    s, e = data.draw(windows_for(t))
    splits = data.draw(st.lists(st.integers(0, t.size), max_size=3))
    scan = scan_of(t, s, e, splits, keep_s=spec.thin_keep_s_per_hour)
    baseline = data.draw(st.lists(st.tuples(st.integers(-3 * DAY_LEN_US, 3 * DAY_LEN_US), st.integers(1, 2 * DAY_LEN_US)), max_size=2))
    bw = [(datetime.fromtimestamp((DAY_US + a) / 1e6, timezone.utc), datetime.fromtimestamp((DAY_US + a + n) / 1e6, timezone.utc)) for a, n in baseline]
    checked_us = int(t[-1]) + data.draw(st.integers(0, 10)) if checked else data.draw(st.one_of(st.none(), st.integers(DAY_US - HOUR_US, int(t[-1]) - 1)))
    as_of = DAY + timedelta(days=age)
    d = decide(DAY, as_of, spec, protected_days(bw), scan, checked_us)
    if d.action == KEEP:
        return
    assert d.action == spec.mode
    assert age > spec.keep_days
    assert brute_uncovered(t, s, e) == 0  # never before every sample's window is fitted
    # the commissioning window's data is never touched: the day shares no instant with it
    assert all(DAY_US + DAY_LEN_US <= DAY_US + a or DAY_US + a + n <= DAY_US for a, n in baseline)
    assert checked_us is not None and checked_us >= t.max()  # the standstill check has read it all
    if spec.mode == "thin":
        assert scan.rows_kept < t.size


@given(st.data(), specs)
@settings(max_examples=100, deadline=None)
def test_reasons_are_the_first_rule_that_fails(data, spec):
    t = data.draw(runs())
    s, e = data.draw(windows_for(t))
    scan = scan_of(t, s, e, [], keep_s=spec.thin_keep_s_per_hour)
    old = DAY + timedelta(days=spec.keep_days + 1)
    assert decide(DAY, DAY + timedelta(days=spec.keep_days), spec, frozenset(), scan, None).reason == f"kept: within {spec.keep_days} days"
    assert decide(DAY, old, spec, frozenset({DAY}), scan, None).reason == REASON_COMMISSIONING
    n_out = brute_uncovered(t, s, e)
    d = decide(DAY, old, spec, frozenset(), scan, None)
    assert d.reason == (REASON_NO_FITS if n_out == t.size else REASON_PART_FITTED if n_out else REASON_UNCHECKED)


@given(st.data(), st.sampled_from([0.001, 0.5, 10.0, 600.0, 3599.0]))
@settings(max_examples=100, deadline=None)
def test_thinning_is_idempotent_and_keeps_every_hour(data, keep_s):
    t = data.draw(runs())
    firsts = hour_firsts(t)
    mask = thin_mask(t, firsts, keep_s)
    kept = t[mask]
    # the same rows as index ranges: by binary search (sorted) and as the mask's runs (any order)
    shuffled = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1))).permutation(t)
    for times in (t, shuffled):
        rows = np.zeros(times.size, bool)
        for a, b in kept_ranges(times, firsts, keep_s):
            assert a < b and not rows[a:b].any()
            rows[a:b] = True
        assert np.array_equal(rows, thin_mask(times, firsts, keep_s))
    # every hour with data keeps its first sample, and only samples < keep_s after it
    assert hour_firsts(kept) == firsts
    assert all(int(x) - firsts[int(x) // HOUR_US] < keep_s * 1e6 for x in kept)
    # thinning the thinned keeps everything: applying retention twice is applying it once
    assert thin_mask(kept, hour_firsts(kept), keep_s).all()
    spec = RetentionSpec(keep_days=1, mode="thin", thin_keep_s_per_hour=keep_s)
    cover = (np.array([t[0]]), np.array([t[-1]]))
    again = PartitionScan(cover)
    again.add(kept)
    again.rows_kept = 0
    again.count_kept(kept, keep_s)
    assert decide(DAY, DAY + timedelta(days=5), spec, frozenset(), again, int(t[-1])).reason == REASON_THINNED


@given(st.data())
@settings(max_examples=100, deadline=None)
def test_scan_does_not_depend_on_batches(data):
    t = data.draw(runs())
    s, e = data.draw(windows_for(t))
    one = scan_of(t, s, e, [], keep_s=10.0)
    many = scan_of(t, s, e, data.draw(st.lists(st.integers(0, t.size), max_size=5)), keep_s=10.0)
    assert (one.rows, one.uncovered, one.last_us, one.firsts, one.rows_kept) == (many.rows, many.uncovered, many.last_us, many.firsts, many.rows_kept)


def test_protected_days_are_the_windows_half_open_dates():
    d0 = datetime(2025, 1, 1, tzinfo=timezone.utc)
    assert protected_days([(d0, d0 + timedelta(days=1))]) == {date(2025, 1, 1)}  # read as start <= t < end
    assert protected_days([(d0 + timedelta(hours=23), d0 + timedelta(days=2, hours=1))]) == {date(2025, 1, d) for d in (1, 2, 3)}
    assert protected_days([]) == frozenset()


def test_thin_mask_and_kept_ranges_refuse_hours_they_were_not_given():
    t = np.array([DAY_US, DAY_US + 2 * HOUR_US])
    with pytest.raises(ValueError, match="hour is missing"):
        thin_mask(t, hour_firsts(t[:1]), 10.0)
    with pytest.raises(ValueError, match="hour is missing"):
        kept_ranges(t, hour_firsts(t[:1]), 10.0)


def test_continuous_hour_keeps_its_first_seconds():
    t = DAY_US + np.arange(0, 2 * HOUR_US, 10_000, dtype=np.int64)  # two hours at 100 Hz
    kept = t[thin_mask(t, hour_firsts(t), 10.0)]
    assert kept.size == 2 * 1_000
    assert kept.size / t.size == pytest.approx(10 / 3600)


@given(st.data())
@settings(max_examples=100, deadline=None)
def test_hour_firsts_of_sorted_and_shuffled_time_stamps_agree(data):
    t = data.draw(runs())
    shuffled = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1))).permutation(t)
    expected = {int(h): int(t[t // HOUR_US == h].min()) for h in np.unique(t // HOUR_US)}
    assert hour_firsts(t) == hour_firsts(shuffled) == expected


@given(st.data(), st.sampled_from([0.001, 0.5, 10.0, 600.0]))
@settings(max_examples=100, deadline=None)
def test_row_groups_left_unread_hold_no_kept_sample(data, keep_s):
    t = data.draw(runs())
    cuts = sorted(set(data.draw(st.lists(st.integers(1, max(t.size - 1, 1)), max_size=6))) - {t.size})
    groups = np.split(t, cuts)
    spans = [(g.size, int(g.min()), int(g.max())) for g in groups]
    firsts = hour_firsts(t)
    read = set(kept_row_groups(spans, firsts, keep_s))
    for i, g in enumerate(groups):
        if i not in read:
            assert not thin_mask(g, firsts, keep_s).any()
    assert read <= set(range(len(groups)))
    # a group without statistics (spanning all time) is always read
    assert kept_row_groups([(1, -(2**63), 2**63 - 1)], firsts, keep_s) == [0]

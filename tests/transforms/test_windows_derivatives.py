"""Step 2: windows from time gaps and the clock; Savitzky–Golay values exact on polynomials, never across a gap."""

from datetime import datetime, timezone

import numpy as np
import polars as pl
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transforms.derivatives import add_savgol, savgol_weights
from transforms.windows import LONG_RUN_FRACTION, assign_windows, infer_sample_period_s, window_layout, window_starts, window_table

DT = 1e-3
T0_US = int(datetime(2025, 3, 1, tzinfo=timezone.utc).timestamp() * 1e6)


def _frame(t_s: np.ndarray, cols: dict[str, np.ndarray], valve: str | list[str] = "V1") -> pl.DataFrame:
    n = t_s.shape[0]
    vals = [valve] * n if isinstance(valve, str) else valve
    return pl.DataFrame(
        {
            "valve_id": vals,
            "timestamp_utc": pl.Series(T0_US + np.round(t_s * 1e6).astype(np.int64)).cast(pl.Datetime("us", "UTC")),
            **cols,
        }
    )


def test_windows_split_at_gaps_and_valves():
    t = np.concatenate([np.arange(100) * DT, 1.0 + np.arange(50) * DT, 1.0 + 50 * DT + 0.0025 + np.arange(30) * DT])
    # third block follows the second after a step of 3.5 ms (> 3 periods): new window
    f = _frame(t, {"y": np.zeros_like(t)})
    f2 = _frame(np.arange(40) * DT, {"y": np.zeros(40)}, valve="V2")
    framed = assign_windows(pl.concat([f, f2]), sample_period_s=DT)
    ids = framed["window_id"].to_numpy()
    assert list(np.unique(ids)) == [0, 1, 2, 3]
    assert (ids[:100] == 0).all() and (ids[100:150] == 1).all() and (ids[150:180] == 2).all() and (ids[180:] == 3).all()
    wt = window_table(framed)
    assert wt["n_samples"].to_list() == [100, 50, 30, 40]
    assert wt["valve_id"].to_list() == ["V1", "V1", "V1", "V2"]
    first = framed.group_by("window_id", maintain_order=True).agg(
        pl.col("timestamp_utc").min().alias("a"), pl.col("timestamp_utc").max().alias("b"),
        pl.col("window_start").n_unique().alias("ns"), pl.col("window_start").first().alias("ws"),
        pl.col("window_end").first().alias("we"),
    )
    assert (first["a"] == first["ws"]).all() and (first["b"] == first["we"]).all()
    assert (first["ns"] == 1).all()


def test_step_of_exactly_the_gap_limit_stays_in_the_window():
    t = np.concatenate([np.arange(10) * DT, 9 * DT + 0.003 + np.arange(10) * DT])
    framed = assign_windows(_frame(t, {"y": np.zeros_like(t)}), sample_period_s=DT, gap_limit_s=0.003)
    assert framed["window_id"].n_unique() == 1
    # ... but the irregular step cuts the uniform run
    assert framed["run_start"].to_list()[10] is True
    assert framed["run_start"].sum() == 2


@pytest.mark.parametrize("gap_limit_s", [0.003, 0.0035])
def test_window_starts_follow_the_rule_of_assign_windows(gap_limit_s):
    """The numpy form the flows use (lake row groups, span slicing, standstill windows) starts a
    window exactly where assign_windows does, including at a step of exactly the gap limit."""
    rng = np.random.default_rng(5)
    steps = rng.choice([DT, DT, DT, 0.003, 0.0035, 0.5], size=300)
    t = np.r_[0.0, np.cumsum(steps)]
    framed = assign_windows(_frame(t, {"y": np.zeros_like(t)}), sample_period_s=DT, gap_limit_s=gap_limit_s)
    expected = np.flatnonzero(np.diff(framed["window_id"].to_numpy(), prepend=-1))
    t_us = framed["timestamp_utc"].dt.epoch("us").to_numpy()
    np.testing.assert_array_equal(window_starts(t_us, gap_limit_s * 1e6), expected)


def test_infer_sample_period():
    t = np.concatenate([np.arange(500) * 2e-3, 5.0 + np.arange(500) * 2e-3])
    assert infer_sample_period_s(_frame(t, {"y": t})) == pytest.approx(2e-3)


@pytest.mark.parametrize("window,order", [(21, 3), (15, 2), (31, 4), (7, 1)])
def test_savgol_exact_on_polynomials(window, order):
    rng = np.random.default_rng(window * 10 + order)
    t = np.arange(400) * DT
    tc = t - 0.2  # centre to keep the polynomial well conditioned
    deg = order + 1 if order % 2 == 1 else order  # odd orders: derivative exact one degree higher
    c_s = rng.normal(size=order + 1)
    c_d = rng.normal(size=deg + 1)
    y_s = np.polyval(c_s, tc * 10) * 1e6 + 5e6  # pressure-like magnitudes
    y_d = np.polyval(c_d, tc * 10) * 1e6 + 5e6
    f = _frame(t, {"ys": y_s, "yd": y_d})
    framed = assign_windows(f, sample_period_s=DT)
    out = add_savgol(
        framed, window=window, order=order, sample_period_s=DT,
        outputs={"ys": ("ys_smooth", None), "yd": (None, "yd_dt")},
    )
    h = window // 2
    sm = out["ys_smooth"].to_numpy()
    dv = out["yd_dt"].to_numpy()
    valid = slice(h, 400 - h)
    assert out["ys_smooth"][:h].is_null().all() and out["ys_smooth"][400 - h :].is_null().all()
    assert out["yd_dt"][:h].is_null().all() and out["yd_dt"][400 - h :].is_null().all()
    np.testing.assert_allclose(sm[valid], y_s[valid], rtol=1e-10, atol=1e-6)
    true_d = np.polyval(np.polyder(c_d), tc * 10) * 1e6 * 10
    scale = np.abs(true_d).max()
    np.testing.assert_allclose(dv[valid], true_d[valid], rtol=0, atol=1e-9 * scale)


def test_savgol_weights_orientation():
    # weights apply oldest sample first: a rising ramp has slope +1, not −1
    w = savgol_weights(21, 3, deriv=1)
    assert np.sum(w * (np.arange(21) - 10)) == pytest.approx(1.0)
    assert savgol_weights(21, 2, deriv=1)[0] < 0


def test_savgol_never_crosses_a_gap_or_valve():
    h = 10
    t1 = np.arange(100) * DT
    t2 = 10.0 + np.arange(100) * DT  # new window after a long gap
    # different ramps: a stencil across the gap would mix them and be visibly wrong
    y = np.concatenate([1e5 * t1, -3e5 * (t2 - 10.0) + 7e6])
    dy = np.concatenate([np.full(100, 1e5), np.full(100, -3e5)])
    t3 = np.arange(100) * DT  # a second valve starting at the same time stamps
    f = pl.concat([_frame(np.concatenate([t1, t2]), {"y": y}), _frame(t3, {"y": 2e5 * t3}, valve="V2")])
    framed = assign_windows(f, sample_period_s=DT)
    out = add_savgol(framed, window=2 * h + 1, order=3, sample_period_s=DT, outputs={"y": ("ys", "dy")})
    d = out["dy"].to_numpy()
    null = out["dy"].is_null().to_numpy()
    for start in (0, 100, 200):
        assert null[start : start + h].all() and null[start + 100 - h : start + 100].all()
        assert not null[start + h : start + 100 - h].any()
    np.testing.assert_allclose(d[h : 100 - h], dy[h : 100 - h], rtol=1e-9)
    np.testing.assert_allclose(d[100 + h : 200 - h], dy[100 + h : 200 - h], rtol=1e-9)
    np.testing.assert_allclose(d[200 + h : 300 - h], 2e5, rtol=1e-9)


def test_savgol_masks_around_a_dropped_sample():
    h = 10
    t = np.delete(np.arange(200) * DT, 100)  # one dropped sample: same window, run cut
    f = _frame(t, {"y": 1e5 * t**2})
    framed = assign_windows(f, sample_period_s=DT)
    assert framed["window_id"].n_unique() == 1
    out = add_savgol(framed, window=2 * h + 1, order=3, sample_period_s=DT, outputs={"y": (None, "dy")})
    null = out["dy"].is_null().to_numpy()
    # rows 0..99 are one run, rows 100..198 (t = 101 ms …) the next
    assert null[100 - h : 100 + h].all()
    assert not null[h : 100 - h].any() and not null[100 + h : 199 - h].any()
    np.testing.assert_allclose(out["dy"].to_numpy()[~null], 2e5 * t[~null], rtol=1e-9)


def test_savgol_missing_value_nulls_its_stencils_only():
    h = 10
    t = np.arange(200) * DT
    y = pl.Series("y", 3e5 * t).scatter(100, None)
    f = _frame(t, {"y": y.to_numpy()}).with_columns(y)
    framed = assign_windows(f, sample_period_s=DT)
    out = add_savgol(framed, window=2 * h + 1, order=3, sample_period_s=DT, outputs={"y": ("ys", "dy")})
    null = out["dy"].is_null().to_numpy()
    assert null[100 - h : 100 + h + 1].all() and out["ys"].is_null().to_numpy()[100 - h : 100 + h + 1].all()
    assert not null[h : 100 - h].any() and not null[100 + h + 1 : 200 - h].any()
    np.testing.assert_allclose(out["dy"].to_numpy()[~null], 3e5, rtol=1e-9)


# --------------------------------------------------------------------------------------------
# windows cut by the clock (continuous recordings)
# --------------------------------------------------------------------------------------------

GAP_US = 3_000.0


@st.composite
def _recordings(draw):
    """Sorted time stamps (µs) of one valve: runs of 1 ms steps with the odd 2 ms or 3 ms step
    or duplicate time stamp (no gap), separated by gaps of 3.5 ms … an hour, starting anywhere on the clock; and a
    window length of 0.05 … 2 s (so runs span several lengths)."""
    t0 = draw(st.integers(T0_US, T0_US + 10**9))
    steps = draw(st.lists(st.sampled_from([1_000] * 30 + [0, 2_000, 3_000, 3_001, 3_500, 250_000, 3_600_000_000]), min_size=1, max_size=3000))
    length_s = draw(st.sampled_from([0.05, 0.1, 0.25, 0.6, 1.0, 1.7, 2.0]))
    return np.r_[t0, t0 + np.cumsum(steps)].astype(np.int64), length_s


def _runs(t_us: np.ndarray) -> np.ndarray:
    return np.r_[0, np.flatnonzero(np.diff(t_us) > GAP_US) + 1, t_us.size]


@given(_recordings())
@settings(max_examples=150, deadline=None)
def test_clock_windows_never_straddle_a_gap_and_cut_at_multiples_of_the_length(rec):
    t, length_s = rec
    length_us = round(length_s * 1e6)
    starts = window_starts(t, GAP_US, length_s)
    is_start = np.zeros(t.size, dtype=bool)
    is_start[starts] = True
    runs = _runs(t)
    assert is_start[runs[:-1]].all()  # every gap starts a window: none straddles one
    cell = t // length_us
    for a, b in zip(runs[:-1], runs[1:]):
        inner = np.arange(a + 1, b)
        if t[b - 1] - t[a] < LONG_RUN_FRACTION * length_us:
            assert not is_start[inner].any()  # a short run (a snapshot) is one window, whole
        else:
            # a long run: a window starts exactly at the first sample of each clock cell
            np.testing.assert_array_equal(is_start[inner], cell[inner] != cell[inner - 1])
    assert window_starts(t, GAP_US, None).tolist() == runs[:-1].tolist()  # no length: whole runs


@given(_recordings(), st.data())
@settings(max_examples=150, deadline=None)
def test_clock_windows_the_same_however_the_recording_is_read(rec, data):
    """Cut in two at any instant and read chunk by chunk (the last window of a chunk carried into
    the next, as flows.monitor.flow.lake_chunks does), or sliced to any run of whole windows (a
    span of a backfill): the same windows as the recording read whole."""
    t, length_s = rec
    whole = window_starts(t, GAP_US, length_s)
    k = data.draw(st.integers(1, t.size))
    first = window_starts(t[:k], GAP_US, length_s)
    carry = int(first[-1])
    rest = carry + window_starts(t[carry:], GAP_US, length_s)
    np.testing.assert_array_equal(np.r_[first[:-1], rest], whole)
    bounds = np.r_[whole, t.size]
    i = data.draw(st.integers(0, whole.size - 1))
    j = data.draw(st.integers(i + 1, whole.size))
    a, b = int(bounds[i]), int(bounds[j])
    np.testing.assert_array_equal(a + window_starts(t[a:b], GAP_US, length_s), whole[i:j])


@given(_recordings())
@settings(max_examples=40, deadline=None)
def test_clock_windows_of_assign_windows_and_window_arrays_follow_window_starts(rec):
    t, length_s = rec
    ts = (t - T0_US) * 1e-6
    framed = assign_windows(_frame(ts, {"y": np.zeros(t.size)}), sample_period_s=DT, gap_limit_s=GAP_US * 1e-6, window_s=length_s)
    expected = window_starts(t, GAP_US, length_s)
    np.testing.assert_array_equal(np.flatnonzero(np.diff(framed["window_id"].to_numpy(), prepend=-1)), expected)
    assert framed["run_start"].to_numpy()[expected].all()  # a stencil never reaches into the next window
    lay = window_layout(t, sample_period_s=DT, gap_limit_s=GAP_US * 1e-6, half_window=10, window_s=length_s)
    assert lay.n_windows == expected.size and lay.every_row
    np.testing.assert_array_equal(np.flatnonzero(np.diff(lay.window, prepend=-1)), expected)
    np.testing.assert_array_equal(lay.first, expected)


def test_snapshots_are_never_cut_continuous_recordings_are():
    """Hourly 10 s snapshots at any offset (here straddling a minute) stay whole with 60 s
    windows; a 200 s recording from 12:00:50 is cut at 12:01, 12:02, 12:03, 12:04 (short remainders
    of 10 s and 10 s at its ends), at the same instants whatever the first sample."""
    base = int(datetime(2025, 3, 1, 12, tzinfo=timezone.utc).timestamp() * 1e6)
    snap = np.arange(10_000) * 1_000
    t = np.concatenate([base + 55_000_000 + snap, base + 3_600_000_000 + 59_999_000 + snap])
    assert window_starts(t, GAP_US, 60.0).tolist() == [0, 10_000]
    rec = base + 50_000_000 + np.arange(200_000) * 1_000
    starts = window_starts(rec, GAP_US, 60.0)
    assert ((rec[starts] - base) / 1e6).tolist() == [50.0, 60.0, 120.0, 180.0, 240.0]
    for drop in (1, 4_321, 15_000):  # the file began later: the later cuts do not move
        assert (drop + window_starts(rec[drop:], GAP_US, 60.0)[1:]).tolist() == starts[starts > drop].tolist()
    with pytest.raises(ValueError, match="window_s"):
        window_starts(rec, GAP_US, 0.0)

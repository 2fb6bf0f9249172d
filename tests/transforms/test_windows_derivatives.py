"""Step 2: windows from time gaps; Savitzky–Golay values exact on polynomials, never across a gap."""

from datetime import datetime, timezone

import numpy as np
import polars as pl
import pytest

from transforms.derivatives import add_savgol, savgol_weights
from transforms.windows import assign_windows, infer_sample_period_s, window_starts, window_table

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

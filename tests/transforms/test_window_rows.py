"""A long window evaluated on every k-th row (``MonitorParams.window_rows``): each evaluated row is
the mean of the k rows it stands for (the Savitzky–Golay stencils and the raw signals averaged over
them); both engines agree; the counts add up."""

import dataclasses

import numpy as np
import polars as pl
import pytest
import synth_valve as sv

from transforms.derivatives import box_mean_at, savgol_arrays, savgol_at, take_rows
from transforms.monitor import monitor_points
from transforms.windows import window_layout

WINDOW_ROWS = 700
"""The 6 s windows of ``sv.chamber_data`` (6,000 rows) every 8th row."""


@pytest.fixture(scope="module")
def lake():
    """Two valves, one window each plus V1's second, shorter window after a gap (every row)."""
    t, xc, x, p1, p2, *_ = sv.chamber_data()
    rng = np.random.default_rng(3)
    n = t.shape[0]
    v1 = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc, valve_id="V1")
    v1b = sv.lake_frame(t[:1000], sv.PS, sv.PR, p1[:1000], p2[:1000], x[:1000], xc[:1000], valve_id="V1",
                        start=sv.T0 + np.timedelta64(1, "h").item())  # fmt: skip
    v2 = sv.lake_frame(t, sv.PS, sv.PR, p1 + rng.normal(0, 5e3, n), p2 + rng.normal(0, 5e3, n), x, xc, valve_id="V2")
    return pl.concat([v1, v1b, v2])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_savgol_at_equals_the_full_pass_bit_for_bit(dtype):
    x = np.random.default_rng(1).normal(size=500).cumsum().astype(dtype)
    rows = np.array([0, 3, 9, 10, 11, 17, 250, 489, 490, 499])
    sm, de = savgol_arrays(x, window=21, order=3, sample_period_s=1e-3)
    sm_at, de_at = savgol_at(x, rows, window=21, order=3, sample_period_s=1e-3)
    np.testing.assert_array_equal(sm_at, sm[rows])
    np.testing.assert_array_equal(de_at, de[rows])



@pytest.mark.parametrize("smooth", [True, False])
def test_savgol_at_any_number_of_rows_equals_the_full_pass_bit_for_bit(smooth):
    """The kernel sums four rows at a time: 1 to 9 rows (a last group of one to four), stencils
    leaving the array among them, give the full pass's values."""
    x = np.random.default_rng(3).normal(size=300).cumsum().astype(np.float32)
    sm, de = savgol_arrays(x, window=21, order=3, sample_period_s=1e-3)
    candidates = np.array([2, 10, 11, 57, 150, 151, 200, 289, 290, 299])
    for k in range(1, 10):
        rows = candidates[:k]
        sm_at, de_at = savgol_at(x, rows, window=21, order=3, sample_period_s=1e-3, smooth=smooth)
        np.testing.assert_array_equal(de_at, de[rows])
        if smooth:
            np.testing.assert_array_equal(sm_at, sm[rows])
        else:
            assert sm_at is None

@pytest.mark.parametrize("box", [2, 10])
def test_savgol_at_with_a_box_is_the_mean_of_the_full_pass_over_the_rows_it_stands_for(box):
    """``box`` = k: at row i the mean of the full pass's values at rows i … i + k − 1 (one stencil
    of 21 + k − 1 taps), NaN where that leaves the array; the raw signal's mean alike."""
    x = np.random.default_rng(4).normal(size=400).cumsum().astype(np.float32)
    sm, de = savgol_arrays(x, window=21, order=3, sample_period_s=1e-3)
    rows = np.array([0, 9, 10, 11, 100, 250, 389 - box, 390 - box, 391 - box, 399])
    sm_at, de_at = savgol_at(x, rows, window=21, order=3, sample_period_s=1e-3, box=box)
    inside = (rows >= 10) & (rows + box - 1 < 390)
    assert inside.sum() == 6 and np.isnan(de_at[~inside]).all() and np.isnan(sm_at[~inside]).all()
    for got, full in ((sm_at, sm), (de_at, de)):
        want = np.array([full[i : i + box].mean() for i in rows[inside]])
        np.testing.assert_allclose(got[inside], want, rtol=1e-12, atol=1e-9 * np.abs(full[10:390]).max())
    raw = box_mean_at(np.split(x, [5, 200]), rows[:-1], box)
    np.testing.assert_allclose(raw, [x[i : i + box].astype(np.float64).mean() for i in rows[:-1]], rtol=1e-12)


@pytest.mark.parametrize("sizes", [[500], [3, 250, 7, 1, 239], [100, 400], [20, 21, 459]])
def test_savgol_at_over_chunks_equals_the_joined_array_bit_for_bit(sizes):
    """A column in chunks (row groups, as polars hands them over) is read where it is: the
    stencils that reach across a chunk's end (or over several short chunks) give the same values."""
    x = np.random.default_rng(2).normal(size=500).cumsum().astype(np.float32)
    chunks = np.split(x, np.cumsum(sizes)[:-1])
    rows = np.unique(np.r_[0:500:3, 5, 9, 10, 11, 99, 100, 101, 489, 490, 499])
    sm, de = savgol_at(x, rows, window=21, order=3, sample_period_s=1e-3)
    sm_c, de_c = savgol_at(chunks, rows, window=21, order=3, sample_period_s=1e-3)
    np.testing.assert_array_equal(sm_c, sm)
    np.testing.assert_array_equal(de_c, de)
    np.testing.assert_array_equal(take_rows(chunks, rows), x[rows])


def test_evaluated_rows_every_kth_row_of_each_long_window():
    # windows of 100, 20 and 35 rows at 1 ms (gaps of 10 ms between them)
    t_us = np.concatenate([np.arange(100), 200 + np.arange(20), 400 + np.arange(35)]) * 1000

    def layout(window_rows):
        return window_layout(t_us, sample_period_s=1e-3, half_window=10, window_rows=window_rows)

    assert layout(None).every_row and layout(100).every_row  # every window ≤ 2 × 100 rows long: k = 1
    lay = layout(30)
    assert not lay.every_row
    np.testing.assert_array_equal(lay.first, [0, 100, 120])
    np.testing.assert_array_equal(lay.count, [100, 20, 35])
    np.testing.assert_array_equal(lay.rows, [0, 3, 6, *range(9, 100, 3), *range(100, 120), *range(120, 155)])
    every = layout(None)
    np.testing.assert_array_equal(lay.window, every.window[lay.rows])
    # a row of the first window (k = 3) is valid where the stencils of the 3 rows from it on are
    valid3 = every.valid[lay.rows] & np.r_[every.valid, False, False][lay.rows + 2]
    np.testing.assert_array_equal(lay.valid, np.where(lay.window == 0, valid3, every.valid[lay.rows]))
    np.testing.assert_array_equal(lay.rows[lay.valid & (lay.window == 0)], range(12, 88, 3))


def test_points_are_the_means_of_the_rows_they_stand_for(lake):
    """A thinned window's points lie at every k-th row, each the mean of the k rows from it on: on
    smooth signals its u and area are those of every row averaged over the same k rows (to the
    curvature of 8 ms); the short window (k = 1) keeps every row's points exactly."""
    params = sv.params()
    full = monitor_points(lake, params)
    part = monitor_points(lake, dataclasses.replace(params, window_rows=WINDOW_ROWS))
    assert part.windows.equals(full.windows)
    k = full.windows.select("valve_id", "window_id", (pl.col("n_samples") // WINDOW_ROWS).clip(lower_bound=1).alias("k"))
    assert sorted(k["k"].to_list()) == [1, 8, 8]
    key = ["valve_id", "window_id", "edge"]
    t = (pl.col("timestamp_utc") - pl.col("window_start")).dt.total_milliseconds()
    block = full.points.join(k, on=["valve_id", "window_id"]).with_columns((t // pl.col("k")).alias("b"))
    means = block.group_by(*key, "b", "k").agg(pl.len().alias("n"), pl.col("u_m", "area_m2").mean())
    got = part.points.join(k, on=["valve_id", "window_id"]).with_columns((t // pl.col("k")).alias("b"))
    assert (got.filter(pl.col("k") > 1).select(t % pl.col("k") == 0)).to_series().all()
    both = got.join(means.filter(pl.col("n") == pl.col("k")), on=[*key, "b"], suffix="_every")
    assert both.height > 0.9 * got.filter(pl.col("k") > 1).height
    np.testing.assert_allclose(both["u_m"], both["u_m_every"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(both["area_m2"], both["area_m2_every"], rtol=2e-3, atol=1e-10)
    dense = pl.col("k") == 1
    assert got.filter(dense).drop("k", "b").equals(full.points.join(k.filter(dense), on=["valve_id", "window_id"]).drop("k"))
    assert part.points.height < full.points.height // 4
    # the counts are those of the evaluated rows and add up
    per = part.selection.group_by("valve_id", "window_id", "edge").agg(
        pl.col("n_removed").sum() + pl.col("n_selected").first() - pl.col("n_samples").first()
    )
    assert (per["n_removed"] == 0).all()
    n_eval = part.selection.group_by("valve_id", "window_id").agg(pl.col("n_samples").first()).join(full.windows, on=["valve_id", "window_id"])
    np.testing.assert_array_equal(n_eval["n_samples"], -(-n_eval["n_samples_right"] // np.maximum(n_eval["n_samples_right"] // WINDOW_ROWS, 1)))


def test_engines_agree_with_window_rows(lake):
    params = sv.params(window_rows=WINDOW_ROWS)
    a = monitor_points(lake, params, engine="numba")
    b = monitor_points(lake, params, engine="polars")
    assert a.windows.equals(b.windows)
    assert a.selection.equals(b.selection)
    assert a.points.drop("area_m2").equals(b.points.drop("area_m2"))
    np.testing.assert_allclose(a.points["area_m2"].to_numpy(), b.points["area_m2"].to_numpy(), rtol=1e-12)


def test_a_window_short_of_information_is_evaluated_at_every_row(lake):
    """With min_points so high that the thinned 6 s windows keep fewer than THIN_MARGIN × min_points
    samples on an edge, they are evaluated at every row: their points are every row's, on both
    engines; with it low enough they stay thinned (the rule, transforms.monitor.THIN_MARGIN)."""
    full = monitor_points(lake, sv.params())
    per = full.points.group_by("valve_id", "window_id", "edge").len()
    most = int(per["len"].max())
    for engine in ("numba", "polars"):
        dense = monitor_points(lake, sv.params(window_rows=WINDOW_ROWS, min_points=most), engine=engine)
        assert dense.points.drop("area_m2").equals(full.points.drop("area_m2"))
        np.testing.assert_allclose(dense.points["area_m2"].to_numpy(), full.points["area_m2"].to_numpy(), rtol=1e-12)
        thin = monitor_points(lake, sv.params(window_rows=WINDOW_ROWS, min_points=1), engine=engine)
        assert thin.points.height < full.points.height // 4
    # between the two: a window is thinned exactly when every edge with points keeps ≥ 2 × min_points samples
    min_points = int(per["len"].min()) // 2 + 1
    some = monitor_points(lake, sv.params(window_rows=WINDOW_ROWS, min_points=min_points))
    got = some.points.group_by("valve_id", "window_id").len().join(full.points.group_by("valve_id", "window_id").len(), on=["valve_id", "window_id"])
    dense_windows = set(zip(*got.filter(pl.col("len") == pl.col("len_right")).select("valve_id", "window_id").to_dict(as_series=False).values()))
    short = per.filter(pl.col("len") < 2 * min_points)
    assert dense_windows >= set(zip(short["valve_id"], short["window_id"]))

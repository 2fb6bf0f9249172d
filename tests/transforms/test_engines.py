"""The compiled fast path equals the polars-expression reference, row for row and count for count."""

from datetime import timedelta

import numpy as np
import polars as pl
import pytest
import synth_valve as sv

from transforms.characteristic import Characteristic
from transforms.derivatives import savgol_valid
from transforms.monitor import monitor, monitor_points
from transforms.windows import UnsortedTimes, assign_windows, window_layout

pytestmark = pytest.mark.xdist_group("transforms_awkward_lake")  # one worker builds the shared `awkward_lake` once

EDGES = ("s1", "1r", "s2", "2r")


@pytest.fixture(scope="module")
def awkward_lake():
    """Two valves; V1 with a dropped sample, a duplicate time stamp, a 2 ms step (same window),
    a missing p1 value, and a second window after a gap; V2 noisy, rows shuffled."""
    t, xc, x, p1, p2, *_ = sv.chamber_data()
    v1 = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc, valve_id="V1")
    v1 = v1.filter(pl.int_range(pl.len()) != 1500)  # dropped sample
    v1 = pl.concat([v1.head(2500), v1.slice(2499, 1), v1.slice(2500)])  # duplicate time stamp
    v1 = v1.with_columns(
        pl.when(pl.int_range(pl.len()) == 4000).then(None).otherwise(pl.col("p1_pa")).alias("p1_pa"),
        pl.when(pl.int_range(pl.len()) >= 5000)
        .then(pl.col("timestamp_utc") + timedelta(milliseconds=1))
        .otherwise(pl.col("timestamp_utc"))
        .alias("timestamp_utc"),  # a 2 ms step: irregular, but below the 3-period gap limit
    )
    v1b = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc, valve_id="V1", start=sv.T0 + timedelta(hours=1))
    rng = np.random.default_rng(5)
    n = t.shape[0]
    v2 = sv.lake_frame(t, sv.PS, sv.PR, p1 + rng.normal(0, 5e3, n), p2 + rng.normal(0, 5e3, n), x, xc, valve_id="V2")
    lake = pl.concat([v2, v1, v1b])
    return lake.sample(fraction=1.0, shuffle=True, seed=2)


def test_window_layout_equals_the_expressions(awkward_lake):
    one = awkward_lake.filter(pl.col("valve_id") == "V1").sort("timestamp_utc", maintain_order=True)
    framed = assign_windows(one, sample_period_s=1e-3).with_columns(savgol_valid(21).alias("valid"))
    ts = one["timestamp_utc"].to_physical().to_numpy()
    lay = window_layout(ts, sample_period_s=1e-3, half_window=10)
    win, valid, n_w = lay.window, lay.valid, lay.n_windows
    assert n_w == 2
    np.testing.assert_array_equal(win, framed["window_id"].to_numpy())
    np.testing.assert_array_equal(valid, framed["valid"].to_numpy())
    assert (~valid).sum() > 4 * 20  # window edges, the dropped sample, the duplicate, the 2 ms step
    with pytest.raises(UnsortedTimes):  # the order is checked in the same pass
        window_layout(ts[::-1], sample_period_s=1e-3, half_window=10)


@pytest.mark.parametrize("leak", [False, True])
def test_engines_agree(awkward_lake, leak):
    params = sv.params()
    ug = np.linspace(-3.5e-3, 3.5e-3, 701)
    leakage = None
    if leak:
        nominal = {e: Characteristic.from_arrays(ug, sv.TRUTH.area(e, ug) + 1e-8) for e in EDGES}
        leakage = {"V1": nominal, "V2": nominal}
    a = monitor_points(awkward_lake, params, engine="numba", leakage=leakage)
    b = monitor_points(awkward_lake, params, engine="polars", leakage=leakage)
    assert a.windows.equals(b.windows)
    assert a.selection.equals(b.selection)
    assert a.points.drop("area_m2").equals(b.points.drop("area_m2"))
    np.testing.assert_allclose(a.points["area_m2"].to_numpy(), b.points["area_m2"].to_numpy(), rtol=1e-12)
    # the missing p1 value removes its stencil from the points
    assert a.selection.filter(pl.col("rule") == "no_derivative", pl.col("valve_id") == "V1")["n_flagged"].sum() > 0


def test_fits_agree_between_engines(awkward_lake):
    ug = np.linspace(-3.5e-3, 3.5e-3, 1401)
    base = {e: Characteristic.from_arrays(ug, sv.TRUTH.area(e, ug)) for e in EDGES}
    params = sv.params(min_points=300)
    a = monitor(awkward_lake, params, {"V1": base, "V2": base}, engine="numba").fits
    b = monitor(awkward_lake, params, {"V1": base, "V2": base}, engine="polars").fits
    assert a.drop("alpha_hat", "x_hat_m", "e_m2", "alpha_ci_low", "alpha_ci_high", "x_hat_ci_low_m",
                  "x_hat_ci_high_m", "ci_inflation").equals(
        b.drop("alpha_hat", "x_hat_m", "e_m2", "alpha_ci_low", "alpha_ci_high", "x_hat_ci_low_m",
               "x_hat_ci_high_m", "ci_inflation"))
    np.testing.assert_allclose(a["alpha_hat"].to_numpy(), b["alpha_hat"].to_numpy(), rtol=1e-12)
    assert (a["status"] == "ok").sum() == 12

"""Steps 2–4b composed: lake rows of several valves → points, selection counts, fits."""

from datetime import timedelta

import numpy as np
import polars as pl
import pytest
import synth_valve as sv

from transforms.characteristic import Characteristic
from transforms.fit import FIT_COLUMNS
from transforms.monitor import monitor, monitor_points
from transforms.points import POINT_COLUMNS
from transforms.selection import STATS_COLUMNS

pytestmark = pytest.mark.xdist_group("transforms_lake")  # one worker builds the shared `lake` once

EDGES = ("s1", "1r", "s2", "2r")
UG = np.linspace(-3.5e-3, 3.5e-3, 1401)
BASE = {e: Characteristic.from_arrays(UG, sv.TRUTH.area(e, UG)) for e in EDGES}
CHANGED = sv.TRUTH.changed(alpha_factor=1.2, shift_m=0.1e-3)


@pytest.fixture(scope="module")
def lake():
    """V1 healthy, two windows an hour apart; V2 with every edge at 1.2 α and +0.1 mm underlap,
    with sensor noise (0.05 bar, 0.5 µm spool, 1 µm cylinder)."""
    t, xc, x, p1, p2, *_ = sv.chamber_data()
    w1 = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc, valve_id="V1")
    w2 = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc, valve_id="V1", start=sv.T0 + timedelta(hours=1))
    t, xc, x, p1, p2, *_ = sv.chamber_data(truth=CHANGED)
    rng = np.random.default_rng(0)
    n = t.shape[0]
    v2 = sv.lake_frame(
        t, sv.PS + rng.normal(0, 5e3, n), sv.PR + rng.normal(0, 5e3, n),
        p1 + rng.normal(0, 5e3, n), p2 + rng.normal(0, 5e3, n),
        x + rng.normal(0, 0.5e-6, n), xc + rng.normal(0, 1e-6, n), valve_id="V2",
    )
    return pl.concat([w1, w2, v2])


def test_monitor_end_to_end(lake):
    params = {"V1": sv.params(), "V2": sv.params()}
    res = monitor(lake, params, {"V1": BASE, "V2": BASE})
    assert res.points.columns == list(POINT_COLUMNS)
    assert res.selection.columns == list(STATS_COLUMNS)
    assert res.fits.columns == list(FIT_COLUMNS)
    assert res.windows.height == 3
    assert res.fits.height == 12
    assert (res.fits["status"] == "ok").all(), res.fits.select("valve_id", "edge", "status")
    v1 = res.fits.filter(pl.col("valve_id") == "V1")
    np.testing.assert_allclose(v1["alpha_hat"].to_numpy(), 1.0, atol=1e-4)
    np.testing.assert_allclose(v1["x_hat_m"].to_numpy(), 0.0, atol=1e-7)
    v2 = res.fits.filter(pl.col("valve_id") == "V2")
    np.testing.assert_allclose(v2["alpha_hat"].to_numpy(), 1.2, atol=0.005)
    np.testing.assert_allclose(v2["x_hat_m"].to_numpy(), 0.1e-3, atol=0.005e-3)
    assert ((v2["alpha_ci_low"] < 1.2) & (v2["alpha_ci_high"] > 1.2)).all()
    # the selection counts close: removed by some rule + selected = samples, per window and edge
    chk = res.selection.group_by("valve_id", "window_id", "edge").agg(
        (pl.col("n_removed").sum() + pl.col("n_selected").first() - pl.col("n_samples").first()).alias("gap"),
        pl.col("n_selected").first(),
    )
    assert (chk["gap"] == 0).all()
    # ... and agree with the points and the fits
    npts = res.points.group_by("valve_id", "window_id", "edge").len()
    joined = chk.join(npts, on=["valve_id", "window_id", "edge"]).join(
        res.fits.select("valve_id", "window_id", "edge", "n_points"), on=["valve_id", "window_id", "edge"]
    )
    assert (joined["n_selected"] == joined["len"]).all() and (joined["len"] == joined["n_points"]).all()
    # every point respects the step-3 spool rule of its edge
    assert (res.points["u_m"] >= sv.params().spool_limit_m("s1")).all()


def test_monitor_reports_unusable_windows(lake):
    short = lake.filter(pl.col("valve_id") == "V1").head(3000)  # half a window, too few points
    res = monitor(short, sv.params(min_points=5000), {"V1": BASE})
    assert res.fits.height == 4
    assert set(res.fits["status"]) == {"too_few_points"}
    still = lake.filter(pl.col("valve_id") == "V1").head(800).with_columns(pl.lit(0.0).alias("x_spool_m"))
    res = monitor(still, sv.params(), {"V1": BASE})
    assert set(res.fits["status"]) == {"no_points"}
    assert res.points.height == 0


def test_unsorted_input_and_empty_input(lake):
    a = monitor_points(lake, sv.params())
    b = monitor_points(lake.sample(fraction=1.0, shuffle=True, seed=3), sv.params())
    assert a.points.equals(b.points)
    empty = monitor_points(lake.head(0), sv.params())
    assert empty.points.height == 0 and empty.points.columns == list(POINT_COLUMNS)

"""x̂ is a shift whatever the edge law: known shifts of every edge, with α unchanged and grown by
15 %, on the four valve families (Eq. 3, sharp edges, worn lands ×3, the linear-gradient edge of
system simulators), the monitor configured for Eq. 3 (docs/monitoring.md, "x̂ on any edge law").

Noiseless sensors: the bounds (3 % of the shift, 0.1 % of x_max) are on the bias; a 10 s window's
noise alone scatters x̂ by ~0.6 µm, 2 % of 0.03 mm (bench/xhat_families.py without
``--noiseless`` measures both).
"""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest

from model.params import GEOMETRY_FAMILIES

from .shift_study import refplant_study, shift_study
from .test_accuracy import QUIET, X_MAX

SHIFTS_M = (0.03e-3, 0.06e-3)
ALPHAS = (1.0, 1.15)
REL_TOL = 0.03
"""|x̂ − shift| ≤ 3 % of the shift ..."""
ABS_TOL = 0.001 * X_MAX
"""... and ≤ 0.1 % of x_max (3.5 µm)."""
STRAIGHT = {"sharp", "linear"}
"""Families whose edges are straight and do not leak: recognised as not Eq. 3's, no leakage."""


@pytest.mark.parametrize("family", ["eq3", "sharp", "worn3", "linear"])
def test_shift_is_estimated_as_a_shift(family):
    fits = shift_study(GEOMETRY_FAMILIES[family], 1, SHIFTS_M, ALPHAS, sensors=QUIET)
    base = fits.filter(pl.col("window_id") == 0)
    later = fits.filter(pl.col("window_id") > 0)
    assert later.height == 16 and (later["status"] == "ok").all(), later.filter(pl.col("status") != "ok")
    err = later["x_err_m"].abs().to_numpy()
    bad = later.filter(pl.Series((err > REL_TOL * later["x_true_m"].to_numpy()) | (err > ABS_TOL)))
    assert bad.height == 0, bad.select("window_id", "edge", "x_true_m", "alpha_true", "x_err_m", "alpha_err")
    assert later["alpha_err"].abs().max() < 0.005
    # the edge law: recognised from the commissioning window where it is not the configured Eq. 3
    assert set(base["edge_law"]) == ({"sharp"} if family in STRAIGHT else {"eq3"})
    if family in STRAIGHT:
        # no closed-edge leakage: identified as none at commissioning, and in every window 0 lies
        # within the window's interval (to 0.01: without sensor noise the narrowest are ±0.003)
        assert (base["leak_scale_baseline"] < 0.05).all(), base
        assert (later["leak_scale_ci_low"] < 0.01).all(), later.filter(pl.col("leak_scale_ci_low") >= 0.01)
    else:
        assert (base["leak_scale_baseline"] > 0.5).all()
    assert np.isfinite(later["leak_scale"].to_numpy()).all()


@pytest.mark.slow
def test_shift_on_the_second_reference_plant():
    """The linear-gradient valve of the reference plant written apart from model/ (its own
    dynamics: continuous PI, Karnopp sticking, ramped loads, transmitter lag and skew; recorded
    with noise), configured as Eq. 3: recognised as straight, no leakage where there is none, and
    x̂ within 3 % of the shift and 0.1 % of x_max on every edge whose window determined it. The
    four windows of ``bench/xhat_families.py --plant refplant``: in the second (α ×1.15 at 0.03 mm)
    s1 and 2r cover only u = 1.04–1.34 mm, where the pressures' 2 ms of lag and skew leave α̂ 0.16 %
    low and the α̂–x̂ coupling turns that into 7 % of the shift; the fit says so (x̂ not
    determined: the points' spread in u < 0.1 mm) rather than report it (docs/monitoring.md, "x̂ on any edge law")."""
    fits = refplant_study("linear", 1, [(0.03e-3, 1.0), (0.03e-3, 1.15), (0.06e-3, 1.0), (0.06e-3, 1.15)])
    base = fits.filter(pl.col("window_id") == 0)
    later = fits.filter(pl.col("window_id") > 0)
    assert set(base["edge_law"]) == {"sharp"}
    assert (later["status"] == "ok").all(), later.filter(pl.col("status") != "ok")
    cols = ("window_id", "edge", "x_true_m", "alpha_true", "x_err_m", "alpha_err", "u_min_m", "u_max_m", "u_spread_m")
    undetermined = later.filter(~pl.col("x_hat_determined"))
    assert sorted(zip(undetermined["window_id"], undetermined["edge"])) == [(2, "2r"), (2, "s1")], undetermined.select(cols)
    assert ((undetermined["u_max_m"] - undetermined["u_min_m"]) < 0.35e-3).all()
    determined = later.filter(pl.col("x_hat_determined"))
    err = determined["x_err_m"].abs().to_numpy()
    bad = determined.filter(pl.Series((err > REL_TOL * determined["x_true_m"].to_numpy()) | (err > ABS_TOL)))
    assert bad.height == 0, bad.select(cols)
    assert (base["leak_scale_baseline"] <= 1.96 * base["leak_scale_baseline_se"] + 0.01).all(), base
    assert (later["leak_scale_ci_low"] < 0.01).all(), later.filter(pl.col("leak_scale_ci_low") >= 0.01)


@pytest.mark.slow
def test_shift_on_a_laminar_corner():
    """The reference plant's linear-gradient edges whose orifice law leaves Eq. 4's near the corner
    (the discharge coefficient falls with the slot's flow number: laminar at small openings and
    pressure drops), configured as Eq. 3, worn by 0.03–0.06 mm and α ×1–1.15: x̂ within 0.1 % of
    x_max on every ok window, determined or not (bench/xhat_families.py --plant refplant --families
    laminar: worst 0.089 % over 2 seeds × 16 windows); the leakage, which these edges do not have,
    either within a window's interval of 0 or held at the commissioning's and marked."""
    fits = refplant_study("laminar", 1, [(0.03e-3, 1.0), (0.03e-3, 1.15), (0.06e-3, 1.0), (0.06e-3, 1.15)])
    base = fits.filter(pl.col("window_id") == 0)
    later = fits.filter(pl.col("window_id") > 0)
    assert set(base["edge_law"]) == {"sharp"}
    ok = later.filter(pl.col("status") == "ok")
    assert ok.height >= 14, later.filter(pl.col("status") != "ok")
    assert (ok["x_err_m"].abs() <= ABS_TOL).all(), ok.select("window_id", "edge", "x_true_m", "x_err_m", "u_min_m", "u_max_m")
    resolved = ok.filter(~pl.col("leak_scale_held"))
    assert (resolved["leak_scale_ci_low"] < 0.01).all(), resolved
    held = ok.filter(pl.col("leak_scale_held")).join(base.select("edge", "leak_scale_baseline"), on="edge")
    assert held.height > 0 and (held["leak_scale"] == held["leak_scale_baseline"]).all()

"""Estimates that hold for valves unlike Eq. 3 (issue 16): the paper's Sec. 4 study on three
valve families with the same default settings, the Table-2 fault on both area laws, and the
identified closed-edge leakage itself.

Families (``model.area``): Eq. 3 (the paper's valve), sharp edges (no closed-edge leakage), and
Eq. 3 with worn lands (``leakage_factor`` 3: 2.2–2.7× Eq. 3's leakage where the points lie).
The study: a commissioning period of six 10 s snapshots (one minute of moves: enough to identify
the leakage, ``MonitorParams.leak_min_points``) and five windows along the wear scenario; the
monitor's design data stay Table 1's (it is not told the family).
"""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest

from model import broken_edge, condition_at, healthy, wear
from model.params import GEOMETRY_FAMILIES
from transforms.leakage import LEAK_RESOLUTION
from transforms.monitor import commissioning_baseline, monitor

from .sim_lake import simulated_lake
from .test_accuracy import NOMINAL, PARAMS, STUDY_TRAJECTORY, X_MAX, wear_study

FAMILIES = {name: GEOMETRY_FAMILIES[name] for name in ("eq3", "sharp", "worn3")}
ALPHA_TOL = 0.01
"""|α̂ / α_true − 1| bound of issue 16 (1 %)."""
X_TOL = 0.002 * X_MAX
"""|x̂ − x_true| bound of issue 16: 0.2 % of x_max = 7 µm."""
COMMISSIONING = 6


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_wear_study_every_family(family, seed):
    """Every edge, every window t1…t5 within 1 % / 0.2 % of x_max, status ok (measured on 6
    seeds: worst 0.16 % / 0.12 % Eq. 3, 0.24 % / 0.13 % sharp, 0.15 % / 0.15 % worn lands;
    with Eq. 3's leakage assumed instead, sharp 0.97 % / 0.70 %, docs/monitoring.md)."""
    fits = wear_study(seed, seed, trajectory=STUDY_TRAJECTORY, geometry=FAMILIES[family], commissioning=COMMISSIONING)
    later = fits.filter(pl.col("window_id") > 0)
    assert later.height == 20 and (later["status"] == "ok").all(), later.filter(pl.col("status") != "ok")
    bad = later.filter((pl.col("alpha_err").abs() > ALPHA_TOL) | (pl.col("x_err_m").abs() > X_TOL))
    assert bad.height == 0, bad.select("window_id", "edge", "alpha_err", "x_err_m", "u_min_m", "u_max_m")
    # every window reports its edges' leakage with an interval: its own where the interval resolves
    # it (narrower than LEAK_RESOLUTION), else the commissioning's, held and marked
    assert later["leak_scale"].is_not_null().all() and (later["leak_scale"] >= 0).all()
    width = later["leak_scale_ci_high"] - later["leak_scale_ci_low"]
    assert (later["leak_scale_held"] == (width >= LEAK_RESOLUTION)).all()
    own = later.filter(~pl.col("leak_scale_held"))
    assert (own["leak_scale_ci_low"] <= own["leak_scale"]).all() and (own["leak_scale"] <= own["leak_scale_ci_high"]).all()


def _commissioning(family: str, seed: int):
    lake = simulated_lake(condition_at(wear(scatter_seed=seed), np.arange(COMMISSIONING, dtype=float)), seed,
                          trajectory=STUDY_TRAJECTORY, geometry=FAMILIES[family])  # fmt: skip
    return commissioning_baseline(lake, PARAMS, NOMINAL)


@pytest.mark.parametrize("seed", [1, 3])
def test_identified_leakage_tells_the_families_apart(seed):
    """2r's leakage (seen by s2's points: the largest, 150 bar across the closed edge) comes out
    near none for sharp edges, near Eq. 3's for Eq. 3 and 2–4× for worn lands, with an interval;
    every identified scale is ≥ 0."""
    lam = {f: _commissioning(f, seed) for f in FAMILIES}
    assert lam["sharp"]["2r"].leak_scale < 0.3
    assert 0.7 < lam["eq3"]["2r"].leak_scale < 1.4
    assert 1.8 < lam["worn3"]["2r"].leak_scale < 4.0
    for fits in lam.values():
        for b in fits.values():
            assert b.leak_scale >= 0 and min(b.leak_coefficients) >= 0 and np.isfinite(b.leak_scale_se)


@pytest.mark.parametrize("family", ["eq3", "sharp"])
def test_baseline_characteristic_is_never_negative(family):
    """Issue 16, item 4: the baseline Â runs over the whole stroke and never below 0; below the
    underlap it is the identified leakage (none for sharp edges: 0 from 0.1 mm past the edge)."""
    base = _commissioning(family, 2)
    u = np.linspace(-X_MAX, X_MAX, 1401)
    for e, b in base.items():
        c = b.characteristic
        assert c.knots_u_m[0] <= -X_MAX
        a = c.evaluate(u)
        assert (a >= 0).all(), (e, a.min())
        closed = u < -PARAMS.underlap(e) - b.x_vs_nominal_m - 0.1e-3
        np.testing.assert_allclose(a[closed], b.leakage.evaluate(u[closed]), rtol=0.03, atol=1e-12)  # both sampled, 0.05 mm
        if family == "sharp" and e == "2r":
            assert a[closed].max() < 0.3 * NOMINAL[e].evaluate(u[closed]).max()


@pytest.mark.parametrize("family", ["eq3", "sharp"])
def test_table2_fault_caught_on_both_area_laws(family):
    """Table 2's broken edge 1r (α ×2.5, underlap +0.413 mm) against the nominal (Eq. 3)
    characteristic: α̂ and x̂ of 1r far beyond the default fault bounds (α 1.8, x̂ 10 %) and its
    step-4a characteristic implausible, on Eq. 3 valves and on sharp-edged ones; the healthy twin
    stays inside the wear bounds."""
    seed = 3
    hours = np.arange(3, dtype=float)
    out = {}
    for name, scenario in (("broken", broken_edge(scatter_seed=seed)), ("healthy", healthy(scatter_seed=seed))):
        lake = simulated_lake(condition_at(scenario, hours), seed, geometry=FAMILIES[family])
        fits = monitor(lake, PARAMS, {"V1": NOMINAL}, leakage={"V1": NOMINAL}).fits.filter(pl.col("status") == "ok")
        out[name] = (fits, commissioning_baseline(lake, PARAMS, NOMINAL))
    broken = out["broken"][0].filter(pl.col("edge") == "1r")
    assert broken.height >= 2
    assert (broken["alpha_hat"] > 2.2).all() and (broken["x_hat_m"] / X_MAX > 0.10).all()
    assert not out["broken"][1]["1r"].plausibility.ok
    twin = out["healthy"][0]
    assert twin["alpha_hat"].is_between(0.9, 1.1).all() and (twin["x_hat_m"].abs() / X_MAX < 0.05).all()

"""The closed-edge leakage model and its estimators (transforms.leakage, transforms.baseline.
leak_scale_lstsq) on synthetic points whose leakage is known exactly, and the warehouse migration
that adds the leakage columns to an older warehouse."""

from __future__ import annotations

import duckdb
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from model import TABLE1, edge_area
from transforms.baseline import choose_knots, leak_scale_lstsq
from transforms.characteristic import Characteristic
from transforms.leakage import LEAK_REF_M, WORN_FACTOR, closed_leakage, effective_scale, leak_columns, leak_scale_step, worn_branch

G = TABLE1.geometry
XU = 4e-5
U = np.arange(-3.5e-3, 5.0e-3, 0.05e-3)
EQ3 = {e: Characteristic.from_arrays(U, 0.675 * edge_area(U, XU, G.taper_angle(e), G.bore_radius_m, G.spool_radius_m)) for e in ("s2", "2r")}


def _points(n=20_000, seed=0, lam=(0.6, 0.3), noise=0.0):
    """s2's points over u = 1–3 mm with 2r leaking λ₁ Eq. 3 + λ₂ worn lands, a pressure ratio that varies
    at every u (loads), and the Eq. 3 open area as truth."""
    rng = np.random.default_rng(seed)
    u = np.sort(rng.uniform(1.04e-3, 3.0e-3, n))
    ratio = -rng.uniform(1.0, 3.0, n)
    cols = leak_columns(EQ3["2r"], -XU, u, ratio)
    truth = EQ3["s2"].evaluate(u)
    plain = truth + cols @ np.asarray(lam) + noise * truth * rng.standard_normal(n)
    return u, plain, cols, truth


@given(l1=st.floats(0.0, 4.0), l2=st.floats(0.0, 0.5))
@settings(max_examples=25, deadline=None)
def test_closed_leakage_is_the_two_term_family(l1, l2):
    """Below the closing point λ₁·A(u) + λ₂·W(u) (W: the worn-lands branch of ``model.area`` with
    factor 4, to 3 %: its closing-point value stands in for x_l's), above it A itself; ≥ 0; effective scale at 1 mm."""
    c = closed_leakage(EQ3["2r"], -XU, (l1, l2))
    u = U[U < -XU - 0.05e-3]  # the samples below the last one before the closing point
    vc = float(EQ3["2r"].evaluate(-XU))
    worn = 0.675 * edge_area(u, XU, G.taper_angle("2r"), G.bore_radius_m, G.spool_radius_m, leakage_factor=WORN_FACTOR)
    far = u < -XU - 0.2e-3
    np.testing.assert_allclose(worn_branch(EQ3["2r"].evaluate(u[far]), vc), worn[far], rtol=0.03)
    np.testing.assert_allclose(c.evaluate(u), l1 * EQ3["2r"].evaluate(u) + l2 * worn_branch(EQ3["2r"].evaluate(u), vc),
                               rtol=1e-9, atol=1e-18)
    up = np.linspace(0.0, 3e-3, 50)
    np.testing.assert_allclose(c.evaluate(up), EQ3["2r"].evaluate(up), rtol=1e-12)
    assert (c.evaluate(u) >= 0).all()
    eff, se = effective_scale(EQ3["2r"], -XU, (l1, l2), np.zeros((2, 2)))
    ref = float(EQ3["2r"].evaluate(-XU - LEAK_REF_M))
    assert eff == pytest.approx((l1 * ref + l2 * worn_branch(ref, vc)) / ref) and se == 0.0


@pytest.mark.parametrize("lam", [(0.0, 0.0), (1.0, 0.0), (2.5, 0.2), (0.4, 0.05)])
def test_joint_fit_recovers_the_leakage(lam):
    """Exact points: the joint least squares with a free piecewise-linear factor gives λ back (the
    factor absorbs the u-dependence, the ratio's variation at each u identifies λ)."""
    u, plain, cols, truth = _points(lam=lam)
    k = choose_knots(u, max_knots=12, min_spacing_m=1e-4, points_per_interval=200)
    est, cov = leak_scale_lstsq(u, plain, cols, k, truth, block=50)
    np.testing.assert_allclose(est, lam, atol=2e-3)
    assert np.all(np.diag(cov) >= 0)


def test_joint_fit_never_negative_and_prior_pulls():
    """A leakage below none (the data's λ₁ < 0) is held at 0; a prior with a small spread pulls a
    noisy fit toward it; the interval reflects the noise."""
    u, plain, cols, truth = _points(lam=(0.0, 0.0), noise=0.01)
    k = choose_knots(u, max_knots=12, min_spacing_m=1e-4, points_per_interval=200)
    neg, _ = leak_scale_lstsq(u, plain - 0.3 * cols[:, 0], cols, k, truth, block=50)
    assert (neg >= 0).all() and neg[0] == 0.0
    free, cov = leak_scale_lstsq(u, plain, cols, k, truth, block=50)
    pulled, _ = leak_scale_lstsq(u, plain, cols, k, truth, block=50, prior=np.array([1.0, 0.0]), prior_sd=1e-3)
    assert abs(pulled[0] - 1.0) < 0.01 and abs(free[0]) < 4 * np.sqrt(cov[0, 0]) + 1e-9


def test_window_step_is_the_missing_leakage():
    """leak_scale_step at the exact (α̂, x̂) of a population corrected with too little leakage gives
    the missing scale (exact points: to 1e-6), on single points and on block means alike."""
    u, plain, cols, truth = _points(lam=(1.7, 0.0))
    leak = cols[:, 0]
    area = plain - 1.0 * leak  # corrected with λ = 1: 0.7 missing
    kn, kv = EQ3["s2"].knots_u_m, EQ3["s2"].values_m2
    ks = np.append(np.diff(kv) / np.diff(kn), 0.0)
    args = (np.array([0, u.shape[0]]), np.array([True]), np.array([1.0]), np.array([0.0]), np.array([0]), np.array([kn.shape[0]]), kn, kv, ks)
    for block in (1, 50):
        step, info, sigma2, rho = leak_scale_step(u, area, leak, *args, np.array([block]))
        assert step[0] == pytest.approx(0.7, abs=1e-6) and info[0] > 0 and np.isfinite(sigma2[0])


def test_older_warehouse_gets_the_leakage_columns(tmp_path):
    """A warehouse whose edge_fits and baselines predate the leak_* (and u_spread_mm, x_hat_determined, row_stride,
    edge_law*) columns gets them
    (NULL in old rows), after its own columns; a current one costs no DDL."""
    from flows.common.warehouse_db import create_table_sql
    from flows.monitor.flow import ensure_monitor_tables
    from schemas.fields import BASELINE_FIELDS, EDGE_FIT_FIELDS

    con = duckdb.connect(str(tmp_path / "old.duckdb"))
    old_fits = tuple(f for f in EDGE_FIT_FIELDS if not f.name.startswith("leak_") and f.name not in ("u_spread_mm", "x_hat_determined", "row_stride"))
    old_base = tuple(f for f in BASELINE_FIELDS if not f.name.startswith(("leak_", "edge_law")))
    con.execute(create_table_sql("edge_fits", old_fits))
    con.execute(create_table_sql("baselines", old_base))
    ensure_monitor_tables(con)
    for table, fields in (("edge_fits", EDGE_FIT_FIELDS), ("baselines", BASELINE_FIELDS)):
        cols = [r[0] for r in con.execute(f"SELECT column_name FROM duckdb_columns() WHERE table_name = '{table}' ORDER BY column_index").fetchall()]
        assert cols == [f.name for f in fields]
    ensure_monitor_tables(con)  # idempotent

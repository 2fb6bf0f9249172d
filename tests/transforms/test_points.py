"""Eq. 7 and its three siblings reproduce a known α·A from physically consistent data."""

import numpy as np
import polars as pl
import pytest
import synth_valve as sv

from transforms.monitor import prepare_samples
from transforms.points import EDGE_SIGN, opening_area_points

DT = 1e-3


def _analytic_port(port: int):
    """Cubic chamber pressure and cubic cylinder motion (Savitzky–Golay of order 3 is exact on
    both); the flow demanded by Eq. 6 is produced by the open edge of the port, whose spool
    position follows by inverting α_e·k_e·u = q / (sqrt(2/ρ) sign(Δp) sqrt|Δp|)."""
    t = np.arange(0.0, 2.0, DT)
    tm = t - 1.0
    xc = 0.3 + 0.06 * tm - 0.08 * tm**3
    v = 0.06 - 0.24 * tm**2  # extends in the middle, retracts at both ends
    p = 90e5 + 8e5 * tm - 6e5 * tm**2 + 4e5 * tm**3
    dp = 8e5 - 12e5 * tm + 12e5 * tm**2
    if port == 1:
        q = (dp * (sv.V01 + sv.A1 * xc) + sv.BETA * sv.A1 * v) / sv.BETA  # into chamber 1
        open_pos, open_neg = "s1", "1r"
        dp_pos, dp_neg = sv.PS - p, sv.PR - p
    else:
        q = (sv.BETA * sv.A2 * v - dp * (sv.V02 - sv.A2 * xc)) / sv.BETA  # out of chamber 2
        open_pos, open_neg = "2r", "s2"
        dp_pos, dp_neg = p - sv.PR, p - sv.PS
    pos = q > 0
    d = np.where(pos, dp_pos, dp_neg)
    alpha_area = q / (np.sqrt(2 / sv.RHO) * np.sign(d) * np.sqrt(np.abs(d)))
    assert (alpha_area >= 0).all()  # the signs of Eq. 4 are consistent by construction
    edge_of = np.where(pos, open_pos, open_neg)
    u = alpha_area / np.array([sv.TRUTH.alpha[e] * sv.TRUTH.slope[e] for e in edge_of])
    x = np.where(pos, u, -u)  # u = +x for s1/2r, −x for 1r/s2
    other = 120e5 + 0 * t  # the other chamber plays no role for this port
    p1, p2 = (p, other) if port == 1 else (other, p)
    return t, xc, x, p1, p2, (open_pos, open_neg)


@pytest.mark.parametrize("port", [1, 2])
def test_eq7_exact_on_polynomial_data(port):
    t, xc, x, p1, p2, edges = _analytic_port(port)
    lake = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc)
    params = sv.params()
    framed = prepare_samples(lake, params)
    pts = opening_area_points(framed, params)
    for edge in edges:
        side = pl.col("u_m") > 0  # the samples where this edge is the open one
        got = pts.filter(pl.col("edge") == edge, side)
        assert got.height > 400
        u = got["u_m"].to_numpy()
        truth = sv.TRUTH.area(edge, u)
        np.testing.assert_allclose(got["area_m2"].to_numpy(), truth, rtol=1e-7, atol=1e-9 * truth.max())
        # opening coordinate sign convention
        xs = framed.join(got.select("timestamp_utc"), on="timestamp_utc")["x_spool_m"].to_numpy()
        np.testing.assert_allclose(u, EDGE_SIGN[edge] * xs)


@pytest.fixture(scope="module")
def ode_data():
    return sv.chamber_data()


def test_eq7_all_four_edges_on_integrated_chambers(ode_data):
    t, xc, x, p1, p2, dp1, dp2, v = ode_data
    lake = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc)
    params = sv.params()
    framed = prepare_samples(lake, params)
    pts = opening_area_points(framed, params)
    for edge in ("s1", "1r", "s2", "2r"):
        got = pts.filter(pl.col("edge") == edge, pl.col("u_m") > 0.3e-3)
        assert got.height > 1500, edge
        u = got["u_m"].to_numpy()
        a = got["area_m2"].to_numpy()
        assert (a > 0).all(), edge
        np.testing.assert_allclose(a, sv.TRUTH.area(edge, u), rtol=1e-4, err_msg=edge)


def test_eq7_with_exact_derivatives_is_the_model(ode_data):
    """The same with the ODE's exact derivatives instead of Savitzky–Golay: machine precision."""
    t, xc, x, p1, p2, dp1, dp2, v = ode_data
    frame = sv.lake_frame(t, sv.PS, sv.PR, p1, p2, x, xc).with_columns(
        pl.Series("p1_smooth_pa", p1), pl.Series("p2_smooth_pa", p2),
        pl.Series("dp1_dt_pa_s", dp1), pl.Series("dp2_dt_pa_s", dp2), pl.Series("v_cyl_m_s", v),
        pl.lit(0, dtype=pl.UInt32).alias("window_id"), pl.col("timestamp_utc").min().alias("window_start"),
    )
    pts = opening_area_points(frame, sv.params())
    for edge in ("s1", "1r", "s2", "2r"):
        got = pts.filter(pl.col("edge") == edge, pl.col("u_m") > 1e-6)
        u = got["u_m"].to_numpy()
        np.testing.assert_allclose(got["area_m2"].to_numpy(), sv.TRUTH.area(edge, u), rtol=1e-9, err_msg=edge)

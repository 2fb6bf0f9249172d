"""Step 3: each rule removes what it should, per edge; the counts add up."""

import numpy as np
import polars as pl
import pytest
import synth_valve as sv

from transforms.selection import RULES, add_selection_flags, selection_stats

P = sv.params()


def _rows(**cols) -> pl.DataFrame:
    """A frame of already-derived signals (what step 3 sees), one window."""
    n = len(next(iter(cols.values())))
    base = {
        "valve_id": ["V1"] * n,
        "window_id": pl.Series([0] * n, dtype=pl.UInt32),
        "window_start": pl.Series([0] * n).cast(pl.Datetime("us", "UTC")),
        "window_end": pl.Series([0] * n).cast(pl.Datetime("us", "UTC")),
        "ps_pa": [sv.PS] * n,
        "pr_pa": [sv.PR] * n,
        "p1_smooth_pa": [60e5] * n,
        "p2_smooth_pa": [140e5] * n,
        "x_spool_m": [2e-3] * n,
        "x_cyl_m": [0.3] * n,
        "dp1_dt_pa_s": [0.0] * n,
        "dp2_dt_pa_s": [0.0] * n,
        "v_cyl_m_s": [0.05] * n,
    }
    base.update(cols)
    return pl.DataFrame(base)


def _selected(frame):
    f = add_selection_flags(frame, P)
    return {e: f[f"selected_{e}"].to_list() for e in ("s1", "1r", "s2", "2r")}


def test_sides_of_the_spool():
    lim = max(P.underlap_m) + P.spool_margin_m
    x = [2e-3, lim + 1e-6, lim - 1e-6, 0.0, -(lim - 1e-6), -(lim + 1e-6), -2e-3]
    v = [0.05, 0.05, 0.05, 0.05, -0.05, -0.05, -0.05]
    sel = _selected(_rows(x_spool_m=x, v_cyl_m_s=v))
    assert sel["s1"] == [True, True, False, False, False, False, False]
    assert sel["2r"] == sel["s1"]
    assert sel["1r"] == [False, False, False, False, False, True, True]
    assert sel["s2"] == sel["1r"]


def test_standstill_peaks_small_dp_and_missing():
    rows = _rows(
        v_cyl_m_s=[0.05, 0.004, -0.004, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05],
        dp1_dt_pa_s=[0.0, 0.0, 0.0, 3e9, 0.0, 0.0, 0.0, 0.0, None],
        dp2_dt_pa_s=[0.0, 0.0, 0.0, 0.0, -3e9, 0.0, 0.0, 0.0, 0.0],
        p1_smooth_pa=[60e5, 60e5, 60e5, 60e5, 60e5, sv.PS - 1e5, 60e5, 60e5, 60e5],
        p2_smooth_pa=[140e5, 140e5, 140e5, 140e5, 140e5, 140e5, sv.PR + 1e5, 140e5, 140e5],
    )
    # row 7: compressibility flow on port 1 larger than half the displacement flow
    rows = rows.with_columns(
        pl.when(pl.int_range(pl.len()) == 7)
        .then(0.6 * P.bulk_modulus_pa * P.piston_area_m2 * 0.05 / (P.v01_m3 + P.piston_area_m2 * 0.3))
        .otherwise(pl.col("dp1_dt_pa_s"))
        .alias("dp1_dt_pa_s")
    )
    sel = _selected(rows)
    assert sel["s1"] == [True, False, False, False, False, False, True, False, False]
    # the ratio rule is per port: row 7 is a peak for port 1 (s1) but not for port 2 (2r)
    assert sel["2r"] == [True, False, False, False, False, True, False, True, False]


def test_ratio_rule_per_port_and_threshold():
    v = 0.05
    comp = P.bulk_modulus_pa * P.annulus_area_m2 * v / (P.v02_m3 - P.annulus_area_m2 * 0.3)
    rows = _rows(dp2_dt_pa_s=[0.49 * comp, 0.51 * comp, -0.51 * comp], v_cyl_m_s=[v] * 3)
    sel = _selected(rows)
    assert sel["2r"] == [True, False, False]
    assert sel["s1"] == [True, True, True]


def test_stats_add_up_and_attribute_in_order():
    rng = np.random.default_rng(0)
    n = 2000
    rows = _rows(
        x_spool_m=rng.uniform(-3.5e-3, 3.5e-3, n),
        v_cyl_m_s=rng.normal(0, 0.03, n),
        dp1_dt_pa_s=rng.normal(0, 5e8, n),
        dp2_dt_pa_s=rng.normal(0, 2e8, n),
        p1_smooth_pa=rng.uniform(0, 200e5, n),
        p2_smooth_pa=rng.uniform(0, 200e5, n),
    ).with_columns(pl.when(pl.int_range(pl.len()) < 30).then(None).otherwise(pl.col("v_cyl_m_s")).alias("v_cyl_m_s"))
    flagged = add_selection_flags(rows, P)
    st = selection_stats(flagged)
    assert st.height == 4 * len(RULES)
    assert st["rule"].to_list()[: len(RULES)] == list(RULES)
    for edge in ("s1", "1r", "s2", "2r"):
        e = st.filter(pl.col("edge") == edge)
        n_sel = e["n_selected"][0]
        assert e["n_removed"].sum() + n_sel == n
        assert (e["n_flagged"] >= e["n_removed"]).all()
        assert e.filter(pl.col("rule") == "no_derivative")["n_removed"][0] == 30
        assert n_sel == flagged[f"selected_{edge}"].sum()
        # the first rule's removals equal its flags
        assert e["n_flagged"][0] == e["n_removed"][0]
        # each rule flags something in this random data
        assert (e["n_flagged"] > 0).all()


def test_params_validation():
    with pytest.raises(ValueError):
        sv.params(underlap_m=(1e-5, 1e-5, 1e-5))
    with pytest.raises(ValueError):
        sv.params(underlap_m={"s1": 1e-5, "1r": 1e-5, "s2": 1e-5, "r2": 1e-5})
    with pytest.raises(ValueError):
        sv.params(savgol_window=20)
    p = sv.params(underlap_m={"s1": 1e-5, "1r": 2e-5, "s2": 3e-5, "2r": 4e-5})
    assert p.underlap_m == (1e-5, 2e-5, 3e-5, 4e-5)
    assert p.spool_limit_m("s1") == pytest.approx(3e-5 + 1e-3)  # max(x_1r, x_s2) + margin
    assert p.spool_limit_m("1r") == pytest.approx(4e-5 + 1e-3)  # max(x_s1, x_2r) + margin

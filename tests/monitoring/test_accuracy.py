"""Accuracy of the monitoring (steps 2–4b) on simulated data: Table 1 valves in the closed loop,
recorded through Table 1's sensors (noise 0.05 bar and 1 µm, 16-bit quantisation), 10 s windows.

1. The paper's simulation study (Sec. 4): a commissioning window (step-4a baseline from it), then
   five windows along the wear scenario (model.condition.wear, 0 … 16,700 h): α̂ within 2 % of
   α(t)/α(t0) and x̂ within 0.5 % of x_max of x_u(t) − x_u(t0) on every edge of every window, e
   within a factor 2 of the commissioning window's, on several seeds (each its own valve:
   manufacturing scatter, trajectories, loads, noise).
2. Table 2's broken edge 1r against the nominal baseline, and its healthy twin.
3. The same archive exported long, wide or as Parquet, ingested and monitored through the real
   flows, gives the same edge_fits.

The known problem these tests pin down (docs/monitoring.md, "Accuracy"): points biased by the
closed edge's leakage and a chord-shaped baseline gave x̂ errors up to −0.8 % of x_max in windows
covering only u ≈ 1.04–1.37 mm; :func:`test_narrow_window_unbiased` holds that case.
"""

from __future__ import annotations

from datetime import timedelta

import numpy as np
import polars as pl
import pytest

from model import TABLE1, TrajectoryParams, broken_edge, condition_arrays, condition_at, edge_area, healthy, wear
from model.params import EDGES, SensorChannel, SensorParams
from transforms.baseline import fit_characteristic
from transforms.characteristic import Characteristic
from transforms.monitor import commissioning_baseline, monitor, monitor_points

from .sim_lake import START, simulated_lake, table1_params

X_MAX = TABLE1.geometry.x_max_m
ALPHA_TOL = 0.02
"""|α̂ / α_true − 1| bound (the brief's 2 %)."""
X_TOL = 0.005 * X_MAX
"""|x̂ − x_true| bound: 0.5 % of x_max = 17.5 µm."""
E_FACTOR = 2.0
"""Each window's e within [e0 / 2, 2 e0], e0 the commissioning window's (measured on 30 valves:
0.64–1.44 with the study's windows; 0.44–1.25 with Table 1's default moves, whose narrow windows
leave fewer, quieter points, hence :data:`E_FACTOR_DEFAULT` there)."""
E_FACTOR_DEFAULT = 2.5
HOURS = np.linspace(0.0, 16_700.0, 6)
"""t0 (commissioning) … t5, six equally spaced instants as in the paper's Fig. 5; Table 3's span."""
STUDY_TRAJECTORY = TrajectoryParams(v_extend_m_s=(0.18, 0.24), v_retract_m_s=(0.09, 0.13))
"""Windows like the paper's Sec. 4 ones, which cover the spool range in both directions: the
default moves without their slowest ends (extension 0.14 → 0.18 m/s, retraction 0.07 → 0.09 m/s;
a worn valve needs less stroke for the same speed, and at 0.14 m/s its spool barely passes the
1 mm step-3 margin). With Table 1's default moves see :func:`test_wear_default_trajectories`."""
PARAMS = table1_params()
QUIET = SensorParams(
    ps=SensorChannel(0.0, 0.0, 0.0, 250e5), pr=SensorChannel(0.0, 0.0, 0.0, 25e5),
    p1=SensorChannel(0.0, 0.0, 0.0, 250e5), p2=SensorChannel(0.0, 0.0, 0.0, 250e5),
    x_spool=SensorChannel(0.0, 0.0, -4e-3, 4e-3), x_cyl=SensorChannel(0.0, 0.0, -0.005, 0.615),
    x_ref=SensorChannel(0.0, 0.0, -4e-3, 4e-3),
)  # fmt: skip
"""Sensors without noise or quantisation (to tell bias from noise)."""


def nominal(area_law: str = "eq3") -> dict[str, Characteristic]:
    """α_nominal·A(u) of Eq. 3 (or another edge law) per edge, as
    flows.monitor.flow.nominal_characteristic builds it (0.05 mm grid over [−x_max, x_max + x̂ bound])."""
    g, c = TABLE1.geometry, TABLE1.nominal_condition
    u = np.arange(-X_MAX, X_MAX + PARAMS.x_hat_bound_m + 0.025e-3, 0.05e-3)
    return {
        e: Characteristic.from_arrays(
            u, c.alpha[i] * edge_area(u, c.underlap_m[i], g.taper_angle(e), g.bore_radius_m, g.spool_radius_m, area_law=area_law))
        for i, e in enumerate(EDGES)
    }


NOMINAL = nominal()
LAWS = {"sharp": nominal("sharp")}
"""The edge law the monitor may recognise besides the configured Eq. 3 (as the flows pass it)."""


def _first_windows(lake: pl.DataFrame, n: int) -> pl.DataFrame:
    return lake.filter(pl.col("timestamp_utc") < START + timedelta(hours=n - 1, minutes=30))


def wear_study(seed: int, scatter_seed: int, trajectory=None, sensors=None, geometry=None, commissioning: int = 1,
               params=None) -> pl.DataFrame:
    """Fits of windows t0…t5 against the step-4a baseline of t0, with the true changes;
    ``geometry``: the simulated valve's (another family), the monitor's design data stay Table 1's;
    ``commissioning``: that many 10 s snapshots an hour apart at t0 pooled for the baseline
    (window 0 is the first of them; wear over a few hours is below a nanometre)."""
    params = params or PARAMS
    scenario = wear(scatter_seed=scatter_seed)
    hours = np.concatenate([np.arange(commissioning, dtype=float), HOURS[1:]])
    xu, al = condition_arrays(scenario, hours)
    lake = simulated_lake(condition_at(scenario, hours), seed, trajectory=trajectory, sensors=sensors, geometry=geometry)
    fitted = commissioning_baseline(_first_windows(lake, commissioning), params, NOMINAL, laws=LAWS)
    res = monitor(
        lake, params, {"V1": {e: b.characteristic for e, b in fitted.items()}},
        leakage={"V1": {e: b.leakage for e, b in fitted.items()}},
        leak_scale={"V1": {e: b.leak_scale for e, b in fitted.items()}},
        leak_reference={"V1": {e: b.leak_reference for e, b in fitted.items()}},
    )  # fmt: skip
    w = res.fits["window_id"].to_numpy().astype(int)
    i = np.array([EDGES.index(e) for e in res.fits["edge"]])
    keep = (w == 0) | (w >= commissioning)
    study_w = np.where(w >= commissioning, w - commissioning + 1, 0)
    fits = res.fits.with_columns(pl.Series("window_id", study_w, dtype=pl.UInt32))
    return fits.filter(pl.Series(keep)).with_columns(
        pl.Series("alpha_true", (al[w, i] / al[0, i])[keep]),
        pl.Series("x_true_m", (xu[w, i] - xu[0, i])[keep]),
        pl.lit(seed).alias("seed"),
    ).with_columns(
        (pl.col("alpha_hat") / pl.col("alpha_true") - 1).alias("alpha_err"),
        (pl.col("x_hat_m") - pl.col("x_true_m")).alias("x_err_m"),
        (pl.col("u_max_m") - pl.col("u_min_m")).alias("coverage_m"),
    )


def _e_ratio(fits: pl.DataFrame) -> pl.DataFrame:
    e0 = {r["edge"]: r["e_m2"] for r in fits.filter(pl.col("window_id") == 0).iter_rows(named=True)}
    return fits.filter(pl.col("window_id") > 0).with_columns((pl.col("e_m2") / pl.col("edge").replace_strict(e0)).alias("e_ratio"))


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5, 6])
def test_paper_wear_study(seed):
    """Sec. 4 / Fig. 6: every edge, every window t1…t5 within the bounds; e at a similar level."""
    fits = wear_study(seed, seed, trajectory=STUDY_TRAJECTORY)
    later = _e_ratio(fits)
    assert later.height == 20
    assert (later["status"] == "ok").all(), later.filter(pl.col("status") != "ok").select("window_id", "edge", "status")
    bad = later.filter((pl.col("alpha_err").abs() > ALPHA_TOL) | (pl.col("x_err_m").abs() > X_TOL))
    assert bad.height == 0, bad.select("window_id", "edge", "alpha_err", "x_err_m", "u_min_m", "u_max_m")
    assert later["e_ratio"].is_between(1 / E_FACTOR, E_FACTOR).all(), later.select("window_id", "edge", "e_ratio")
    # the study is a real wear trend: the estimates follow it (x grows 0.13 mm, α 18 %)
    last = later.filter(pl.col("window_id") == 5)
    assert (last["x_hat_m"] > 0.1e-3).all() and (last["alpha_hat"] > 1.12).all()


def test_wear_default_trajectories():
    """Table 1's default moves (slow retractions included) over ten valves: every window/edge
    with an estimate is within the bounds; the others are reported ``too_little_coverage``
    (< 0.25 mm of spool travel), never a wrong estimate, and they are rare."""
    fits = pl.concat([wear_study(s, s) for s in range(1, 10)] + [wear_study(11, 7)])
    later = _e_ratio(fits)
    ok = later.filter(pl.col("status") == "ok")
    bad = ok.filter((pl.col("alpha_err").abs() > ALPHA_TOL) | (pl.col("x_err_m").abs() > X_TOL))
    assert bad.height == 0, bad.select("seed", "window_id", "edge", "alpha_err", "x_err_m", "u_min_m", "u_max_m")
    assert ok["e_ratio"].is_between(1 / E_FACTOR_DEFAULT, E_FACTOR_DEFAULT).all()
    rest = later.filter(pl.col("status") != "ok")
    assert set(rest["status"]) <= {"too_little_coverage"}
    assert (rest["coverage_m"] < PARAMS.min_coverage_m).all()
    assert ok.height >= 0.95 * later.height  # measured on 30 valves: 97 %
    # narrow windows are in the sample and fine: x̂ within the bound with < 0.4 mm of coverage
    assert ok.filter(pl.col("coverage_m") < 0.4e-3).height >= 3


@pytest.mark.parametrize("sensors", [None, QUIET], ids=["recorded", "noiseless"])
def test_narrow_window_unbiased(sensors):
    """The brief's case: seed 11, scatter 7, window t4, edge s2 covers only u ≈ 1.04–1.34 mm.
    With the closed-edge correction following the window's estimates and the nominal-shaped
    baseline x̂ is within 0.2 % of x_max (noiseless too: no bias left); the paper's plain form
    (Eq. 7 without leakage, chord baseline) is off by more than 0.5 % there."""
    fits = wear_study(11, 7, sensors=sensors)
    s2 = fits.filter((pl.col("window_id") == 4) & (pl.col("edge") == "s2")).row(0, named=True)
    assert s2["status"] == "ok" and s2["u_max_m"] - s2["u_min_m"] < 0.35e-3
    assert abs(s2["x_err_m"]) < 0.002 * X_MAX and abs(s2["alpha_err"]) < 0.005

    # the same data the plain way: this is the bias the defaults remove
    scenario = wear(scatter_seed=7)
    xu, al = condition_arrays(scenario, HOURS)
    lake = simulated_lake(condition_at(scenario, HOURS), 11, sensors=sensors)
    pts = monitor_points(_first_windows(lake, 1), PARAMS).points
    base = {}
    for e in EDGES:
        p = pts.filter(pl.col("edge") == e)
        base[e] = fit_characteristic(p["u_m"], p["area_m2"], max_knots=PARAMS.max_knots)
    plain = monitor(lake, PARAMS, {"V1": base}).fits.filter((pl.col("window_id") == 4) & (pl.col("edge") == "s2")).row(0, named=True)
    i = EDGES.index("s2")
    assert plain["x_hat_m"] - (xu[4, i] - xu[0, i]) < -0.005 * X_MAX


def _twins(seed: int, n_windows: int = 3):
    """Table 2's faulty valve (edge 1r: α ×2.5, underlap +0.413 mm) and its healthy twin: same
    manufacturing scatter, same trajectories, loads and noise draws."""
    out = {}
    hours = np.arange(n_windows, dtype=float)
    for name, scenario in (("broken", broken_edge(scatter_seed=seed)), ("healthy", healthy(scatter_seed=seed))):
        xu, al = condition_arrays(scenario, hours)
        lake = simulated_lake(condition_at(scenario, hours), seed)
        res = monitor(lake, PARAMS, {"V1": NOMINAL}, leakage={"V1": NOMINAL})  # nominal baseline (paper Sec. 5.1)
        i = np.array([EDGES.index(e) for e in res.fits["edge"]])
        w = res.fits["window_id"].to_numpy().astype(int)
        fits = res.fits.with_columns(
            pl.Series("alpha_true", al[w, i] / TABLE1.nominal_condition.alpha[0]),
            pl.Series("x_true_m", xu[w, i] - TABLE1.nominal_condition.underlap_m[0]),
        )
        out[name] = (fits, commissioning_baseline(lake, PARAMS, NOMINAL))
    return out


@pytest.mark.parametrize("seed", [1, 3, 7])
def test_table2_broken_edge(seed):
    """Sec. 5.1 / Table 2 with the nominal baseline: edge 1r estimated near its truth (α̂ ≈ 2.5,
    x̂ ≈ 11.8 % x_max, within the same bounds as the wear study, coverage often only up to
    ~1.4 mm), its step-4a characteristic fails the plausibility check; the healthy twin passes
    and is estimated near its own (scatter) truth."""
    twins = _twins(seed)
    for name, (fits, _) in twins.items():
        ok = fits.filter(pl.col("status") == "ok")
        assert ok.filter(pl.col("edge") == "1r").height >= 2, (name, fits.select("window_id", "edge", "status"))
        err_a = (ok["alpha_hat"] / ok["alpha_true"] - 1).abs()
        err_x = (ok["x_hat_m"] - ok["x_true_m"]).abs()
        assert (err_a <= ALPHA_TOL).all() and (err_x <= X_TOL).all(), (name, ok.select("window_id", "edge", "alpha_hat", "alpha_true", "x_hat_m", "x_true_m"))
    broken = twins["broken"][0].filter((pl.col("edge") == "1r") & (pl.col("status") == "ok"))
    assert broken["alpha_hat"].is_between(2.3, 2.7).all()  # 2.5 × the valve's α scatter
    assert (broken["x_hat_m"] / X_MAX).is_between(0.112, 0.124).all()  # 11.8 % ± scatter and error
    healthy_1r = twins["healthy"][0].filter((pl.col("edge") == "1r") & (pl.col("status") == "ok"))
    assert broken["e_m2"].mean() > 2 * healthy_1r["e_m2"].mean()  # Table 2: e rises with the fault

    b = twins["broken"][1]
    assert b["1r"].plausibility is not None and not b["1r"].plausibility.ok
    reasons = " ".join(b["1r"].plausibility.reasons)
    assert "value scale" in reasons and "shift" in reasons
    assert b["1r"].alpha_vs_nominal > 2.2 and 0.38e-3 < b["1r"].x_vs_nominal_m < 0.45e-3
    h = twins["healthy"][1]
    assert all(h[e].plausibility is not None and h[e].plausibility.ok for e in EDGES), {e: h[e].plausibility for e in EDGES}


# --------------------------------------------------------------------------------------------
# 3. long, wide, Parquet: the same fits through the real flows
# --------------------------------------------------------------------------------------------


def test_export_formats_give_identical_fits(tmp_path):
    """2 valves × 4 windows (wear, broken 1r), ~11 s: CSV holds each tag at its sensor step's
    decimals, Parquet the same values as doubles, so the lake and the fits agree."""
    from flows.common.warehouse_db import connect, query_frame
    from flows.ingest.flow import run_ingest
    from flows.monitor.flow import run_monitor
    from flows.simulate.archive import SimulateRequest, run_simulate

    fits = {}
    for fmt in ("long", "wide", "parquet"):
        sim = tmp_path / f"sim_{fmt}"
        run_simulate(
            SimulateRequest(out=sim, n_valves=2, hours="12", windows_per_day=8, format=fmt, seed=5, workers=0,
                            scenarios=("V001=wear", "V002=broken_edge")),
            show_progress=False,
        )  # fmt: skip
        wh = tmp_path / f"wh_{fmt}"
        run_ingest(sim / "plant.toml", [sim / "exports"], wh)
        reports = run_monitor(sim / "plant.toml", wh)
        assert sum(r.windows for r in reports) == 8
        with connect(wh) as con:
            fits[fmt] = query_frame(con, "SELECT * EXCLUDE (monitored_at) FROM edge_fits ORDER BY valve_id, edge, window_start")
    ref = fits["parquet"]
    assert ref.height == 2 * 4 * 4 and (ref["status"] == "ok").sum() >= 24
    for fmt in ("long", "wide"):
        other = fits[fmt]
        assert other.select(pl.exclude(pl.Float64)).equals(ref.select(pl.exclude(pl.Float64))), fmt
        for c in [c for c, t in ref.schema.items() if t == pl.Float64]:
            np.testing.assert_allclose(other[c].to_numpy(), ref[c].to_numpy(), rtol=1e-9, atol=1e-12, equal_nan=True, err_msg=f"{fmt}: {c}")

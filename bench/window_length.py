"""How long a monitoring window must be: α̂, x̂, e against the window length on continuous
recordings (docs/monitoring.md, "Continuous recordings").

Each valve is a Table 1 positioning unit in the closed loop (``model``), recorded back to back
through Table 1's sensors for ``--duration-s`` (default 1200 s: a 20-min recording), in the
wear scenario at ``--hours`` with its own manufacturing scatter; fitted against the nominal
characteristic (paper Sec. 5.1), so the truth is α(t)/α_nominal and x_u(t) − x_u,nominal per edge.
The recording is cut into windows of each length (``transforms.windows``) and monitored
(``transforms.monitor.monitor`` with the closed-edge leakage correction). Per length:

* the share of window-edges with status ``ok``, the median and 5 % quantile of the points per
  window-edge and the median 95 % confidence half-widths of α̂ and x̂ (% of x_max);
* the worst |α̂ error| (%) and |x̂ error| (% of x_max) of the ok ones (the study's bounds: 2 %,
  0.5 %);
* the window-to-window scatter (standard deviation per valve and edge, then the median over them)
  of α̂, x̂ (% of x_max) and e (mm²), to set against the condition bounds' ``*_sigma_floor``
  (0.02, 0.30 %, 0.03 mm²): the change detection never takes the scale below those floors, so a
  window whose own scatter is well inside them does not turn noise into alarms.

    .venv/bin/python bench/window_length.py [--valves 6] [--duration-s 1200] [--lengths 10,20,30,60,120,300]
        [--window-rows none,6000]   # also with long windows evaluated on every k-th row ([monitor] window_rows)
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
from pathlib import Path

import numpy as np
import polars as pl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from model import TABLE1, condition_arrays, condition_at, wear  # noqa: E402
from model.params import EDGES  # noqa: E402
from tests.monitoring.sim_lake import simulated_lake, table1_params  # noqa: E402
from tests.monitoring.test_accuracy import NOMINAL  # noqa: E402
from transforms.monitor import monitor  # noqa: E402

X_MAX = TABLE1.geometry.x_max_m


def valve_fits(seed: int, hours: float, duration_s: float, lengths: list[float], window_rows: list[int | None] = (None,)) -> pl.DataFrame:
    scenario = wear(scatter_seed=seed)
    xu, al = condition_arrays(scenario, np.array([hours]))
    lake = simulated_lake(condition_at(scenario, np.array([hours])), seed, duration_s=duration_s)
    nom = TABLE1.nominal_condition
    out = []
    for length, rows in itertools.product(lengths, window_rows):
        params = dataclasses.replace(table1_params(), window_s=length, window_rows=rows)
        fits = monitor(lake, params, {"V1": NOMINAL}, leakage={"V1": NOMINAL}).fits
        i = np.array([EDGES.index(e) for e in fits["edge"]])
        out.append(fits.with_columns(
            pl.lit(length).alias("length_s"), pl.lit(rows or 0).alias("window_rows"), pl.lit(seed).alias("seed"),
            (pl.col("alpha_hat") / pl.Series(al[0, i] / np.array(nom.alpha)[i]) - 1).alias("alpha_err"),
            ((pl.col("x_hat_m") - pl.Series(xu[0, i] - np.array(nom.underlap_m)[i])) / X_MAX * 100).alias("x_err_pct"),
            (pl.col("x_hat_m") / X_MAX * 100).alias("x_hat_pct"), (pl.col("e_m2") * 1e6).alias("e_mm2"),
        ))  # fmt: skip
    return pl.concat(out)


def summary(fits: pl.DataFrame) -> pl.DataFrame:
    ok = fits.filter(pl.col("status") == "ok")
    spread = (
        ok.group_by("length_s", "window_rows", "seed", "edge")
        .agg(pl.col("alpha_hat").std().alias("sd_alpha"), pl.col("x_hat_pct").std().alias("sd_x_pct"), pl.col("e_mm2").std().alias("sd_e_mm2"))
        .group_by("length_s", "window_rows")
        .agg(pl.col("sd_alpha", "sd_x_pct", "sd_e_mm2").median())
    )
    worst = ok.group_by("length_s", "window_rows").agg(
        (pl.col("alpha_err").abs().max() * 100).alias("worst_alpha_err_pct"), pl.col("x_err_pct").abs().max().alias("worst_x_err_pct_xmax"),
    )
    counts = fits.group_by("length_s", "window_rows").agg(
        pl.len().alias("window_edges"), (pl.col("status") == "ok").mean().alias("ok_share"), pl.col("n_points").median().alias("median_points"),
        pl.col("n_points").quantile(0.05).alias("p05_points"),
        ((pl.col("alpha_ci_high") - pl.col("alpha_ci_low")) / 2).median().alias("ci_alpha"),
        ((pl.col("x_hat_ci_high_m") - pl.col("x_hat_ci_low_m")) / 2 / X_MAX * 100).median().alias("ci_x_pct"),
    )
    keys = ["length_s", "window_rows"]
    return counts.join(worst, on=keys).join(spread, on=keys).sort(keys)


def per_edge_scatter(fits: pl.DataFrame) -> pl.DataFrame:
    """Per length and edge: the window-to-window standard deviation of α̂, x̂ (% of x_max) and e
    (mm²) about each valve's own mean, pooled over the valves, and the largest |deviation| in
    those standard deviations (how heavy the tails are)."""
    params = ("alpha_hat", "x_hat_pct", "e_mm2")
    dev = fits.filter(pl.col("status") == "ok").with_columns(
        (pl.col(p) - pl.col(p).mean().over("length_s", "window_rows", "seed", "edge")).alias(f"d_{p}") for p in params
    )
    return (
        dev.group_by("length_s", "window_rows", "edge")
        .agg(pl.len().alias("windows"),
             *[(pl.col(f"d_{p}") ** 2).mean().sqrt().alias(f"sd_{p}") for p in params],
             *[(pl.col(f"d_{p}").abs().max() / (pl.col(f"d_{p}") ** 2).mean().sqrt()).alias(f"max_dev_sd_{p}") for p in params])
        .sort("length_s", "window_rows", "edge")
    )  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--valves", type=int, default=6)
    ap.add_argument("--duration-s", type=float, default=1200.0)
    ap.add_argument("--hours", type=float, default=8000.0)
    ap.add_argument("--lengths", default="10,20,30,60,120,300")
    ap.add_argument("--window-rows", default="none",
                    help="comma-separated [monitor] window_rows to compare (none: every row; window_rows 0 in the table)")
    ap.add_argument("--per-edge", action="store_true", help="also the scatter per edge (sd over valves' ok windows, pooled) and the largest |deviation| / sd")
    a = ap.parse_args()
    lengths = [float(x) for x in a.lengths.split(",")]
    rows = [None if r.strip().lower() == "none" else int(r) for r in a.window_rows.split(",")]
    fits = pl.concat([valve_fits(s, a.hours, a.duration_s, lengths, rows) for s in range(1, a.valves + 1)])
    with pl.Config(tbl_rows=50, tbl_cols=20, tbl_width_chars=250, float_precision=4):
        print(summary(fits))
        if a.per_edge:
            with pl.Config(float_precision=6):
                print(per_edge_scatter(fits))


if __name__ == "__main__":
    main()

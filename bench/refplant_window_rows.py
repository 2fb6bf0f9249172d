"""Every k-th row against every row on the second reference plant's continuous recordings.

``[monitor] window_rows`` (every 10th row of a 60 s window at 1 kHz) was measured on ``model``'s
plant (``bench/window_length.py``). This runs the same comparison on the reference plant written
apart from it (``tests/refplant``): for each edge family and seed, a manufactured valve on that
family is commissioned from six 10 s snapshots (as ``tests/monitoring/shift_study.refplant_study``),
then one continuous recording of ``--duration-s`` of it, worn by a known shift and α factor on
every edge, is cut into 60 s windows and monitored twice, every row and every k-th row, against
the commissioning baselines. Per family and setting: the ok window-edges, the worst |α̂ error|
(%) and |x̂ error| (% of x_max) against the truth (the accuracy study's bars: 2 %, 0.5 %), the
window-to-window scatter of α̂ and x̂, and the largest difference between the two settings'
estimates of the same window-edge; and whether a thinned setting keeps the every-row verdicts:
``ok_lost`` (ok at every row, not ok thinned), ``ok_gained`` (the reverse) and ``outside_ci``
(α̂ or x̂ of an ok window-edge outside the every-row 95 % interval).

``--operation sparse`` runs the valve as a positioning cylinder on a mill (dwells of 2–10 s between
moves, ``tests/refplant`` ``sparse``); ``--sensors noisy_end`` or ``plant_grade`` records its
positions as plants do.

    .venv/bin/python bench/refplant_window_rows.py [--seeds 1,2] [--laws eq3,sharp,linear] [--duration-s 300]
        [--operation busy|sparse] [--sensors default|noisy_end|plant_grade] [--out FITS.parquet]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import polars as pl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests import refplant as rp  # noqa: E402
from tests.monitoring.shift_study import fits_against_truth  # noqa: E402
from tests.monitoring.sim_lake import START  # noqa: E402
from tests.monitoring.test_accuracy import LAWS, NOMINAL, PARAMS  # noqa: E402
from transforms.monitor import commissioning_baseline  # noqa: E402

X_MAX = PARAMS.x_max_m
SHIFT_M, ALPHA = 0.1e-3, 0.95
"""The wear of every edge in the recording, against the commissioning state."""


SENSORS = {"default": lambda p, seed: p, "noisy_end": lambda p, seed: rp.noisy_end(p), "plant_grade": rp.plant_grade}


def valve_fits(law: str, seed: int, duration_s: float, window_rows: list[int | None], operation: str = "busy",
               sensors: str = "default") -> pl.DataFrame:
    base = SENSORS[sensors](rp.family(rp.manufactured(rp.NAMEPLATE, seed=seed), law), seed)
    comm = rp.to_lake_frame(rp.simulate_windows(base, 6, seed), "V1", START)  # commissioning: busy moves
    fitted = commissioning_baseline(comm, PARAMS, NOMINAL, laws=LAWS)
    plant = rp.sparse(base) if operation == "sparse" else base
    rec = rp.simulate(rp.worn(plant, alpha_scale=(ALPHA,) * 4, underlap_shift_m=(SHIFT_M,) * 4), duration_s, seed * 1000 + 777)
    lake = rp.to_lake_frame(rec, "V1", START)
    out = []
    for rows in window_rows:
        params = dataclasses.replace(PARAMS, window_s=60.0, window_rows=rows)
        n = lake.height  # every window carries the same wear: one (shift, α) pair per window
        fits = fits_against_truth(lake, fitted, [(SHIFT_M, ALPHA)] * n, params).filter(pl.col("window_id") > 0)
        out.append(fits.with_columns(pl.lit(law).alias("law"), pl.lit(seed).alias("seed"), pl.lit(rows or 0).alias("window_rows")))
    return pl.concat(out, how="diagonal_relaxed")


def summary(fits: pl.DataFrame) -> pl.DataFrame:
    ok = fits.filter(pl.col("status") == "ok")
    keys = ["law", "window_rows"]
    spread = (ok.group_by(*keys, "seed", "edge").agg(pl.col("alpha_hat").std().alias("sd_alpha"),
                                                      (pl.col("x_hat_m").std() / X_MAX * 100).alias("sd_x_pct"))
              .group_by(keys).agg(pl.col("sd_alpha", "sd_x_pct").median()))  # fmt: skip
    worst = fits.group_by(keys).agg(
        pl.len().alias("window_edges"), (pl.col("status") == "ok").sum().alias("ok"), pl.col("n_points").median().alias("median_points"),
        (pl.col("alpha_err").filter(pl.col("status") == "ok").abs().max() * 100).alias("worst_alpha_err_pct"),
        (pl.col("x_err_m").filter(pl.col("status") == "ok").abs().max() / X_MAX * 100).alias("worst_x_err_pct_xmax"),
    )  # fmt: skip
    every = fits.filter(pl.col("window_rows") == 0).select(
        "law", "seed", "window_id", "edge", pl.col("alpha_hat").alias("a0"), pl.col("x_hat_m").alias("x0"),
        (pl.col("status") == "ok").alias("ok0"), "alpha_ci_low", "alpha_ci_high", "x_hat_ci_low_m", "x_hat_ci_high_m",
    )  # fmt: skip
    ok = pl.col("status") == "ok"
    outside = ~pl.col("alpha_hat").is_between("alpha_ci_low_right", "alpha_ci_high_right") | ~pl.col("x_hat_m").is_between(
        "x_hat_ci_low_m_right", "x_hat_ci_high_m_right")  # fmt: skip
    diff = (fits.join(every, on=["law", "seed", "window_id", "edge"])
            .group_by(keys).agg(((pl.col("alpha_hat") - pl.col("a0")).abs().max() * 100).alias("max_diff_alpha_pct"),
                                ((pl.col("x_hat_m") - pl.col("x0")).abs().max() / X_MAX * 100).alias("max_diff_x_pct_xmax"),
                                (pl.col("ok0") & ~ok).sum().alias("ok_lost"), (~pl.col("ok0") & ok).sum().alias("ok_gained"),
                                (pl.col("ok0") & ok & outside).sum().alias("outside_ci")))  # fmt: skip
    return worst.join(spread, on=keys).join(diff, on=keys).sort(keys)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--laws", default="eq3,sharp,linear")
    ap.add_argument("--duration-s", type=float, default=300.0)
    ap.add_argument("--window-rows", default="none,6000", help="comma-separated window_rows (none: every row; 0 in the table)")
    ap.add_argument("--operation", choices=("busy", "sparse"), default="busy")
    ap.add_argument("--sensors", choices=tuple(SENSORS), default="default")
    ap.add_argument("--out", help="write every window-edge to this Parquet file")
    a = ap.parse_args()
    rows = [None if r.strip().lower() == "none" else int(r) for r in a.window_rows.split(",")]
    fits = pl.concat([valve_fits(law, int(s), a.duration_s, rows, a.operation, a.sensors) for law in a.laws.split(",")
                      for s in a.seeds.split(",")], how="diagonal_relaxed")  # fmt: skip
    if a.out:
        fits.write_parquet(a.out)
    with pl.Config(tbl_rows=50, tbl_cols=20, tbl_width_chars=250, float_precision=4):
        print(summary(fits))


if __name__ == "__main__":
    main()

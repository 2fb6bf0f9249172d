"""x̂ against known shifts on the second reference plant (``tests/refplant``, written apart from
``model/``): the shift study of ``bench/xhat_families.py`` on its edge families.

Per family (``--families``, of the reference plant's Eq. 3, sharp and linear-gradient edges) and
valve (``--seeds``: the plant's manufactured valve, its underlap and α scatter and β 2.5 % off the
nameplate): ``--commissioning`` 10 s snapshots of the new valve (the baseline), then one 10 s
window per (shift, α) pair, every edge shifted and scaled; the monitor configured with Table 1's
design data (Eq. 3). The reference plant's own choices stay on: continuous PI, Karnopp sticking,
ramped load steps, 1 ms transmitter lag and the pressures one sample late. ``--noiseless``: its
acquisition without noise or quantisation.

    .venv/bin/python bench/xhat_refplant.py [--seeds 1] [--families eq3,sharp,linear]
        [--shifts-mm 0.03,0.06] [--alphas 1.0,1.15] [--noiseless] [--out FILE.parquet]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np
import polars as pl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from model.params import EDGES  # noqa: E402
from tests.monitoring.shift_study import refplant_study  # noqa: E402
from tests.monitoring.test_accuracy import X_MAX  # noqa: E402

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--families", default="eq3,sharp,linear")
    ap.add_argument("--shifts-mm", default="0.03,0.06")
    ap.add_argument("--alphas", default="1.0,1.15")
    ap.add_argument("--commissioning", type=int, default=6)
    ap.add_argument("--noiseless", action="store_true")
    ap.add_argument("--out")
    args = ap.parse_args()
    lo, _, hi = args.seeds.partition("-")
    seeds = range(int(lo), int(hi or lo) + 1)
    shifts = [float(v) * 1e-3 for v in args.shifts_mm.split(",")]
    alphas = [float(v) for v in args.alphas.split(",")]
    t0 = time.process_time()
    pairs = list(itertools.product(shifts, alphas))
    parts = [refplant_study(f, s, pairs, commissioning=args.commissioning, noiseless=args.noiseless)
             .with_columns(pl.lit(f).alias("family"), pl.lit(s).alias("seed"))
             for f in args.families.split(",") for s in seeds]  # fmt: skip
    allf = pl.concat(parts, how="diagonal_relaxed")
    if args.out:
        allf.write_parquet(args.out)
    print(f"{'family':7} {'edge':4} {'ok':>6} {'worst x̂ err/shift':>17} {'worst x̂ % x_max':>16} {'worst α̂ %':>10} "
          f"{'leak_scale max (ci_low max)':>27} {'commissioning: law, leak':>24}")
    for f in args.families.split(","):
        for e in EDGES:
            d = allf.filter((pl.col("family") == f) & (pl.col("edge") == e))
            w = d.filter(pl.col("window_id") > 0)
            ok = w.filter(pl.col("status") == "ok")
            moved = ok.filter(pl.col("x_true_m") > 0)
            rel = (moved["x_err_m"] / moved["x_true_m"]).to_numpy()
            worst = rel[np.argmax(np.abs(rel))] if rel.size else np.nan
            c = d.filter(pl.col("window_id") == 0)
            print(f"{f:7} {e:4} {ok.height:2d}/{w.height:<3d} {worst:+17.1%} {ok['x_err_m'].abs().max() / X_MAX:16.3%} "
                  f"{ok['alpha_err'].abs().max():10.3%} {ok['leak_scale'].max():16.2f} ({ok['leak_scale_ci_low'].max():.2f})"
                  f"    {c['edge_law'][0]:>6} {c['leak_scale_baseline'].median():5.2f}")
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()

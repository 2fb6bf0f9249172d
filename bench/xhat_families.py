"""x̂ against the true shift on every valve family: a sweep of shift × α per family and edge.

Per family and valve (``--seeds``, each with its manufacturing scatter): a commissioning period
of ``--commissioning`` 10 s snapshots of the new valve (the step-4a baseline, the leakage
identified), then one window of ``--duration-s`` per (shift, α) of the sweep, every edge shifted
by the shift (its underlap grown) and its α scaled by the factor. The monitor's design data are
Table 1's (Eq. 3) whatever the family, as in the accuracy study. The two ports have their own
area gradients (port 1: s1, 1r; port 2: s2, 2r), so the rows per edge are the sweep over the
gradient. ``--noiseless``: sensors without noise or quantisation (bias alone).

``--plant model`` (default): ``model/``'s closed loop, families of ``model.params.GEOMETRY_FAMILIES``
(default Eq. 3, sharp, worn lands ×3, linear gradient). ``--plant refplant``: the second reference
plant (``tests/refplant``, written apart from ``model/``: its own dynamics, loads and transmitters;
families eq3, sharp, linear, laminar; 10 s windows); ``--ideal-transmitters``: its pressures without
their 1 ms lag and one sample of skew.

Printed per family and edge: the worst and the median x̂ error as a fraction of the true shift
(shifts > 0), the worst |x̂ error| in % of x_max (every shift, 0 included) — over the windows whose
x̂ the fit calls determined (``x_hat_determined``), with the worst of the others after the slash
("-": none) —, the worst |α̂ error| (%),
the identified ``leak_scale`` of the edge in the windows that resolved it (median; the largest
lower bound of its 95 % interval; how many windows held the commissioning's, ``leak_scale_held``)
and at commissioning, and the edge law step 4a recognised.

    .venv/bin/python bench/xhat_families.py [--plant model|refplant] [--seeds 1-2]
        [--families eq3,sharp,worn3,linear] [--shifts-mm 0,0.03,0.06,0.1] [--alphas 0.9,1.0,1.15,1.2]
        [--duration-s 10] [--noiseless] [--ideal-transmitters] [--out FILE.parquet]
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

from model import TABLE1  # noqa: E402
from model.params import EDGES, GEOMETRY_FAMILIES  # noqa: E402
from tests.monitoring import test_accuracy as study  # noqa: E402
from tests.monitoring.shift_study import refplant_study, shift_study  # noqa: E402


def _list(spec: str, kind=float) -> list:
    return [kind(v) for v in spec.split(",") if v]


def _seeds(spec: str) -> list[int]:
    lo, _, hi = spec.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def _resolved(fits: pl.DataFrame) -> pl.DataFrame:
    return fits.filter(~pl.col("leak_scale_held"))


def _nan(v) -> float:
    return float("nan") if v is None else v


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plant", choices=("model", "refplant"), default="model")
    ap.add_argument("--seeds", default="1-2")
    ap.add_argument("--families", help="default: eq3,sharp,worn3,linear (model), eq3,sharp,linear,laminar (refplant)")
    ap.add_argument("--shifts-mm", default="0,0.03,0.06,0.1")
    ap.add_argument("--alphas", default="0.9,1.0,1.15,1.2")
    ap.add_argument("--duration-s", type=float, default=10.0, help="window length (model plant)")
    ap.add_argument("--commissioning", type=int, default=6)
    ap.add_argument("--noiseless", action="store_true")
    ap.add_argument("--ideal-transmitters", action="store_true", help="refplant: pressures without lag and skew")
    ap.add_argument("--out", help="write every window-edge to this Parquet file")
    args = ap.parse_args()
    families = _list(args.families or ("eq3,sharp,worn3,linear" if args.plant == "model" else "eq3,sharp,linear,laminar"), str)
    shifts = [s * 1e-3 for s in _list(args.shifts_mm)]
    alphas = _list(args.alphas)
    t0 = time.process_time()
    rows = []
    for fam in families:
        for seed in _seeds(args.seeds):
            if args.plant == "model":
                fits = shift_study(GEOMETRY_FAMILIES[fam], seed, shifts, alphas, duration_s=args.duration_s,
                                   commissioning=args.commissioning, sensors=study.QUIET if args.noiseless else None)
            else:
                fits = refplant_study(fam, seed, list(itertools.product(shifts, alphas)), commissioning=args.commissioning,
                                      noiseless=args.noiseless, ideal_transmitters=args.ideal_transmitters)
            rows.append(fits.with_columns(pl.lit(fam).alias("family"), pl.lit(seed).alias("seed")))
    allf = pl.concat(rows, how="diagonal_relaxed")
    if args.out:
        allf.write_parquet(args.out)
    x_max = TABLE1.geometry.x_max_m
    print(f"{'family':7} {'edge':4} {'ok':>7} {'worst x̂ err/shift (not det.)':>28} {'median':>7} {'worst x̂ % x_max':>16} "
          f"{'worst α̂ %':>10} {'leak_scale resolved (ci_low max) held / commissioning':>54} {'edge law':>8}")
    for fam in families:
        for e in EDGES:
            d = allf.filter((pl.col("family") == fam) & (pl.col("edge") == e))
            every = d.filter((pl.col("window_id") > 0) & (pl.col("status") == "ok"))
            ok, und = every.filter(pl.col("x_hat_determined")), every.filter(~pl.col("x_hat_determined"))
            moved = ok.filter(pl.col("x_true_m") > 0)
            und_rel = (und["x_err_m"] / und["x_true_m"]).filter(und["x_true_m"] > 0).abs().max()
            rel = (moved["x_err_m"] / moved["x_true_m"]).to_numpy()
            worst = rel[np.argmax(np.abs(rel))] if rel.size else np.nan
            c = d.filter(pl.col("window_id") == 0)
            print(f"{fam:7} {e:4} {ok.height:3d}/{d.height - c.height:<3d} {worst:+9.1%} / {'-' if und_rel is None else f'{und_rel:.1%}':>6} {np.median(rel):+7.1%} "
                  f"{ok['x_err_m'].abs().max() / x_max:16.3%} {every['alpha_err'].abs().max():10.3%} "
                  f"{_nan(_resolved(every)['leak_scale'].median()):31.2f} ({_nan(_resolved(every)['leak_scale_ci_low'].max()):.2f}) "
                  f"{every['leak_scale_held'].sum():3d} / "
                  f"{c['leak_scale_baseline'].median():.2f} {c['edge_law'][0]:>8}")
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()

"""Accuracy of the monitor on three valve families, with the closed-edge leakage identified
(the defaults) or Eq. 3's assumed (docs/monitoring.md, "Closed-edge leakage identified").

The paper's Sec. 4 study (``tests/monitoring/test_accuracy.py``: Table 1 valves in the closed loop
through Table 1's sensors, the wear scenario with each valve's manufacturing scatter, the study's
trajectories) with a commissioning period of ``--commissioning`` 10 s snapshots (default 6) and the
five windows at 3,340 … 16,700 h, for each family of ``model.area``:

* ``eq3``: the paper's valve;
* ``sharp``: sharp edges, no closed-edge leakage;
* ``worn3``, ``worn4``: Eq. 3 with worn lands, ``leakage_factor`` 3 and 4 (2.2–2.7× and
  2.6–3.3× Eq. 3's leakage 1–2 mm inside the edge).

The monitor's design data are Table 1's whatever the family. Per family: the worst |α̂ error| (%)
and |x̂ error| (% of x_max) over all valves, windows t1…t5 and edges (all ``ok``), and the median
identified leakage ``leak_scale`` of s2's closed edge 2r at commissioning. ``--assume-eq3``: the
method before issue 16 (Eq. 3's leakage, λ = 1, never identified).

    .venv/bin/python bench/leakage_families.py [--seeds 1-6] [--commissioning 6] [--assume-eq3]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import polars as pl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from model.params import GEOMETRY_FAMILIES  # noqa: E402
from tests.monitoring import test_accuracy as study  # noqa: E402


def _seeds(spec: str) -> list[int]:
    lo, _, hi = spec.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-6", help="valves (seed = scatter seed), e.g. 1-6")
    ap.add_argument("--commissioning", type=int, default=6, help="10 s snapshots pooled for the baseline")
    ap.add_argument("--assume-eq3", action="store_true", help="Eq. 3's leakage, not identified (the method before)")
    args = ap.parse_args()
    params = study.PARAMS
    if args.assume_eq3:
        params = dataclasses.replace(params, leak_min_points=10**12)
    print(f"{'family':8} {'window-edges':>12} {'ok':>4} {'worst α̂ %':>10} {'worst x̂ % x_max':>16} {'2r leak (t1…t5)':>16}")
    for name, geometry in GEOMETRY_FAMILIES.items():
        fits = pl.concat([
            study.wear_study(s, s, trajectory=study.STUDY_TRAJECTORY, geometry=geometry, commissioning=args.commissioning, params=params)
            for s in _seeds(args.seeds)
        ]).filter(pl.col("window_id") > 0)  # fmt: skip
        ok = fits.filter(pl.col("status") == "ok")
        a = ok["alpha_err"].abs().max() * 100
        x = ok["x_err_m"].abs().max() / study.X_MAX * 100
        leak = ok.filter(pl.col("edge") == "2r")["leak_scale"].median()
        print(f"{name:8} {fits.height:12d} {ok.height:4d} {a:10.3f} {x:16.3f} {leak:16.2f}")


if __name__ == "__main__":
    main()

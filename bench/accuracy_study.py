"""The accuracy study's figures (docs/monitoring.md, "Accuracy on simulated data"): worst |α̂ error| (%)
and |x̂ error| (% of x_max) per edge over the wear study's windows t1…t5 with status ``ok``.

``tests/monitoring/test_accuracy.py``'s wear study (Table 1 valves, its sensors, the wear scenario
with each valve's manufacturing scatter, one 10 s commissioning snapshot), on 31 valves with Table
1's default moves (seeds 1–30 and seed 11 / scatter 7) and 30 with the study's trajectories.

    .venv/bin/python bench/accuracy_study.py
"""

from __future__ import annotations

import resource
import sys
from pathlib import Path

import polars as pl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.monitoring import test_accuracy as study  # noqa: E402


def main() -> None:
    runs = {
        "default moves": [(s, s, None) for s in range(1, 31)] + [(11, 7, None)],
        "study trajectories": [(s, s, study.STUDY_TRAJECTORY) for s in range(1, 31)],
    }
    for name, cases in runs.items():
        fits = pl.concat([study.wear_study(seed, scatter, trajectory=t) for seed, scatter, t in cases]).filter(pl.col("window_id") > 0)
        ok = fits.filter(pl.col("status") == "ok")
        print(f"{name}: {ok.height} of {fits.height} window-edges ok; worst |α̂ error| % / |x̂ error| % of x_max")
        for e in ("s1", "1r", "s2", "2r"):
            d = ok.filter(pl.col("edge") == e)
            print(f"  {e}  {d['alpha_err'].abs().max() * 100:.2f} % / {d['x_err_m'].abs().max() / study.X_MAX * 100:.2f} %")
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(f"CPU {ru.ru_utime + ru.ru_stime:.0f} s")


if __name__ == "__main__":
    main()

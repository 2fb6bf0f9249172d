"""Speed of the discrepancy workflow's core (:func:`transforms.discrepancy.pipeline.diagnose`, steps
1–4) on N records of 10 s (Table 1 valve, an internal leak hidden), one core, after a warm-up run
that loads the compiled kernels.

    .venv/bin/python bench/discrepancy_speed.py --records 4 12 48
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from model import TABLE1  # noqa: E402
from model.effects import Effects  # noqa: E402
from tests.discrepancy.simdata import simulate_lake  # noqa: E402
from transforms.discrepancy import DiscrepancySettings, split_records  # noqa: E402
from transforms.discrepancy.pipeline import diagnose  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--records", nargs="*", type=int, default=[4, 12, 48])
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    s = DiscrepancySettings(max_records=max(args.records))
    fx = Effects(internal_leakage_m3_s_pa=1e-12)
    diagnose(split_records(simulate_lake(fx, n_windows=2, seed=0), s), TABLE1, settings=s)  # warm-up
    print("| records (10 s each) | steps 1–3 (s, best) | with step 4 (s, best) | per record (s) |")
    print("|---|---|---|---|")
    for n in args.records:
        recs_lake = simulate_lake(fx, n_windows=n, seed=1)
        best = {False: float("inf"), True: float("inf")}
        for _ in range(args.repeats):
            for mon in (False, True):
                recs = split_records(recs_lake, s)
                t, c = time.perf_counter(), time.process_time()
                diagnose(recs, TABLE1, settings=s, monitoring=mon)
                best[mon] = min(best[mon], time.process_time() - c)
        print(f"| {n} | {best[False]:.1f} | {best[True]:.1f} | {best[True] / n:.2f} |", flush=True)


if __name__ == "__main__":
    main()

"""The load estimate on the second reference plant (``tests/refplant``: loads ramping to a new level
every 1–4 s): per seed and 10 s window of the robustness study's clean valve, the load error on the
samples at speed and the mechanical replay's gap (X on the recorded pressures,
``transforms.discrepancy.gaps``) with the estimated load against the same replay with the plant's
true load (``tests.discrepancy.refplant_load.window_figures``). The model is Table 1's with the
reference plant's true cylinder (mass, friction), so what is left is the load estimate's.

    taskset -c 0 .venv/bin/python bench/refplant_load.py --seeds 5

Prints one line per window and the CPU seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--windows", type=int, default=2)
    a = ap.parse_args(argv)
    from tests.discrepancy.refplant_load import window_figures

    t0 = time.process_time()
    for seed in range(a.seeds):
        for r in window_figures(seed, a.windows):
            print(f"seed {r['seed']} window {r['window']}: load ({r['load']}) off by {r['load_error_n']:.0f} N RMS at speed; "
                  f"mechanical gap {r['mechanical_gap_mm']:.3f} mm, with the true load {r['true_load_gap_mm']:.3f} mm", flush=True)
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()

"""The load estimate on the second reference plant (``tests/refplant``: loads ramping to a new level
every 1–4 s): per seed and 10 s window of the robustness study's clean valve, the load error on the
samples at speed and the mechanical replay's gap (X on the recorded pressures,
``transforms.discrepancy.gaps``) with the estimated load against the same replay with the plant's
true load (``tests.discrepancy.refplant_load.window_figures``). The model is Table 1's with the
reference plant's true cylinder (mass, friction), so what is left is the load estimate's.
With ``--commissioning`` the model is instead the study's commissioning calibration
(``bench/discrepancy_robustness.py: commissioning_model``, on the same load interval), and the same
again with its viscous friction d_v set to the plant's: what the calibrated d_v alone leaves.

    taskset -c 0 .venv/bin/python bench/refplant_load.py --seeds 5 [--load-interval-s 1,1] [--commissioning]

Prints one line per window (the velocity and mass parts are what the load estimate leaves
proportional to v_X and to the acceleration: a friction and mass mismatch of the model, or load
error that follows the motion; the mechanical replay moves the model's friction and mass by them,
within 1 % and 2 %, so the force it takes for the load is the load plus those parts times v_X and
the acceleration) and the CPU seconds.
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
    ap.add_argument("--commissioning", action="store_true", help="diagnose with the study's commissioning calibration (and with its d_v set to the plant's)")
    ap.add_argument("--load-interval-s", default=None, help="range of the load's intervals between new levels [s], e.g. 1,1 (default: the plant's 1-4 s)")
    a = ap.parse_args(argv)
    from dataclasses import replace

    from bench.discrepancy_robustness import commissioning_model
    from tests.discrepancy.refplant_load import window_figures
    from tests.refplant import NAMEPLATE, manufactured

    interval = tuple(float(v) for v in a.load_interval_s.split(",")) if a.load_interval_s else None
    t0 = time.process_time()
    for seed in range(a.seeds):
        models = {"true cylinder": None}
        if a.commissioning:
            cp, cc = commissioning_model(seed, a.windows, "eq3", "nameplate", "ref", interval)
            d_v = manufactured(NAMEPLATE, seed=seed).cylinder.d_v_n_s_m
            models = {f"commissioning (d_v {cp.cylinder.d_v_n_s_m:.0f} N s/m)": (cp, cc),
                      f"commissioning, d_v the plant's {d_v:.0f} N s/m": (replace(cp, cylinder=replace(cp.cylinder, d_v_n_s_m=d_v)), cc)}
        for name, model in models.items():
            for r in window_figures(seed, a.windows, load_interval_s=interval, model=model):
                print(f"seed {r['seed']} window {r['window']}, {name}: load ({r['load']}) off by {r['load_error_n']:.0f} N RMS at speed, "
                      f"velocity part {r['velocity_part_n_s_m']:.0f} N s/m, mass part {r['mass_part_kg']:.0f} kg, the force the replay takes off by {r['replayed_force_error_n']:.0f} N; "
                      f"mechanical gap {r['mechanical_gap_mm']:.3f} mm, with the true load {r['true_load_gap_mm']:.3f} mm", flush=True)
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()

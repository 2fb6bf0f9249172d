"""The load estimate on the second reference plant (``tests/refplant``: loads ramping to a new level
every 1–4 s): per seed and 10 s window of the robustness study's clean valve, the load error on the
samples at speed and the mechanical replay's gap (X on the recorded pressures,
``transforms.discrepancy.gaps``) with the estimated load against the same replay with the plant's
true load. The model is Table 1's with the reference plant's true cylinder (mass, friction), so
what is left is the load estimate's.

    taskset -c 0 .venv/bin/python bench/refplant_load.py --seeds 5

Prints one line per window and the CPU seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def window_figures(seed: int, n_windows: int) -> list[dict]:
    """Per window: load error at speed [N], mechanical gap with the estimate and the true load [mm]."""
    from model import TABLE1
    from model.effects import Effects
    from transforms.discrepancy import DiscrepancySettings, split_records
    from transforms.discrepancy.alignment import align_records
    from transforms.discrepancy.rows import _replay_record, prepare_records

    from bench.discrepancy_robustness import ref_lake
    from tests.refplant import NAMEPLATE, manufactured, simulate_windows

    s = DiscrepancySettings()
    truth = simulate_windows(manufactured(NAMEPLATE, seed=seed), n_windows, 100 + seed)
    tc = truth[0].plant.cylinder
    plant = replace(TABLE1, cylinder=replace(TABLE1.cylinder, mass_kg=tc.mass_kg, d_v_n_s_m=tc.d_v_n_s_m, d_c_n=tc.d_c_n, d_s_n=tc.d_s_n, v0_m_s=tc.v0_m_s))
    cond = plant.nominal_condition
    recs, _ = align_records(split_records(ref_lake(None, None, seed, 100 + seed, n_windows), s), plant, cond, s)
    fx = Effects()
    key = (plant, cond, fx)
    out = []
    for i, (p, r) in enumerate(zip(prepare_records(recs, plant, cond, s), truth)):
        est = p.loads[key]
        true_load = r.true["F_l"][:p.rec.n].astype(float)
        gaps = []
        for load in (est, replace(est, load=true_load, hold_until=0)):
            p.loads[key] = load
            e = _replay_record(p, plant, cond, fx, s)["X_mechanical"] - p.rec.raw["X"]
            gaps.append(float(np.sqrt(np.nanmean(e ** 2))) * 1e3)
        at_speed = est.usable
        out.append({"seed": seed, "window": i, "load": "ramps" if est.knot_samples else "constant",
                    "load_error_n": float(np.sqrt(np.mean((est.load[at_speed] - true_load[at_speed]) ** 2))),
                    "mechanical_gap_mm": gaps[0], "true_load_gap_mm": gaps[1]})
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--windows", type=int, default=2)
    a = ap.parse_args(argv)
    t0 = time.process_time()
    for seed in range(a.seeds):
        for r in window_figures(seed, a.windows):
            print(f"seed {r['seed']} window {r['window']}: load ({r['load']}) off by {r['load_error_n']:.0f} N RMS at speed; "
                  f"mechanical gap {r['mechanical_gap_mm']:.3f} mm, with the true load {r['true_load_gap_mm']:.3f} mm", flush=True)
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()

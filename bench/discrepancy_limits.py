"""Detection limits of the discrepancy workflow: for each library effect, the smallest magnitude
that is still named first, reliably.

For every effect and magnitude (a geometric series down from the library's typical magnitude)
and every seed, a valve with Table 1's nominal condition is simulated in-process with that effect
hidden (``--windows`` hourly windows of 10 s, recorded through the sensor models, seeds 0 …
``--seeds``−1), and :func:`transforms.discrepancy.pipeline.diagnose` (step 4 off) is run on it. A run
*detects* the effect if the effect is named first; it *recovers* it if, in addition, the fitted
parameter is within ``--tolerance`` (relative) of the truth. The table gives, per effect, the
smallest magnitude from which on every seed is detected and recovered at that and every larger
magnitude of the series, and what was named instead below it. The null case (no effect) is run
on the same seeds.

    .venv/bin/python bench/discrepancy_limits.py --seeds 5 --windows 4

Prints a Markdown table (``docs/discrepancy.md``, "Detection limits").
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from model import TABLE1  # noqa: E402
from model.effects import EFFECT_LIBRARY  # noqa: E402
from tests.discrepancy.simdata import simulate_lake  # noqa: E402
from transforms.discrepancy import DiscrepancySettings, split_records  # noqa: E402
from transforms.discrepancy.pipeline import diagnose  # noqa: E402

FRACTIONS = (1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001)
"""Magnitudes as fractions of the library's typical magnitude (gains: of |gain − 1|)."""


def run_one(spec, value, seed, windows):
    fx = None if spec is None else spec.effects(value)
    lake = simulate_lake(fx, n_windows=windows, seed=seed)
    s = DiscrepancySettings()
    d = diagnose(split_records(lake, s), TABLE1, settings=s, monitoring=False)
    first = d.named[0] if d.named else None
    return first


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--windows", type=int, default=4)
    ap.add_argument("--tolerance", type=float, default=0.2)
    ap.add_argument("--effects", nargs="*", default=None, help="library keys (default all)")
    ap.add_argument("--fractions", nargs="*", type=float, default=list(FRACTIONS))
    args = ap.parse_args()
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    t_start = time.time()
    specs = [s for s in EFFECT_LIBRARY if args.effects is None or s.key in args.effects]
    null_named = []
    for seed in range(args.seeds):
        first = run_one(None, 0.0, seed, args.windows)
        if first is not None:
            null_named.append((seed, first.spec.key))
    print(f"null case: {args.seeds - len(null_named)}/{args.seeds} seeds named nothing {null_named or ''}", flush=True)
    rows = []
    for spec in specs:
        results = {}
        for frac in sorted(args.fractions, reverse=True):
            mag = frac * spec.typical
            value = spec.neutral + mag
            ok, named_instead, errs = 0, [], []
            for seed in range(args.seeds):
                first = run_one(spec, value, seed, args.windows)
                if first is not None and first.spec.key == spec.key:
                    err = abs(first.value - value) / mag
                    errs.append(err)
                    if err <= args.tolerance:
                        ok += 1
                    else:
                        named_instead.append(f"{spec.key} off by {err:.0%}")
                else:
                    named_instead.append(first.spec.key if first else "none")
            results[frac] = (ok, named_instead, max(errs) if errs else float("nan"))
            print(f"  {spec.key:28s} {spec.parameter_name}={value:.6g} {spec.unit}: {ok}/{args.seeds}"
                  f" max rel err {results[frac][2]:.3f} {named_instead}", flush=True)
        limit = None
        for frac in sorted(args.fractions, reverse=True):
            if results[frac][0] == args.seeds:
                limit = frac
            else:
                break
        below = None
        if limit is not None:
            smaller = [f for f in sorted(args.fractions, reverse=True) if f < limit]
            if smaller:
                below = results[smaller[0]]
        rows.append((spec, limit, results, below))
    print(f"\n{len(specs)} effects x {len(args.fractions)} magnitudes x {args.seeds} seeds, "
          f"{args.windows} windows of 10 s each, in {time.time() - t_start:.0f} s\n")
    print("| effect | parameter | smallest \\|parameter − neutral\\| named first in every seed | max rel. error there | next smaller magnitude: named first |")
    print("|---|---|---|---|---|")
    for spec, limit, results, below in rows:
        if limit is None:
            print(f"| {spec.key} | {spec.parameter_name} [{spec.unit}] | not reliable at {spec.typical:.3g} | | |")
            continue
        mag = limit * spec.typical
        nxt = "—" if below is None else f"{below[0]}/{args.seeds} (else {', '.join(sorted(set(below[1]))) or '—'})"
        print(f"| {spec.key} | {spec.parameter_name} [{spec.unit}] | {mag:.3g} | {results[limit][2]:.1%} | {nxt} |")


if __name__ == "__main__":
    main()

"""COMTRADE reading: valvemon's streaming reader against the ``comtrade`` package (PyPI 0.2.0).

Writes one recording (``--seconds`` at ``--rate`` Hz, 8 analog channels of which 6 are the plant's
and 2 digital channels) as a BINARY and an ASCII ``.dat``, then reads each in a fresh process,
pinned to one core by the caller (``taskset -c 1``), with

- ``valvemon``: ``flows.ingest.formats.open_export`` + ``iload`` (the frames the ingest gets:
  UTC times, scaled values; batches of ``BATCH_SAMPLES``), the frames dropped as they come;
- ``comtrade``: ``comtrade.load(cfg, dat, use_numpy_arrays=True)`` (the whole file into arrays,
  times as float seconds from the start).

and prints CPU seconds (user + sys) and the peak resident memory (``VmHWM``) per process. The
``comtrade`` package is not a dependency: install it into a scratch folder and pass
``PYTHONPATH`` (``pip download --no-deps comtrade==0.2.0`` and unzip the wheel).

    taskset -c 1 .venv/bin/python bench/comtrade.py --seconds 3600 --rate 1000
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import json, resource, sys, time
sys.path.insert(0, {root!r})
which, cfg = sys.argv[1], sys.argv[2]
start = resource.getrusage(resource.RUSAGE_SELF)
if which == "valvemon":
    from flows.common.config import load_plant_config
    from flows.ingest.formats import iload, open_export
    config = load_plant_config(sys.argv[3])
    src = open_export(cfg, config.export, config.timezone)
    rows = sum(b.frame.height for b in iload(src, config.export))
else:
    import comtrade
    rows = comtrade.load(cfg, cfg[:-4] + ".dat", use_numpy_arrays=True).total_samples
end = resource.getrusage(resource.RUSAGE_SELF)
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
print(json.dumps({{"rows": rows, "cpu_s": end.ru_utime + end.ru_stime - start.ru_utime - start.ru_stime, "peak_mb": hwm / 1024}}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3600.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from tests.ingest.comtrade_files import RAW_DTYPE, Analog, Recording, write_comtrade
    from tests.ingest.conftest import write_plant

    n = int(args.seconds * args.rate)
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        plant = write_plant(folder, layout="wide", timestamp_column="Time", tag_column=None, value_column=None, quality_column=None, good_quality=None, sample_rate_hz=args.rate, max_gap_s=5 / args.rate)
        tags = ["MILL1.V017.PS", "MILL1.V017.PR", "MILL1.V017.P1", "MILL1.V017.P2", "MILL1.V017.XS", "MILL1.V017.XC", "OTHER.IA", "OTHER.IB"]
        for ft in ("BINARY", "ASCII"):
            raw = [rng.integers(0, 20000, n).astype(RAW_DTYPE[ft]) for _ in tags]
            rec = Recording([Analog(t, "mm" if t[-2:] in ("XS", "XC") else "bar" if t.startswith("MILL") else "A", r, 0.01) for t, r in zip(tags, raw)], [("CB OPEN", np.zeros(n, dtype=np.int64)), ("TRIP", np.zeros(n, dtype=np.int64))], rate_hz=args.rate)
            cfg = write_comtrade(folder / f"rec_{ft}.cfg", rec, ft)
            mb = cfg.with_suffix(".dat").stat().st_size / 1e6
            for which in ("valvemon", "comtrade"):
                out = subprocess.run([sys.executable, "-c", CHILD.format(root=str(ROOT)), which, str(cfg), str(plant)], capture_output=True, text=True, env=dict(os.environ, POLARS_MAX_THREADS="1"))
                if out.returncode:
                    print(f"{ft:<7} {which:<9} failed: {out.stderr.strip().splitlines()[-1]}")
                    continue
                r = json.loads(out.stdout.splitlines()[-1])
                print(f"{ft:<7} {mb:>8.1f} MB {n:>11,} samples  {which:<9} CPU {r['cpu_s']:>7.2f} s  peak {r['peak_mb']:>7.0f} MB")


if __name__ == "__main__":
    main()

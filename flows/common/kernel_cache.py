"""``python -m flows.common.kernel_cache snapshot|continuous``: numba's kernel cache, filled at set-up.

numba compiles a kernel on its first call in a process and keeps the machine code in the
``__pycache__`` beside its source (``cache=True``); later processes load it in milliseconds. On a
fresh install the first calls cost ~90 s of CPU in all: the first ``valvemon`` commands would pay
them, and each worker of a test run the kernels it calls. ``make setup`` pays them here instead, on a
tiny simulated plant run through the pipeline's own functions in a temporary directory, so that
every kernel is compiled for the argument types the pipeline passes it:

* ``snapshot``: two valves' snapshot windows (Parquet) ingested, monitored and checked for
  standstill; one window in each text and TDMS format, ingested;
* ``continuous``: a continuous recording ingested and monitored, then the discrepancy workflow
  on it, with both positions reconstructed.

The two parts run side by side (``make -j2``). Nothing outside the temporary directory is written
but numba's cache (and matplotlib's font cache, on its first use).
"""

from __future__ import annotations

import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path


def _archive(out: Path, **kw):
    from flows.simulate.archive import SimulateRequest, run_simulate

    run_simulate(SimulateRequest(out=out, seed=5, workers=0, **kw), show_progress=False)
    return out / "plant.toml", out / "exports"


def snapshot(root: Path) -> None:
    """Snapshot windows in every export format through ingest, monitoring and the standstill check."""
    from flows.common.config import load_plant_config
    from flows.ingest.flow import run_ingest
    from flows.monitor.flow import run_monitor
    from flows.report.flow import update_standstill

    cfg, exports = _archive(root / "parquet", n_valves=2, days=1.0, windows_per_day=4, format="parquet")
    run_ingest(cfg, [exports], root / "wh")
    run_monitor(cfg, root / "wh")
    update_standstill(load_plant_config(cfg), root / "wh", datetime.now(timezone.utc))
    for fmt in ("long", "wide", "ascii", "tdms"):
        cfg, exports = _archive(root / fmt, n_valves=1, days=1.0, windows_per_day=1, format=fmt)
        run_ingest(cfg, [exports], root / f"wh-{fmt}")


def continuous(root: Path) -> None:
    """A continuous recording through ingest and monitoring, then the discrepancy workflow."""
    from flows.common.config import load_plant_config
    from flows.discrepancy.flow import discrepancy_valve
    from flows.ingest.flow import run_ingest
    from flows.monitor.flow import run_monitor
    from transforms.discrepancy.settings import DiscrepancySettings

    cfg, exports = _archive(root / "sim", n_valves=1, start="2025-01-01T00:00:00Z", end="2025-01-01T00:00:20Z", recording="continuous", file_minutes=1.0, format="parquet")
    run_ingest(cfg, [exports], root / "wh")
    run_monitor(cfg, root / "wh")
    config = load_plant_config(cfg)
    settings = DiscrepancySettings(reconstruct_spool=True, reconstruct_cylinder=True, max_records=1)
    discrepancy_valve(config, config.valves[0].id, root / "wh", None, None, settings, "design")


PARTS = {"snapshot": snapshot, "continuous": continuous}
"""The parts by name, in the order ``make setup`` names them."""


def main(argv: list[str]) -> int:
    parts = argv or list(PARTS)
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        print(f"kernel_cache: unknown part {unknown[0]!r}; the parts are {', '.join(PARTS)}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="valvemon-kernels-") as tmp:
        for part in parts:
            PARTS[part](Path(tmp) / part)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

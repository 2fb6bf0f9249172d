"""Benchmark of lake rows → opening-area points → fits (transforms.monitor) on one core.

Simulates a batch of 10 s windows (healthy, worn and broken-1r valves mixed, recorded through
the sensor models), lays them out as a lake frame of one valve (hourly windows), builds the
nominal characteristic (701 grid points) or a commissioning fit (step 4a on the first window,
at most 12 knots) as baseline, runs :func:`transforms.monitor.monitor` once to warm up (numba
cache, polars), then times it ``--repeats`` times and prints lake rows per second of process
CPU time (median and best of the repeats; on a shared machine the best is the one least
disturbed by other processes) and of wall clock, with the split into steps 2–3 + Eq. 7 (points
and selection counts) and step 4b (fits). Polars and numba are limited to one thread and the
process is pinned to one CPU where the OS allows it.

    .venv/bin/python bench/monitor_throughput.py [--windows 100] [--duration 10] [--repeats 7]
        [--baseline nominal|commissioning] [--engine numba|polars] [--no-leakage]

By default the closed-edge leakage correction runs as in production (flows/monitor/flow.py): the
nominal characteristic as each edge's baseline-state leakage, one refinement pass.
"""

from __future__ import annotations

import os

os.environ.setdefault("POLARS_MAX_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import polars as pl  # noqa: E402

from model import BROKEN_1R, TABLE1, WEAR, condition_at, simulate_windows  # noqa: E402
from model.area import edge_area  # noqa: E402
from model.params import EDGES  # noqa: E402
from model.sensors import measure  # noqa: E402
from transforms.baseline import fit_characteristic  # noqa: E402
from transforms.characteristic import Characteristic  # noqa: E402
from transforms.fit import fit_windows  # noqa: E402
from transforms.monitor import monitor, monitor_points  # noqa: E402
from transforms.params import MonitorParams  # noqa: E402


def conditions(n: int):
    out = []
    for i in range(n):
        kind = i % 3
        if kind == 0:
            out.append(TABLE1.nominal_condition)
        elif kind == 1:
            out += condition_at(WEAR, [20000.0 * i / n])
        else:
            out += condition_at(BROKEN_1R, [0.0])
    return out


def lake_frame(n_windows: int, duration_s: float, seed: int) -> pl.DataFrame:
    res = simulate_windows(TABLE1, conditions(n_windows), duration_s, seed)
    m = measure(res, TABLE1.sensors, np.random.default_rng(seed))
    t0 = int(datetime(2025, 3, 1, tzinfo=timezone.utc).timestamp() * 1e6)
    hour = 3_600_000_000
    ts = (t0 + np.arange(res.n_windows)[:, None] * hour + np.round(m.t_s * 1e6).astype(np.int64)).ravel()
    n = ts.shape[0]
    return pl.DataFrame({
        "valve_id": pl.Series(["V001"] * n, dtype=pl.Utf8),
        "timestamp_utc": pl.Series(ts).cast(pl.Datetime("us", "UTC")),
        "ps_pa": m.ps.ravel(), "pr_pa": m.pr.ravel(), "p1_pa": m.p1.ravel(), "p2_pa": m.p2.ravel(),
        "x_spool_m": m.x_spool.ravel(), "x_cyl_m": m.x_cyl.ravel(),
    })


def params() -> MonitorParams:
    c, g = TABLE1.cylinder, TABLE1.geometry
    return MonitorParams(
        piston_area_m2=c.A1, annulus_area_m2=c.A2, v01_m3=c.v01_m3, v02_m3=c.v02_m3,
        bulk_modulus_pa=TABLE1.fluid.bulk_modulus_pa, density_kg_m3=TABLE1.fluid.density_kg_m3,
        underlap_m=TABLE1.nominal_condition.underlap_m, x_max_m=g.x_max_m,
    )


def nominal() -> dict[str, Characteristic]:
    g, cond = TABLE1.geometry, TABLE1.nominal_condition
    u = np.linspace(-g.x_max_m, g.x_max_m, 701)
    xl = cond.x_l_m(g)
    return {
        e: Characteristic.from_arrays(
            u, cond.alpha[i] * edge_area(u, cond.underlap_m[i], g.taper_angle(e), g.bore_radius_m, g.spool_radius_m, xl[i])
        )
        for i, e in enumerate(EDGES)
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=100)
    ap.add_argument("--duration", type=float, default=10.0, help="window length [s]")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--baseline", choices=("nominal", "commissioning"), default="nominal")
    ap.add_argument("--engine", choices=("numba", "polars"), default="numba")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    ap.add_argument("--no-leakage", action="store_true", help="without the closed-edge leakage correction")
    a = ap.parse_args(argv)

    pinned = "no"
    if hasattr(os, "sched_setaffinity") and not a.no_pin:
        cpu = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {cpu})
        pinned = f"cpu {cpu}"

    t = time.perf_counter()
    lake = lake_frame(a.windows, a.duration, a.seed)
    t_sim = time.perf_counter() - t
    p = params()
    if a.baseline == "nominal":
        base = {"V001": nominal()}
    else:
        first = lake.head(int(a.duration * 1000))
        pts = monitor_points(first, p).points
        base = {"V001": {}}
        for e in EDGES:
            d = pts.filter(pl.col("edge") == e)
            base["V001"][e] = fit_characteristic(d["u_m"], d["area_m2"], max_knots=p.max_knots)
    leak = None if a.no_leakage else {"V001": nominal()}
    res = monitor(lake, p, base, engine=a.engine, leakage=leak)  # warm-up (numba cache load/compile)

    wall, cpu, cpu_pts, cpu_fit = [], [], [], []
    for _ in range(a.repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        res = monitor(lake, p, base, engine=a.engine, leakage=leak)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
        c0 = time.process_time()
        pts = monitor_points(lake, p, engine=a.engine)
        cpu_pts.append(time.process_time() - c0)
        c0 = time.process_time()
        fit_windows(pts.points, base, {"V001": p}, windows=pts.windows)
        cpu_fit.append(time.process_time() - c0)

    rows = lake.height
    npts = res.points.height
    ok = (res.fits["status"] == "ok").sum()
    med, best = statistics.median(cpu), min(cpu)
    print(f"lake rows            {rows:,} ({a.windows} windows x {a.duration:g} s at 1 kHz; simulated in {t_sim:.1f} s)")
    print(f"points               {npts:,} ({npts / rows:.2f} per row); fits {res.fits.height} rows, {ok} ok")
    print(f"baseline, engine     {a.baseline}, {a.engine}, leakage {'off' if leak is None else 'on'}")
    print(f"threads              polars {pl.thread_pool_size()}, pinned: {pinned}, load average {os.getloadavg()[0]:.1f}")
    print(f"monitor() CPU        median {med * 1e3:7.1f} ms, best {best * 1e3:7.1f} ms  ({a.repeats} repeats)")
    print(f"monitor() wall       median {statistics.median(wall) * 1e3:7.1f} ms")
    print(f"  points + selection best {min(cpu_pts) * 1e3:7.1f} ms CPU  ({rows / min(cpu_pts) / 1e6:.2f} M rows/s)")
    print(f"  fits (fit_windows) best {min(cpu_fit) * 1e3:7.1f} ms CPU  ({npts / min(cpu_fit) / 1e6:.2f} M points/s)")
    print(f"throughput           {rows / med / 1e6:.2f} M rows/s CPU (median), {rows / best / 1e6:.2f} M rows/s CPU (best), "
          f"{rows / statistics.median(wall) / 1e6:.2f} M rows/s wall (median)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

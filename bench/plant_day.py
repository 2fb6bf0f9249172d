"""The nightly path on one simulated valve-day of continuous recording, step by step, on one core.

Runs what a plant runs every night — ``valvemon ingest`` of the day's exports, ``monitor``,
``report``, ``retention`` — each step as its own command (start-up included) pinned to one CPU
(``taskset -c``), and prints per step the CPU seconds (user + system of the command, from
``wait4``), wall seconds, peak RSS, lake rows per CPU second, and the extrapolation to a plant of
500 continuously recorded valves (core-hours a day: 500 × the valve-day's CPU; the goal is ≤ 3).

    # the valve-day (once; ~24 files of an hour, 86.4 M lake rows)
    valvemon simulate --out DAY --n-valves 1 --recording continuous --days 1 --format parquet \\
        --layout wide --scenario wear --quiet --workers 0
    # the path on it, with this tree's code and, for a before/after in one run, another tree
    .venv/bin/python bench/plant_day.py --day DAY --work DIR [--code before=TREE] [--code after=.]

``--code LABEL=TREE`` (repeat; default: this tree) runs the commands with ``PYTHONPATH=TREE`` (a
``git archive`` of another commit, say), so two versions of the code are measured on the same
files in one run, one whole path after the other (``--rounds`` N: N times, alternating;
``--ingest-once``: the later codes get a copy of the first one's ingested warehouse, for codes
whose ingest is the same). Before the measured runs each code runs the whole path once on the
first 45 minutes of the same recording (``--warm-minutes``, 0: no warm-up; more than the monitor
reads at once, so that its chunked reads compile the same kernel signatures), so that the numba
kernels are in that tree's cache, as a nightly run finds them. ``--hours N`` takes the first N
files and scales the sum to a day (linearly, start-up counted each time: an upper bound).
``--steps ingest`` (a comma-separated list) runs only those steps. With the ingest, each round also
runs the anchor, polars' bare streaming copy of the same files (:data:`POLARS_COPY`), pinned and
measured alike, and prints the ingest ÷ copy ratio (the goal: ≤ 1.2). ``--duckdb`` adds, each round,
DuckDB's bare ``COPY`` of the same files into a partitioned Parquet lake (one thread, no
validation; :data:`DUCKDB_COPY`), pinned and measured alike, and prints the ingest ÷ DuckDB ratio:

    .venv/bin/python bench/plant_day.py --day DAY --work DIR --code before=BEFORE --code after=AFTER \
        --steps ingest --duckdb --warm-minutes 5

The retention step thins the valve-day (``[retention] keep_days = 1``, ``mode = "thin"``,
``--as-of`` two days after it), as it would once the day is older than the plant's ``keep_days``.

A plant runs each command once a night for all its valves: start-up, the report's pictures (of
the :data:`~flows.report.flow.DETAIL_VALVES` most urgent valves and the fleet) and its HTML are
paid once, not once a valve. ``--fleet K`` measures that split: after the rounds above it builds
the same day as K valves (each hour file holding the valve-day's columns K times, under K valves'
tags, as a recorder writes a line's valves into one file; the plant configuration with K copies
of the valve) and runs the whole path on it, ``--rounds`` times. Per step, a valve's share is
(K valves − 1 valve) / (K − 1) and the night's fixed part is 1 valve − that share; the night of
:data:`VALVES` valves is fixed + 500 × share:

    .venv/bin/python bench/plant_day.py --day DAY --work DIR --fleet 2 --rounds 2

The machine is shared: read CPU seconds, not wall seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from datetime import date, timedelta
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STEPS = ("ingest", "monitor", "report", "retention")
VALVES = 500
GOAL_CORE_H = 3.0
VALVE_DAY_ROWS = 86_400_000
"""A valve-day at 1 kHz."""


DUCKDB_COPY = """
import sys, duckdb
out, files = sys.argv[1], sys.argv[2:]
con = duckdb.connect()
con.execute("SET threads = 1")
listed = ", ".join(f"'{f}'" for f in files)
con.execute(
    f"COPY (SELECT 'V001' AS valve_id, CAST(timestamp AS DATE) AS date, * FROM read_parquet([{listed}])) "
    f"TO '{out}' (FORMAT parquet, PARTITION_BY (valve_id, date))"
)
"""
"""DuckDB's bare copy of the exports into a partitioned Parquet lake (one thread, its defaults:
snappy, the columns as they are): no validation, no grid, no units, no manifest."""

POLARS_COPY = """
import os, sys, tomllib
os.environ["POLARS_MAX_THREADS"] = "1"
import polars as pl
from pathlib import Path
SI = {"bar": 1e5, "mm": 1e-3, "Pa": 1.0, "m": 1.0}
COLUMN = {"ps": "ps_pa", "pr": "pr_pa", "p1": "p1_pa", "p2": "p2_pa", "x_spool": "x_spool_m", "x_cyl": "x_cyl_m", "x_ref": "x_ref_m"}
config, out, files = tomllib.loads(Path(sys.argv[1]).read_text()), Path(sys.argv[2]), sys.argv[3:]
valve = config["valves"][0]
t = pl.col(config["export"]["timestamp_column"])
out.mkdir(parents=True, exist_ok=True)
TEXT = {"decimal_comma": config["export"].get("decimal", ".") == ",", "separator": config["export"].get("separator", ",")}
for i, f in enumerate(files):
    if f.endswith(".parquet"):
        scan, when = pl.scan_parquet(f), t
    else:  # polars' own streaming read of the text: ISO-8601 times parsed, the values as Float64
        scan = pl.scan_csv(f, schema_overrides={config["export"]["timestamp_column"]: pl.String}, **TEXT)
        when = t.str.to_datetime(time_unit="us", time_zone="UTC")
    scan.select(
        pl.lit(valve["id"]).alias("valve_id"), when.dt.date().alias("date"), when.alias("timestamp_utc"),
        *[(pl.col(tag["tag"]) * SI[tag["unit"]]).cast(pl.Float32).alias(COLUMN[s]) for s, tag in valve["tags"].items()],
    ).sink_parquet(out / f"part-{i:02d}.parquet", compression="uncompressed")
"""
"""polars' bare streaming copy of each wide export (Parquet, or CSV with ISO-8601 times) into a lake
file (one thread): scan, scale to SI, cast to float32, sink uncompressed (the lake's codec); no
validation, no grid, no manifest. The
anchor of the issue's "ingest within 1.2x of a bare streaming copy"."""


def run_step(code: Path, cpu: int, argv: list[str], log: Path, script: str | None = None) -> dict:
    """One ``valvemon`` command (or the Python ``script`` with ``argv``) with ``PYTHONPATH=code``,
    pinned to ``cpu``: wall, CPU, peak RSS. The command is the tree's installed entry point
    (``flows.cli.console``, or ``main`` in trees from before it existed)."""
    env = dict(os.environ, PYTHONPATH=str(code), POLARS_MAX_THREADS="1", NUMBA_NUM_THREADS="1")
    script = script or "import sys, flows.cli as c; sys.argv[0] = 'valvemon'; getattr(c, 'console', c.main)()"
    cmd = ["taskset", "-c", str(cpu), sys.executable, "-c", script, *argv]
    t0 = time.perf_counter()
    with log.open("a") as out:
        out.write("$ " + " ".join(argv) + "\n")
        out.flush()
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, cwd=code)
        _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"{' '.join(argv[:1])} failed with status {status}; see {log}")
    return {"cpu_s": ru.ru_utime + ru.ru_stime, "wall_s": wall, "rss_mb": ru.ru_maxrss / 1024}


def plant_with_retention(config: Path, out: Path) -> Path:
    """The plant configuration with ``[retention] keep_days = 1`` (thin)."""
    text = config.read_text()
    if "[retention]" not in text:
        text += '\n[retention]\nkeep_days = 1\nmode = "thin"\nthin_keep_s_per_hour = 10\n'
    out.write_text(text)
    tomllib.loads(text)
    return out


def fleet_day(config: Path, files: list[Path], k: int, out: Path) -> tuple[Path, list[Path]]:
    """The day as ``k`` valves into ``out``: the plant configuration with ``k`` copies of its one
    valve (ids ``<id>-<i>``, tags renamed alike) and each Parquet hour file with the valve's columns
    ``k`` times under those tags (the same samples: the work, not the estimates, is measured)."""
    import pyarrow.parquet as pq  # noqa: PLC0415 - only the fleet's files need them
    import tomli_w  # noqa: PLC0415

    plant = tomllib.loads(config.read_text())
    (valve,) = plant["valves"]
    tags = {t["tag"] for t in valve["tags"].values()}

    def renamed(name: str, i: int) -> str:  # valve i's name of the valve's id or tag (valve 0: the valve itself)
        return name if i == 0 else name.replace(valve["id"], f"{valve['id']}-{i}")

    copies = [valve | {"id": renamed(valve["id"], i), "tags": {s: t | {"tag": renamed(t["tag"], i)} for s, t in valve["tags"].items()}}
              for i in range(k)]
    out.mkdir(parents=True, exist_ok=True)
    fleet_config = out / "plant.toml"
    fleet_config.write_text(tomli_w.dumps(plant | {"valves": copies}))
    fleet_files = []
    for f in files:
        if f.suffix != ".parquet":
            raise SystemExit("--fleet: Parquet exports only")
        source = pq.ParquetFile(f)
        table = source.read()
        extra = [(renamed(c, i), table[c]) for i in range(1, k) for c in table.column_names if c in tags]
        for name, column in extra:
            table = table.append_column(name, column)
        # as the recorder wrote the valve's file: its codec and row groups (the ingest reads a row group at a time)
        meta = source.metadata
        pq.write_table(table, out / f.name, compression=meta.row_group(0).column(0).compression.lower(),
                       row_group_size=meta.row_group(0).num_rows)
        fleet_files.append(out / f.name)
        del table, extra
    return fleet_config, fleet_files


def export_rows(files: list[Path]) -> int:
    """Rows of the wide exports (one per instant: the lake rows they make; a CSV's lines after its header)."""
    import pyarrow.parquet as pq  # noqa: PLC0415

    def lines(f: Path) -> int:
        with f.open("rb") as fh:
            return sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 24), b"")) - 1

    return sum(pq.ParquetFile(f).metadata.num_rows if f.suffix == ".parquet" else lines(f) for f in files)


def day_of(files: list[Path]) -> date:
    stem = files[0].stem.split("_")[-1]
    return date(int(stem[:4]), int(stem[4:6]), int(stem[6:8]))


def duckdb_copy(cpu: int, files: list[Path], out: Path, log: Path) -> dict:
    """:data:`DUCKDB_COPY` of ``files`` into ``out`` (emptied first), pinned to ``cpu``."""
    if out.exists():
        shutil.rmtree(out)
    return run_step(ROOT, cpu, [str(out), *map(str, files)], log, DUCKDB_COPY)


def polars_copy(cpu: int, config: Path, files: list[Path], out: Path, log: Path) -> dict:
    """:data:`POLARS_COPY` of ``files`` into ``out`` (emptied first), pinned to ``cpu``."""
    if out.exists():
        shutil.rmtree(out)
    return run_step(ROOT, cpu, [str(config), str(out), *map(str, files)], log, POLARS_COPY)


def path_once(code: Path, cpu: int, config: Path, files: list[Path], warehouse: Path, as_of: date, log: Path,
              ingested: Path | None = None, keep: Path | None = None, steps: tuple[str, ...] = STEPS) -> dict:
    """The nightly path into a fresh ``warehouse``: {step: measurement}. With ``ingested`` (a
    warehouse the same exports were ingested into) its copy replaces the ingest step; with
    ``keep`` the warehouse right after the ingest is copied there."""
    if warehouse.exists():
        shutil.rmtree(warehouse)
    wh = ["--warehouse", str(warehouse)]
    argv = {
        "ingest": ["ingest", "--config", str(config), *wh, *map(str, files)],
        "monitor": ["monitor", "--config", str(config), *wh],
        "report": ["report", "--config", str(config), *wh],
        "retention": ["retention", "--config", str(config), *wh, "--as-of", as_of.isoformat()],
    }
    out = {}
    for step in steps:
        if step == "ingest" and ingested is not None:
            shutil.copytree(ingested, warehouse)
            continue
        out[step] = run_step(code, cpu, argv[step], log)
        if step == "ingest" and keep is not None:
            if keep.exists():
                shutil.rmtree(keep)
            shutil.copytree(warehouse, keep)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--day", type=Path, required=True, help="a simulated valve-day: DAY/plant.toml, DAY/exports/*")
    ap.add_argument("--work", type=Path, required=True, help="scratch folder (warehouses, logs); emptied first")
    ap.add_argument("--code", action="append", default=None, help="LABEL=TREE (repeat); default this=<this tree>")
    ap.add_argument("--cpu", type=int, default=1, help="the CPU each step is pinned to")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--warm-minutes", type=int, default=45, help="minutes of the first file for the warm-up (> 2 M rows: read in spans, as the day)")
    ap.add_argument("--hours", type=int, default=None, help="only the first N hourly files")
    ap.add_argument("--ingest-once", action="store_true",
                    help="ingest with the first code only and give the others a copy of its warehouse (codes whose ingest is the same)")
    ap.add_argument("--steps", default=",".join(STEPS), help="the steps to run, comma-separated (default: all four)")
    ap.add_argument("--fleet", type=int, default=1, help="K > 1: also the whole path on the day as K valves (module doc)")
    ap.add_argument("--duckdb", action="store_true",
                    help="also DuckDB's bare COPY of the same files into a partitioned Parquet lake, pinned likewise, each round")
    args = ap.parse_args()
    steps = tuple(s for s in STEPS if s in args.steps.split(","))

    codes = [(c.split("=", 1)[0], Path(c.split("=", 1)[1]).resolve()) for c in (args.code or [f"this={ROOT}"])]
    files = sorted((args.day / "exports").glob("*.parquet")) or sorted((args.day / "exports").glob("*.csv"))
    if args.hours:
        files = files[: args.hours]
    if not files:
        raise SystemExit(f"no exports in {args.day / 'exports'}")
    if args.work.exists():
        shutil.rmtree(args.work)
    args.work.mkdir(parents=True)
    config = plant_with_retention(args.day / "plant.toml", args.work / "plant.toml")
    as_of = day_of(files) + timedelta(days=2)
    log = args.work / "commands.log"

    # warm-up: the whole path on the first minutes (compiles each tree's numba cache once; 0: skip)
    if args.warm_minutes > 0:
        warm = args.work / "warm_exports"
        warm.mkdir()
        import pyarrow.parquet as pq  # noqa: PLC0415 - only the warm-up's cut needs it

        if files[0].suffix == ".parquet":
            table = pq.read_table(files[0])
            pq.write_table(table.slice(0, args.warm_minutes * 60_000), warm / files[0].name)
            del table
        else:  # the header and the first minutes' lines
            with files[0].open("rb") as src, (warm / files[0].name).open("wb") as dst:
                dst.writelines(line for _, line in zip(range(args.warm_minutes * 60_000 + 1), src))
        for label, code in codes:
            path_once(code, args.cpu, config, [warm / files[0].name], args.work / f"wh_warm_{label}", as_of, log, steps=steps)
    ingested = args.work / "wh_ingested"

    results: dict[str, list[dict]] = {label: [] for label, _ in codes}
    duck: list[dict] = []
    copy: list[dict] = []
    rows = export_rows(files)
    for r in range(args.rounds):
        for label, code in codes:
            first = label == codes[0][0]
            once = args.ingest_once and "ingest" in steps
            res = path_once(code, args.cpu, config, files, args.work / f"wh_{label}", as_of, log,
                            ingested if once and not first else None, ingested if once and first else None, steps)
            if "ingest" not in res and "ingest" in steps:
                res["ingest"] = results[codes[0][0]][-1]["ingest"]
            results[label].append(res)
            print(json.dumps({"round": r + 1, "code": label, **res}), flush=True)
        if "ingest" in steps:
            copy.append(polars_copy(args.cpu, config, files, args.work / "polars_lake", log))
            print(json.dumps({"round": r + 1, "polars copy": copy[-1]}), flush=True)
        if args.duckdb:
            duck.append(duckdb_copy(args.cpu, files, args.work / "duckdb_lake", log))
            print(json.dumps({"round": r + 1, "duckdb copy": duck[-1]}), flush=True)

    print(f"\n{len(files)} file(s), {rows:,} lake rows; CPU s per step (user + system, pinned to CPU {args.cpu}), "
          f"least of {args.rounds} round(s)\n")
    head = "| step | " + " | ".join(f"{label}: CPU s | wall s | peak RSS | M rows / CPU s" for label, _ in codes) + " |"
    print(head)
    print("|---|" + "---:|" * (4 * len(codes)))
    best = {label: {s: min(rr[s]["cpu_s"] for rr in results[label]) for s in steps} for label, _ in codes}
    for step in steps:
        cells = []
        for label, _ in codes:
            rr = min(results[label], key=lambda x: x[step]["cpu_s"])[step]
            cells += [f"{rr['cpu_s']:.1f}", f"{rr['wall_s']:.1f}", f"{rr['rss_mb'] / 1024:.2f} GB", f"{rows / rr['cpu_s'] / 1e6:.2f}"]
        print(f"| {step} | " + " | ".join(cells) + " |")
    if copy:
        p = min(copy, key=lambda x: x["cpu_s"])
        print(f"| polars bare streaming copy | {p['cpu_s']:.1f} | {p['wall_s']:.1f} | {p['rss_mb'] / 1024:.2f} GB | {rows / p['cpu_s'] / 1e6:.2f} |")
        print("\ningest ÷ polars bare streaming copy (CPU, least of each): "
              + ", ".join(f"{label} {best[label]['ingest'] / p['cpu_s']:.2f}×" for label, _ in codes)
              + "; per round: " + "; ".join(
                  ", ".join(f"{label} {results[label][r]['ingest']['cpu_s'] / copy[r]['cpu_s']:.2f}×" for label, _ in codes)
                  for r in range(len(copy))))
    if duck:
        d = min(duck, key=lambda x: x["cpu_s"])
        print(f"| DuckDB bare COPY | {d['cpu_s']:.1f} | {d['wall_s']:.1f} | {d['rss_mb'] / 1024:.2f} GB | {rows / d['cpu_s'] / 1e6:.2f} |")
        if "ingest" in steps:
            print("\ningest ÷ DuckDB bare COPY (CPU, least of each): "
                  + ", ".join(f"{label} {best[label]['ingest'] / d['cpu_s']:.2f}×" for label, _ in codes)
                  + "; per round: " + "; ".join(
                      ", ".join(f"{label} {results[label][r]['ingest']['cpu_s'] / duck[r]['cpu_s']:.2f}×" for label, _ in codes)
                      for r in range(len(duck))))
    day = VALVE_DAY_ROWS / rows  # a part of a day (--hours): scaled up linearly, start-up included each time
    scaled = "" if day == 1 else f" (measured on {rows:,} rows, scaled x{day:.2f} to a valve-day: an upper bound, start-up counted each time)"
    print()
    for label, _ in codes:
        if steps != STEPS:
            continue  # a part of the path: no plant-day figure
        total = sum(best[label].values()) * day
        per = ", ".join(f"{s} {best[label][s] * day * VALVES / 3600:.2f}" for s in STEPS)
        verdict = "within" if total * VALVES / 3600 <= GOAL_CORE_H else "over"
        print(f"{label}: {total:.1f} CPU s per valve-day{scaled} -> {total * VALVES / 3600:.2f} core-hours per {VALVES}-valve "
              f"plant-day ({per}); {verdict} the goal of {GOAL_CORE_H:g} (each command once a valve: an upper bound)")
    if args.fleet > 1 and steps == STEPS:
        fleet_night(args, codes, config, files, as_of, log, best, day)


def fleet_night(args, codes, config: Path, files: list[Path], as_of: date, log: Path, one: dict, day: float) -> None:
    """The whole path on the day as ``args.fleet`` valves (:func:`fleet_day`), ``args.rounds``
    times a code; per step the fixed part and a valve's share, and the night of :data:`VALVES`."""
    k = args.fleet
    fleet_config, fleet_files = fleet_day(config, files, k, args.work / f"fleet_{k}")
    many = {label: [] for label, _ in codes}
    for r in range(args.rounds):
        for label, code in codes:
            many[label].append(path_once(code, args.cpu, fleet_config, fleet_files, args.work / f"wh_fleet_{label}", as_of, log))
            print(json.dumps({"round": r + 1, "code": label, "valves": k, **many[label][-1]}), flush=True)
    print(f"\nthe day as {k} valves: CPU s per step (least of {args.rounds} round(s)); a valve's share = ({k} valves − 1 valve) / {k - 1}\n")
    print("| step | code | 1 valve | " + f"{k} valves | a valve's share | fixed a night | {VALVES} valves, core-h |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for label, _ in codes:
        night = 0.0
        for step in STEPS:
            kk = min(rr[step]["cpu_s"] for rr in many[label])
            share = (kk - one[label][step]) / (k - 1)
            fixed = one[label][step] - share
            hours = (fixed + VALVES * share * day) / 3600
            night += hours
            print(f"| {step} | {label} | {one[label][step]:.1f} | {kk:.1f} | {share:.1f} | {fixed:.1f} | {hours:.2f} |")
        verdict = "within" if night <= GOAL_CORE_H else "over"
        print(f"\n{label}: the night of {VALVES} continuously recorded valves, each command once: {night:.2f} core-hours; {verdict} the goal of {GOAL_CORE_H:g}")


if __name__ == "__main__":
    main()

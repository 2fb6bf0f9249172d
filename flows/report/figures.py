"""The report's pictures (matplotlib, Agg), written as PNG files.

* :func:`characteristics_figure`: per valve, the opening-area characteristic of each edge:
  nominal α·A(u) (Eq. 3), the baseline Â(u) the fits are made against, and the current
  α̂·Â(u + x̂) of the latest ok window (the paper's Figs. 4, 5, 8 and 9), with the change
  current − baseline underneath, where wear of a few per cent becomes visible.
* :func:`trends_figure`: per valve, α̂, x̂ and e over operating hours for each edge, a point a
  UTC day (``trend_daily``: the day's median, and its windows' minimum to maximum as a band), with
  the wear and fault bounds, the fitted trend and, where the edge has a forecast within the
  horizon (``valve_condition``), the end of life with its 95 % interval (the paper's Fig. 6);
  days with an alarm marked in red. A continuous recording's 1,440 windows a day are its day's
  point and band, not 1,440 points.
* :func:`fleet_figure`: the fleet at a glance: the state of every edge of the most urgent
  valves, their remaining life (bars where there is a figure, the report's words beside), and the
  count of valves per state.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import cache
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import polars as pl  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from flows.report.remaining import remaining_text  # noqa: E402
from schemas.fields import EDGES, STATES  # noqa: E402

STATE_COLOURS = {"healthy": "#4caf50", "worn": "#ff9800", "faulty": "#d32f2f", "unknown": "#9e9e9e"}
PARAM_LABELS = {"alpha_hat": "α̂ (relative)", "x_hat_pct": "x̂ (% of x_max)", "e_mm2": "e (mm²)"}
DPI = 100
POOL_MIN_FIGURES = 8
"""Fewest pictures worth a process pool (a spawned process takes ~1.5 s to import matplotlib)."""
MAX_WORKERS = 4
"""Most processes drawing pictures at once."""
FIXED_LAYOUT = {"left": 0.05, "right": 0.99, "wspace": 0.22}
"""The per-valve pictures' margins, fixed: their grids of panels are always the same, and
matplotlib's constrained layout (measuring every tick label) took half of their drawing time."""


def render_figures(jobs: list[tuple[Callable[..., Path], tuple]], workers: int | None = None) -> list[Path]:
    """Draw each (figure function, arguments) of ``jobs``; their paths, in order.

    A picture whose inputs are those it was last drawn from (:func:`figure_key`, kept beside it)
    is kept as it is, not drawn again: a valve whose state and trend did not change costs the
    nightly report nothing. ``workers`` spawned processes draw the others (None: one per CPU, at
    most :data:`MAX_WORKERS`, and none for fewer than :data:`POOL_MIN_FIGURES` pictures; 0: all
    here). Each picture is drawn by one process alone from its arguments, so the files are the
    same either way."""
    keys = [figure_key(fn, args) for fn, args in jobs]
    todo = [(job, key) for job, key in zip(jobs, keys) if _stored_key(_path_of(job)) != key]
    for job, _ in todo:
        _key_file(_path_of(job)).unlink(missing_ok=True)  # a picture being redrawn is never taken for the old one
    if workers is None:
        workers = min(MAX_WORKERS, os.cpu_count() or 1) if len(todo) >= POOL_MIN_FIGURES else 0
    if workers <= 1:
        drawn = [fn(*args) for (fn, args), _ in todo]
    else:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(fn, *args) for (fn, args), _ in todo]
            drawn = [f.result() for f in futures]
    for path, (_, key) in zip(drawn, todo):
        _key_file(path).write_text(key)
    return [_path_of(job) for job in jobs]


def _path_of(job: tuple[Callable[..., Path], tuple]) -> Path:
    """The picture's file: its figure function's one Path argument."""
    return next(a for a in job[1] if isinstance(a, Path))


def _key_file(path: Path) -> Path:
    return path.parent / f".{path.name}.key"


def _stored_key(path: Path) -> str | None:
    key = _key_file(path)
    return key.read_text() if key.exists() and path.exists() else None


@cache
def _code_key() -> bytes:
    """This module's source, the remaining-life wording it draws and matplotlib's version: a change
    to how pictures are drawn redraws them all."""
    here = Path(__file__).resolve()
    return here.read_bytes() + (here.parent / "remaining.py").read_bytes() + matplotlib.__version__.encode()


def figure_key(fn: Callable[..., Path], args: tuple) -> str:
    """What a picture is drawn from: the figure function, its arguments (frames by their rows in
    any order, as the report's queries give them; arrays by content) and the drawing code, as a
    BLAKE3 hex digest."""
    from blake3 import blake3  # noqa: PLC0415

    rows = tuple(a.sort(a.columns, nulls_last=True) if isinstance(a, pl.DataFrame) and a.height else a for a in args)
    return blake3(_code_key() + pickle.dumps((fn.__module__, fn.__qualname__, rows), protocol=5)).hexdigest()


def _save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _daily_band(ax, h: np.ndarray, median: np.ndarray, lo: np.ndarray, hi: np.ndarray, colour: str, label: str) -> None:
    """A day's median (points joined) and the band of its windows' minimum to maximum."""
    ax.fill_between(h, lo, hi, color=colour, alpha=0.2, lw=0, step="mid", label=f"{label}: daily min–max")
    ax.plot(h, median, ".-", color=colour, ms=4, lw=0.8, label=f"{label}: daily median")


def _leak_panel(ax, d: pl.DataFrame | None) -> None:
    """The edge's closed-edge leakage (× Eq. 3): daily median and range of the windows' estimates, and at commissioning."""
    ax.set_xlabel("operating hours (h)")
    ax.grid(alpha=0.3)
    if ax.get_subplotspec().is_first_col():
        ax.set_ylabel("leakage (× Eq. 3)")
    if d is None or d.height == 0:
        ax.text(0.5, 0.5, "no leakage estimates", ha="center", va="center", transform=ax.transAxes)
        return
    d = d.sort("operating_hours")
    y = d["median_leak_scale"].to_numpy()
    _daily_band(ax, d["operating_hours"].to_numpy(), y, d["min_leak_scale"].to_numpy(), d["max_leak_scale"].to_numpy(), "#37474f", "windows")
    base = d["leak_scale_baseline"].drop_nulls()
    if base.len():
        ax.axhline(float(base[0]), color="#1565c0", lw=1.2, label="commissioning")
    ax.axhline(1.0, color="k", ls="--", lw=0.8, label="Eq. 3")
    top = max(2.0, 1.5 * float(np.nanpercentile(y, 95)), 1.5 * (float(base[0]) if base.len() else 0.0))
    ax.set_ylim(0.0, top)  # the daily medians, not the widest single windows
    ax.legend(fontsize=7, loc="upper left")


def characteristics_figure(valve_id: str, curves: dict[str, dict[str, np.ndarray]], latest: dict[str, dict], path: Path) -> Path:
    """Opening-area characteristics of one valve's four edges.

    Parameters
    ----------
    curves : dict
        edge → {"u_mm", "nominal_mm2", "baseline_mm2", "current_mm2" (or None)} on one u grid.
    latest : dict
        edge → {"alpha_hat", "x_hat_pct", "state", "window_start"} of the latest ok window.
    """
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.4]})
    fig.subplots_adjust(**FIXED_LAYOUT, top=0.90, bottom=0.08, hspace=0.1)
    for j, edge in enumerate(EDGES):
        c = curves.get(edge)
        top, bottom = axes[0, j], axes[1, j]
        info = latest.get(edge) or {}
        state = info.get("state") or "unknown"
        top.set_title(f"{valve_id} edge {edge}: {state}", color=STATE_COLOURS.get(state, "black"), fontsize=11)
        if c is None:
            top.text(0.5, 0.5, "no baseline", ha="center", va="center", transform=top.transAxes)
            continue
        u = c["u_mm"]
        top.plot(u, c["nominal_mm2"], "k--", lw=1.2, label="nominal α·A(u), Eq. 3")
        top.plot(u, c["baseline_mm2"], "-", color="#1565c0", lw=1.6, label="baseline Â(u)")
        if c.get("current_mm2") is not None:
            label = f"current α̂·Â(u+x̂): α̂ {info['alpha_hat']:.3f}, x̂ {info['x_hat_pct']:+.2f} %"
            top.plot(u, c["current_mm2"], "-", color=STATE_COLOURS.get(state, "#000"), lw=1.6, label=label)
            bottom.plot(u, c["current_mm2"] - c["baseline_mm2"], color=STATE_COLOURS.get(state, "#000"), lw=1.4)
        bottom.axhline(0, color="#1565c0", lw=0.8)
        top.grid(alpha=0.3)
        bottom.grid(alpha=0.3)
        top.legend(fontsize=7.5, loc="upper left")
        bottom.set_xlabel("opening coordinate u (mm)")
        if j == 0:
            top.set_ylabel("α·A (mm²)")
            bottom.set_ylabel("current − baseline (mm²)")
    fig.suptitle(f"Opening-area characteristics of valve {valve_id}", fontsize=13)
    return _save(fig, path)


def trends_figure(valve_id: str, daily: pl.DataFrame, lines: pl.DataFrame, bounds: pl.DataFrame, life: dict[str, dict],
                  path: Path, leak: pl.DataFrame | None = None) -> Path:
    """α̂, x̂, e and the closed-edge leakage over operating hours for the four edges of one valve,
    a point a UTC day (a continuous recording gives 1,440 windows a day: its picture is its days).

    Parameters
    ----------
    daily : DataFrame
        Rows of view ``trend_daily`` for the valve (per edge, day and parameter: median, min, max,
        n_alarms, operating_hours at the day's last window).
    lines : DataFrame
        Rows of view ``parameter_trends`` for the valve (slope, intercept).
    bounds : DataFrame
        Rows of view ``stg_condition_bounds`` for the valve (fault and wear bounds per parameter).
    life : dict
        edge → its ``valve_condition`` row: the end of life is drawn where that row has a
        forecast (``remaining_basis`` forecast, on its ``limiting_parameter``), nowhere else.
    leak : DataFrame, optional
        Per edge and day: operating_hours, median_leak_scale, min_leak_scale, max_leak_scale of
        the ok windows, and leak_scale_baseline: the bottom row.
    """
    params = ("alpha_hat", "x_hat_pct", "e_mm2")
    fig, axes = plt.subplots(4, 4, figsize=(16, 12.5), sharex="col")
    fig.subplots_adjust(**FIXED_LAYOUT, top=0.935, bottom=0.05, hspace=0.12)
    for j, edge in enumerate(EDGES):
        _leak_panel(axes[3, j], None if leak is None else leak.filter(pl.col("edge") == edge))
    for j, edge in enumerate(EDGES):
        for i, p in enumerate(params):
            ax = axes[i, j]
            d = daily.filter((pl.col("edge") == edge) & (pl.col("parameter") == p)).sort("operating_hours")
            if i == 0:
                ax.set_title(f"{valve_id} edge {edge}", fontsize=11)
            if j == 0:
                ax.set_ylabel(PARAM_LABELS[p])
            ax.grid(alpha=0.3)
            if d.height == 0:
                ax.text(0.5, 0.5, "no ok fits", ha="center", va="center", transform=ax.transAxes)
                continue
            h = d["operating_hours"].to_numpy()
            lo_v, hi_v = d["min_value"].to_numpy(), d["max_value"].to_numpy()
            _daily_band(ax, h, d["median_value"].to_numpy(), lo_v, hi_v, "#37474f", "windows")
            alarm = d["n_alarms"].to_numpy() > 0
            if alarm.any():
                ax.plot(h[alarm], hi_v[alarm], "x", color=STATE_COLOURS["faulty"], ms=7, mew=2, label="day with an alarm")
            x_end = h.max()
            lp = lines.filter((pl.col("edge") == edge) & (pl.col("parameter") == p))
            c = life.get(edge, {})
            if c.get("remaining_basis") == "forecast" and c.get("limiting_parameter") == p:
                now = c["operating_hours"]
                x_end = max(x_end, c["end_of_life_hours"])
                ax.axvline(c["end_of_life_hours"], color=STATE_COLOURS["worn"], lw=1.2)
                hi = c["remaining_hours_high"] if c["remaining_hours_high"] is not None else c["remaining_horizon_hours"]
                ax.axvspan(now + c["remaining_hours_low"], now + hi, color=STATE_COLOURS["worn"], alpha=0.15, label="end of life (95 %)")
            if lp.height and lp["slope_per_hour"][0] is not None and lp["n_fits"][0] >= 3:
                xs = np.array([h.min(), x_end])
                ax.plot(xs, lp["intercept"][0] + lp["slope_per_hour"][0] * xs, "--", color="#ef6c00", lw=1.2, label="trend (OLS)")
            b = bounds.filter(pl.col("parameter") == p)
            b = b.row(0, named=True) if b.height else {}
            for col, style, colour in (("wear_low", "--", STATE_COLOURS["worn"]), ("wear_high", "--", STATE_COLOURS["worn"]),
                                       ("fault_low", ":", STATE_COLOURS["faulty"]), ("fault_high", ":", STATE_COLOURS["faulty"])):  # fmt: skip
                if b.get(col) is not None:
                    ax.axhline(b[col], ls=style, color=colour, lw=1)
            lo_y = min([float(np.nanmin(lo_v))] + [v for v in (b.get("wear_low"),) if v is not None])
            hi_y = max([float(np.nanmax(hi_v))] + [v for v in (b.get("wear_high"),) if v is not None])
            pad = 0.08 * (hi_y - lo_y or 1.0)
            ax.set_ylim(lo_y - pad, hi_y + pad)
            if i == 0 and j == 0:
                ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"Condition parameters of valve {valve_id} over operating hours, a point a day "
                 "(dashed orange: wear bounds; dotted red: fault bounds)", fontsize=13)  # fmt: skip
    return _save(fig, path)


def fleet_figure(ranking: pl.DataFrame, conditions: pl.DataFrame, path: Path, max_valves: int = 40) -> Path:
    """Fleet overview: edge states of the most urgent valves, their remaining life, state counts."""
    top = ranking.sort("urgency_rank").head(max_valves)
    ids = top["valve_id"].to_list()
    n = max(len(ids), 1)
    fig = plt.figure(figsize=(16, max(4.5, 0.32 * n + 2.0)), constrained_layout=True)
    gs = fig.add_gridspec(1, 3, width_ratios=[1.1, 2.2, 1.0])
    ax_state, ax_life, ax_count = fig.add_subplot(gs[0]), fig.add_subplot(gs[1]), fig.add_subplot(gs[2])
    codes = {s: k for k, s in enumerate(STATES)}
    grid = np.full((n, len(EDGES)), codes["unknown"], dtype=float)
    lookup = {(r["valve_id"], r["edge"]): r["state"] for r in conditions.iter_rows(named=True)}
    for a, vid in enumerate(ids):
        for b, edge in enumerate(EDGES):
            grid[a, b] = codes[lookup.get((vid, edge), "unknown")]
    cmap = ListedColormap([STATE_COLOURS[s] for s in STATES])
    ax_state.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(STATES) - 0.5, aspect="auto")
    ax_state.set_xticks(range(len(EDGES)), EDGES)
    ax_state.set_yticks(range(len(ids)), [f"{r['urgency_rank']}. {r['valve_id']}" for r in top.iter_rows(named=True)], fontsize=8)
    ax_state.set_title(f"edge states, {len(ids)} most urgent valves")
    ax_state.legend(handles=[Patch(color=STATE_COLOURS[s], label=s) for s in STATES], fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.04), ncol=2)
    y = np.arange(len(ids))
    rem = top["remaining_hours"].to_numpy().astype(float)
    lo = top["remaining_hours_low"].to_numpy().astype(float)
    hi = top["remaining_hours_high"].to_numpy().astype(float)
    has = np.isfinite(rem)
    colours = [STATE_COLOURS.get(s, "#000") for s in top["state"].to_list()]
    if has.any():
        ax_life.barh(y[has], rem[has], color=[c for c, k in zip(colours, has) if k], alpha=0.85)
        err = np.vstack([rem[has] - lo[has], np.where(np.isfinite(hi[has]), hi[has] - rem[has], 0)])
        ax_life.errorbar(rem[has], y[has], xerr=np.clip(err, 0, None), fmt="none", ecolor="black", capsize=3, lw=1)
    for k, row in enumerate(top.iter_rows(named=True)):  # the words of the table (now, > horizon, ...)
        ax_life.text(0 if not has[k] else rem[k], y[k], "  " + remaining_text(row), va="center", fontsize=8, color="#616161")
    reach = np.nanmax(np.concatenate([rem[has], hi[has], [0.0]]))
    if reach > 0:
        ax_life.set_xlim(0, 1.3 * reach)  # room for the words beside the bars
    else:  # nothing but "now" and words: no hour axis to read
        ax_life.set_xlim(0, 1)
        ax_life.set_xticks([])
    ax_life.set_yticks(y, [str(v) for v in ids], fontsize=8)
    ax_life.set_ylim(len(ids) - 0.5, -0.5)
    ax_life.set_xlabel("remaining operating hours to a wear bound (bar) with 95 % interval, within the forecast horizon")
    ax_life.set_title("remaining service life")
    ax_life.grid(axis="x", alpha=0.3)
    counts = {s: int((ranking["state"] == s).sum()) for s in STATES}
    ax_count.bar(list(counts), list(counts.values()), color=[STATE_COLOURS[s] for s in counts])
    for k, (s, v) in enumerate(counts.items()):
        ax_count.text(k, v, str(v), ha="center", va="bottom")
    ax_count.set_title(f"valves per state ({ranking.height} valves)")
    fig.suptitle("Fleet overview", fontsize=13)
    return _save(fig, path)

"""Overlay pictures of the discrepancy workflow (matplotlib, Agg), written as PNG files under
``WAREHOUSE/reports/discrepancy/``.

One picture per named effect (or one for ``none``): for the record with the largest gap before,
the recorded p1 and p2 against the replay before the effect was added (the model with the
effects named earlier) and after; and the replay's position error X̂ − X before and after
(the position itself, ~0.5 m of travel, would hide millimetres).
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from transforms.discrepancy.pipeline import ReplayTrace  # noqa: E402

DPI = 100


def overlay_figure(trace: ReplayTrace, stage_before: int, stage_after: int, title: str, path: Path) -> Path:
    """Measured against replayed p1, p2 and the position error, two stages of the model.

    Parameters
    ----------
    trace : ReplayTrace
        The record's recorded signals and replays of every stage.
    stage_before, stage_after : int
        Stages to compare (0 = the base model; equal for a run that named nothing).
    title : str
        Figure title.
    path : Path
        PNG file to write (folders are created).
    """
    t = trace.t
    fig, axes = plt.subplots(3, 1, figsize=(12, 8.5), sharex=True, constrained_layout=True)
    start = datetime.fromtimestamp(trace.start_us / 1e6, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    fig.suptitle(f"{title}\nrecord from {start}", fontsize=11)
    same = stage_before == stage_after
    for ax, sig, label in ((axes[0], "p1", "p1 (bar)"), (axes[1], "p2", "p2 (bar)")):
        ax.plot(t, trace.measured[sig] / 1e5, color="black", lw=0.8, label="measured")
        ax.plot(t, trace.replayed[f"stage{stage_before}_{sig}"] / 1e5, color="#d32f2f", lw=0.9, ls="--" if not same else "-", label="simulated, before" if not same else "simulated")
        if not same:
            ax.plot(t, trace.replayed[f"stage{stage_after}_{sig}"] / 1e5, color="#1976d2", lw=0.9, label="simulated, after")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    ax = axes[2]
    eb = (trace.replayed[f"stage{stage_before}_X"] - trace.measured["X"]) * 1e3
    ax.plot(t, eb, color="#d32f2f", lw=0.9, label="simulated − measured, before" if not same else "simulated − measured")
    if not same:
        ea = (trace.replayed[f"stage{stage_after}_X"] - trace.measured["X"]) * 1e3
        ax.plot(t, ea, color="#1976d2", lw=0.9, label="simulated − measured, after")
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_ylabel("X error (mm)")
    ax.set_xlabel("time in record (s)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    if np.all(~np.isfinite(eb)):
        ax.text(0.5, 0.5, "no replay", transform=ax.transAxes, ha="center")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path

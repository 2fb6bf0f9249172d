"""The pressure channels' delay against the position channels, and records aligned for it.

A transmitter's dynamics (a first-order lag of ~1 ms behaves as a delay of 1 ms below ~100 Hz) and
an acquisition that samples the pressures a sample later than the positions make the recorded
pressures late. The chamber equations and the replays take the pressures and positions as
simultaneous, so a delay of d looks like a compressibility change (the orifice flows at p(t − d) ≈
q − d ∂q/∂p ṗ): on a plant with 1 ms of lag and one sample of skew the hydraulic replay of a clean
valve was 3.3× its noise floor and the selection read a p1 gain or a mass change.

The delay is estimated in whole samples from the hydraulic replay of the model (p1, p2 on the
recorded spool, supply and cylinder motion; :mod:`transforms.discrepancy.rows`): the shift k of
the recorded p1, p2 against the replayed ones with the least squared difference, k = 0 …
``MAX_DELAY_S``, the difference high-passed (minus its ``HIGHPASS_SAMPLES`` moving mean: the
slowly varying disagreement of a model not yet calibrated hides the delay; by the raw difference
a 2 ms delay came out as 1 ms, by the high-passed one as 2 ms, and 0 on ``model``'s own plant). The records are then cut so that every pressure channel (ps, pr, p1, p2) is
taken k samples later than the positions. One delay for all pressure channels: they share the
acquisition and transmitter type; a single transmitter lagging on its own is a discrepancy the
workflow must report, not absorb.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from transforms.discrepancy.records import Record

__all__ = ["MAX_DELAY_S", "align_records", "pressure_delay_samples", "shifted"]

MAX_DELAY_S = 5.0e-3
"""Largest pressure delay looked for. [s]"""
PRESSURES = ("ps", "pr", "p1", "p2")
HIGHPASS_SAMPLES = 51
"""Length of the moving mean taken off the replay's difference before the delay is fitted."""


def shifted(rec: Record, k: int) -> Record:
    """``rec`` with every pressure channel taken ``k`` samples later than the positions (the
    record ``k`` samples shorter)."""
    if k <= 0:
        return rec
    raw = {c: (v[k:] if c in PRESSURES else v[:-k]).copy() for c, v in rec.raw.items()}
    return replace(rec, end_us=rec.end_us - int(round(k * rec.dt * 1e6)), raw=raw, sg={})


def pressure_delay_samples(prepared, plant, condition, settings) -> int:
    """The delay (whole samples) of the recorded p1, p2 against the model's hydraulic replay (module docstring)."""
    from model.effects import Effects
    from transforms.discrepancy.rows import _replay_record

    kmax = int(round(MAX_DELAY_S / prepared[0].rec.dt)) if prepared else 0
    sse = np.zeros(kmax + 1)
    for p in prepared:
        rr = _replay_record(p, plant, condition, Effects(), settings)
        n = p.rec.n
        for ch in ("p1", "p2"):
            rep, rec = rr[f"{ch}_hydraulic"], p.rec.raw[ch]
            for k in range(kmax + 1):
                e = rec[k + kmax:] - rep[kmax:n - k]  # the same replayed samples for every k
                ok = np.isfinite(e)
                e = e - np.convolve(np.where(ok, e, 0.0), np.ones(HIGHPASS_SAMPLES) / HIGHPASS_SAMPLES, "same")
                sse[k] += float(np.sum(e[ok] ** 2))
    return int(np.argmin(sse))


def align_records(records: list[Record], plant, condition, settings) -> tuple[list[Record], int]:
    """(``records`` aligned for the pressure delay, the delay in samples)."""
    from transforms.discrepancy.rows import prepare_records

    prepared = prepare_records(records, plant, condition, settings)
    k = pressure_delay_samples(prepared, plant, condition, settings)
    return ([shifted(r, k) for r in records] if k else records), k

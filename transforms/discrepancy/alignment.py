"""The pressure channels' delay against the position channels, per channel, and records aligned for it.

A transmitter's dynamics (a first-order lag of ~1 ms behaves as a delay of 1 ms below ~100 Hz) and
an acquisition that samples the pressures a sample later than the positions make the recorded
pressures late. The chamber equations and the replays take the pressures and positions as
simultaneous, so a delay of d looks like a compressibility change (the orifice flows at p(t − d) ≈
q − d ∂q/∂p ṗ): on a plant with 1 ms of lag and one sample of skew the hydraulic replay of a clean
valve was 3.3× its noise floor and the selection read a p1 gain or a mass change.

The delay is estimated in whole samples from the hydraulic replay of the model (p1, p2 on the
recorded spool, supply and cylinder motion; :mod:`transforms.discrepancy.rows`): for p1 and p2
separately, the squared difference of the recorded channel shifted by k against the replayed one,
k = 0 … ``MAX_DELAY_S``, the difference high-passed (minus its ``HIGHPASS_SAMPLES`` moving mean:
the slowly varying disagreement of a model not yet calibrated hides the delay; by the raw
difference a 2 ms delay came out as 1 ms, by the high-passed one as 2 ms, and 0 on ``model``'s own
plant). Where the two channels' best shifts differ and *each* fits its own shift better than the
other's by ``LAG_EVIDENCE`` (3 %) of its squared difference, each channel takes its own delay;
otherwise both take the shift that fits them jointly (the sum's least). The test on both sides
matters: a channel whose difference is dominated by what the uncalibrated model gets wrong has a
flat curve (p2 on ``model``'s plant with an internal leak: 1.000 at 0 and at 1 sample) and would
otherwise report a lag it does not have. The supply and return pressures hardly move the chamber
replay, so they take the *shared* delay, the smaller of p1's and p2's (the acquisition's and the
transmitters' common part: a lag adds delay, it never removes it). Every pressure channel is then
taken its own delay later than the positions.

A chamber transmitter whose delay exceeds the shared one (``PressureDelays.lagging``) lags the
others: a slow or damped transmitter, a long or air-filled sensing line. That is no library effect;
aligned for it, the other effects are judged as on a healthy transmitter, and the lag is reported
as a finding of its own (:meth:`PressureDelays.finding`) rather than left for a p1 offset or gain
to absorb (with one delay for all pressures, a 2 ms lag on the reference plant's p1 transmitter
was named a −0.65 bar p1 offset).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from transforms.discrepancy.records import Record

__all__ = ["MAX_DELAY_S", "PressureDelays", "align_prepared", "align_records", "pressure_delays", "shifted"]

MAX_DELAY_S = 5.0e-3
"""Largest pressure delay looked for. [s]"""
PRESSURES = ("ps", "pr", "p1", "p2")
CHAMBERS = ("p1", "p2")
HIGHPASS_SAMPLES = 51
"""Length of the moving mean taken off the replay's difference before the delay is fitted."""
LAG_EVIDENCE = 0.03
"""One chamber channel lags the other only where each fits its own delay better than the other's by
this fraction of its squared difference; otherwise both take the delay that fits them jointly
(module docstring)."""


@dataclass(frozen=True)
class PressureDelays:
    """The delay of each chamber pressure channel against the model's hydraulic replay.

    Attributes
    ----------
    samples : dict
        Whole samples per chamber channel (``p1``, ``p2``): the shift with the least squared
        (high-passed) difference.
    fine : dict
        The same to a fraction of a sample (the parabola through the squared differences at the
        best shift and its neighbours), for the report.
    sse : dict
        Per chamber channel, the squared high-passed difference for every shift 0 … kmax.
    dt : float
        Sample period. [s]
    """

    samples: dict
    fine: dict
    sse: dict
    dt: float

    @property
    def shared(self) -> int:
        """The delay common to all pressure channels (samples): the smaller chamber channel's."""
        return min(self.samples.values()) if self.samples else 0

    def of(self, channel: str) -> int:
        """The delay channel ``channel`` (ps, pr, p1, p2) is aligned for (samples)."""
        return self.samples.get(channel, self.shared)

    @property
    def lagging(self) -> list[str]:
        """The chamber channels lagging the others (their delay above the shared one)."""
        return [c for c in CHAMBERS if self.samples.get(c, 0) > self.shared]

    def finding(self) -> str:
        """The lagging transmitters, how much, and how much aligning for it changed ("" if none)."""
        parts = []
        for c in self.lagging:
            other = [o for o in CHAMBERS if o != c][0]
            k, k0 = self.samples[c], self.shared
            drop = 1.0 - self.sse[c][k] / self.sse[c][k0]
            parts.append(
                f"the {c} transmitter lags the other pressures by {(self.fine[c] - self.fine[other]) * self.dt * 1e3:.2g} ms "
                f"(its delay against the model's replay {self.fine[c] * self.dt * 1e3:.2g} ms, {other}'s {self.fine[other] * self.dt * 1e3:.2g} ms; "
                f"taken {k - k0} samples later than the others, its high-passed disagreement is {drop:.0%} smaller): a slow transmitter "
                f"or sensing line, which no library effect describes")
        return "; ".join(parts)


def shifted(rec: Record, k: int | dict) -> Record:
    """``rec`` with every pressure channel taken ``k`` samples (an int, or per channel a dict
    ps/pr/p1/p2 → samples) later than the positions (the record max(k) samples shorter)."""
    ks = {c: k for c in PRESSURES} if isinstance(k, int) else {c: int(k.get(c, 0)) for c in PRESSURES}
    kmax = max(ks.values())
    if kmax <= 0:
        return rec
    n = rec.n
    raw = {c: (v[ks[c]:n - kmax + ks[c]] if c in PRESSURES else v[:n - kmax]).copy() for c, v in rec.raw.items()}
    return replace(rec, end_us=rec.end_us - int(round(kmax * rec.dt * 1e6)), raw=raw, sg={}, pos={}, noise={})


def _vertex(s: np.ndarray, k: int) -> float:
    """The minimum of the parabola through s[k-1], s[k], s[k+1] (k itself at the ends)."""
    if k <= 0 or k >= s.size - 1:
        return float(k)
    den = s[k - 1] - 2.0 * s[k] + s[k + 1]
    return float(k + 0.5 * (s[k - 1] - s[k + 1]) / den) if den > 0 else float(k)


def pressure_delays(prepared, plant, condition, settings) -> PressureDelays:
    """The delay of the recorded p1 and p2, each against the model's hydraulic replay (module docstring)."""
    from model.effects import Effects
    from transforms.discrepancy.rows import hydraulic_readings

    dt = prepared[0].rec.dt if prepared else 1.0
    kmax = int(round(MAX_DELAY_S / dt)) if prepared else 0
    sse = {ch: np.zeros(kmax + 1) for ch in CHAMBERS}
    box = np.ones(HIGHPASS_SAMPLES) / HIGHPASS_SAMPLES
    for p in prepared:
        rr = dict(zip(CHAMBERS, hydraulic_readings(p, plant, condition, Effects(), settings)))
        n = p.rec.n
        for ch in CHAMBERS:
            rep, rec = rr[ch], p.rec.raw[ch]
            for k in range(kmax + 1):
                e = rec[k + kmax:] - rep[kmax:n - k]  # the same replayed samples for every k
                ok = np.isfinite(e)
                e = e - np.convolve(np.where(ok, e, 0.0), box, "same")
                sse[ch][k] += float(np.sum(e[ok] ** 2))
    own = {ch: int(np.argmin(s)) for ch, s in sse.items()}
    lo, hi = sorted(CHAMBERS, key=lambda ch: own[ch])
    if own[hi] > own[lo] and min(sse[hi][own[lo]] / sse[hi][own[hi]], sse[lo][own[hi]] / sse[lo][own[lo]]) >= 1.0 + LAG_EVIDENCE:
        samples = own  # each channel clearly prefers its own delay to the other's: one lags
    else:
        joint = int(np.argmin(sse["p1"] + sse["p2"]))
        samples = {ch: joint for ch in CHAMBERS}
    return PressureDelays(samples=samples, fine={ch: _vertex(sse[ch], own[ch]) for ch in CHAMBERS}, sse=sse, dt=dt)


def align_records(records: list[Record], plant, condition, settings) -> tuple[list[Record], PressureDelays]:
    """(``records`` with each pressure channel aligned for its delay, the delays)."""
    return align_prepared(records, plant, condition, settings)[:2]


def align_prepared(records: list[Record], plant, condition, settings) -> tuple[list[Record], PressureDelays, list]:
    """:func:`align_records` and the aligned records prepared for (plant, condition)
    (:func:`transforms.discrepancy.rows.prepare_records`): the preparation the delays were
    measured on when no channel moved, whose loads need not be estimated again."""
    from transforms.discrepancy.rows import prepare_records

    prepared = prepare_records(records, plant, condition, settings)
    d = pressure_delays(prepared, plant, condition, settings)
    ks = {c: d.of(c) for c in PRESSURES}
    if not any(ks.values()):
        return records, d, prepared
    records = [shifted(r, ks) for r in records]
    return records, d, prepare_records(records, plant, condition, settings)

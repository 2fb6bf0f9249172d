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

A lagging channel is aligned by whichever of two models of its extra delay fits its high-passed
difference better: whole samples more (a dead time), or the shared shift and its lag above the
others' taken out. A slow transmitter is a lag, not a dead time: it passes the slow parts a little
late and damps the fast ones, so whole samples leave a residual in ṗ that reads as a
compressibility change (on the reference plant's 2 ms p1 lag, entrained air). Bringing a
first-order lag τ₁ to the others' τₒ is (1 + τ₁s)/(1 + τₒs) ≈ 1 + τs − τ τₒ s², τ = τ₁ − τₒ:
p = p_m + τ ṗ_m + c p̈_m (Savitzky–Golay derivatives), τ and c ≤ 0 by least squares (the
difference is linear in them), τₒ = −c/τ. The others' lag itself stays whole samples: against a
dead time it is not told apart at the recorded noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from transforms.discrepancy.records import Record, savgol

__all__ = ["MAX_DELAY_S", "PressureDelays", "align_prepared", "align_records", "pressure_delays", "shifted", "unlagged"]

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
    lag_s : dict
        A lagging channel's lag above the others' taken out (τ, module docstring), its ``samples``
        then the shared shift; absent where whole samples fit better. [s]
    lag_sse : dict
        The lagging channel's squared high-passed difference with that lag taken out.
    second_s2 : dict
        The lagging channel's second-order term c = −τ τₒ (module docstring). [s²]
    """

    samples: dict
    fine: dict
    sse: dict
    dt: float
    lag_s: dict = field(default_factory=dict)
    lag_sse: dict = field(default_factory=dict)
    second_s2: dict = field(default_factory=dict)

    @property
    def shared(self) -> int:
        """The delay common to all pressure channels (samples): the smaller chamber channel's."""
        return min(self.samples.values()) if self.samples else 0

    def of(self, channel: str) -> int:
        """The delay channel ``channel`` (ps, pr, p1, p2) is aligned for (samples)."""
        return self.samples.get(channel, self.shared)

    @property
    def lagging(self) -> list[str]:
        """The chamber channels lagging the others (their delay above the shared one, or a lag taken out)."""
        return [c for c in CHAMBERS if self.samples.get(c, 0) > self.shared or c in self.lag_s]

    def finding(self) -> str:
        """The lagging transmitters, how much, and how much aligning for it changed ("" if none)."""
        parts = []
        for c in self.lagging:
            other = [o for o in CHAMBERS if o != c][0]
            k, k0 = self.samples[c], self.shared
            if c in self.lag_s:
                how = f"a first-order lag of {self.lag_s[c] * 1e3:.2g} ms taken out" + (
                    f" (on the others' {-self.second_s2[c] / self.lag_s[c] * 1e3:.2g} ms)" if self.second_s2[c] < 0.0 else "")
                drop = 1.0 - self.lag_sse[c] / self.sse[c][k0]
            else:
                how = f"taken {k - k0} samples later than the others"
                drop = 1.0 - self.sse[c][k] / self.sse[c][k0]
            parts.append(
                f"the {c} transmitter lags the other pressures by {(self.fine[c] - self.fine[other]) * self.dt * 1e3:.2g} ms "
                f"(its delay against the model's replay {self.fine[c] * self.dt * 1e3:.2g} ms, {other}'s {self.fine[other] * self.dt * 1e3:.2g} ms; "
                f"{how}, its high-passed disagreement is {drop:.0%} smaller): a slow transmitter "
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


def unlagged(rec: Record, lag_s: dict, second_s2: dict, settings) -> Record:
    """``rec`` with each channel of ``lag_s`` (channel → first-order lag [s]) taken out of its lag,
    p = p_m + τ ṗ_m + c p̈_m (``second_s2``: channel → c [s²]; Savitzky–Golay derivatives of ``settings``),
    and every channel cut by half a stencil at both ends, where those derivatives are not defined."""
    if not lag_s:
        return rec
    h = settings.savgol_window // 2
    L, o = settings.savgol_window, settings.savgol_order
    raw = {c: (v + lag_s[c] * savgol(v, L, o, 1, rec.dt) + second_s2.get(c, 0.0) * savgol(v, L, o, 2, rec.dt) if c in lag_s else v)[h:rec.n - h].copy()
           for c, v in rec.raw.items()}
    cut = int(round(h * rec.dt * 1e6))
    return replace(rec, start_us=rec.start_us + cut, end_us=rec.end_us - cut, raw=raw, sg={}, pos={}, noise={})


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
    replays = []
    for p in prepared:
        rr = dict(zip(CHAMBERS, hydraulic_readings(p, plant, condition, Effects(), settings)))
        replays.append(rr)
        for ch in CHAMBERS:
            for k in range(kmax + 1):
                e = _difference(p, rr[ch], ch, k, kmax)
                ok = np.isfinite(e)
                sse[ch][k] += float(np.sum(_highpassed(e, ok)[ok] ** 2))
    own = {ch: int(np.argmin(s)) for ch, s in sse.items()}
    lo, hi = sorted(CHAMBERS, key=lambda ch: own[ch])
    lag_s, lag_sse, second = {}, {}, {}
    if own[hi] > own[lo] and min(sse[hi][own[lo]] / sse[hi][own[hi]], sse[lo][own[hi]] / sse[lo][own[lo]]) >= 1.0 + LAG_EVIDENCE:
        samples = dict(own)  # each channel clearly prefers its own delay to the other's: one lags
        tau, c2, s_lag, s_dead = _lag_terms(prepared, replays, hi, own[lo], own[hi], kmax, settings)
        if tau > 0.0 and s_lag < s_dead:  # a lag fits better than whole samples more
            # its squared difference on the scale of ``sse`` (both were summed where the derivative is defined)
            samples[hi], lag_s[hi], lag_sse[hi], second[hi] = own[lo], tau, s_lag * sse[hi][own[hi]] / s_dead, c2
    else:
        joint = int(np.argmin(sse["p1"] + sse["p2"]))
        samples = {ch: joint for ch in CHAMBERS}
    return PressureDelays(samples=samples, fine={ch: _vertex(sse[ch], own[ch]) for ch in CHAMBERS}, sse=sse, dt=dt, lag_s=lag_s, lag_sse=lag_sse, second_s2=second)


def _highpassed(e: np.ndarray, ok: np.ndarray) -> np.ndarray:
    return e - np.convolve(np.where(ok, e, 0.0), np.ones(HIGHPASS_SAMPLES) / HIGHPASS_SAMPLES, "same")


def _difference(p, rep: np.ndarray, ch: str, k: int, kmax: int) -> np.ndarray:
    """Channel ``ch`` of ``p``'s record taken ``k`` samples late, minus its replay ``rep`` (from the
    replay's sample ``kmax`` on)."""
    return p.rec.raw[ch][k + kmax:] - rep[kmax:p.rec.n - k]


def _lag_terms(prepared, replays, ch: str, k0: int, k: int, kmax: int, settings) -> tuple[float, float, float, float]:
    """(τ [s], c [s²], the squared high-passed difference of channel ``ch`` shifted ``k0`` samples
    with p_m + τ ṗ_m + c p̈_m, that of ``ch`` shifted ``k`` > ``k0`` samples) over the replayed
    samples where both are defined: τ and c ≤ 0 by least squares (the difference linear in them)."""
    G = np.zeros((2, 2))
    b = np.zeros(2)
    ee = s_dead = 0.0
    for p, rr in zip(prepared, replays):
        m = p.rec.n - kmax - k
        e0 = _difference(p, rr[ch], ch, k0, kmax)[:m]
        dp = p.rec.sg["d" + ch][k0 + kmax:][:m]
        ddp = savgol(p.rec.raw[ch], settings.savgol_window, settings.savgol_order, 2, p.rec.dt)[k0 + kmax:][:m]
        e1 = _difference(p, rr[ch], ch, k, kmax)
        ok = np.isfinite(e0) & np.isfinite(dp) & np.isfinite(ddp) & np.isfinite(e1)
        e0, d, dd, e1 = (_highpassed(v, ok)[ok] for v in (e0, dp, ddp, e1))
        X = np.column_stack([d, dd])
        G += X.T @ X
        b += X.T @ e0
        ee, s_dead = ee + float(e0 @ e0), s_dead + float(e1 @ e1)
    theta = -np.linalg.solve(G, b) if np.linalg.det(G) > 0 else np.zeros(2)
    if theta[1] > 0.0:  # a lag's second-order term is ≤ 0 (module docstring): τ alone
        theta = np.array([-b[0] / G[0, 0] if G[0, 0] > 0 else 0.0, 0.0])
    s_lag = ee + 2.0 * float(theta @ b) + float(theta @ G @ theta)
    return float(theta[0]), float(theta[1]), s_lag, s_dead


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
    if not any(ks.values()) and not d.lag_s:
        return records, d, prepared
    records = [unlagged(shifted(r, ks), d.lag_s, d.second_s2, settings) for r in records]
    return records, d, prepare_records(records, plant, condition, settings)

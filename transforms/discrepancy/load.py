"""The unknown external load F_l, estimated where the replay and the motion equation need it.

The motion equation (Eq. 5) integrated twice over ±L samples gives, at every sample k,

    F̂_l(k) = Σ_j w_j (m g + A1 p1 − A2 p2 − F_f(v_X))_{k+j} − m (X_{k+L} − 2 X_k + X_{k−L}) / T²

(triangular weights w, :func:`transforms.discrepancy.residuals.triangular_force_balance`): the
load averaged over the triangle, exactly, if the model is right and the cylinder does not stick
within ±L samples (a sticking cylinder's friction is unknown, anything up to d_s). Such samples
are *valid*. The plant's load is piecewise constant (``model.params.LoadParams``: steps at random
instants), so the estimate is made piecewise constant:

1. **steps.** The valid samples are taken in time order as one sequence (a standstill in between
   simply disappears from it). Around every sample the sequence over ±w samples is fitted by a
   quadratic in time plus a jump after the sample; the jump's coefficient is a fixed linear
   filter (:func:`step_filter`). A slowly varying discrepancy -- a friction or mass change
   follows v_X and dv_X/dt, which change over the 0.3–0.6 s ramps and vanish towards a stop --
   is absorbed by the quadratic; a load step is a jump within the triangle's 2L samples, and a
   step while the cylinder stood still is a jump across the standstill. Local maxima of |jump|
   above max(``step_threshold_n``, ``step_threshold_sigmas`` × robust σ) are steps. A step
   found across a standstill is placed at the first slip fragment of a creeping cylinder in
   between that already shows the new level (pointwise estimate), else at the first valid
   sample after it: the load matters from the breakaway on. (The workflow then moves such a
   step to where a short replay of the standstill fits best, ``transforms.discrepancy.pipeline``.)
2. **levels.** Each segment between steps gets the median of F̂_l over its valid samples
   (those within ``step_guard_samples`` of a step left out); segments without any take the
   level of the next segment (else the previous one).
3. **ramps.** A rolling force is not piecewise constant: it ramps to a new level over 0.1–0.4 s,
   which the step filter's quadratic takes up and does not report. So the load is also fitted
   piecewise linear in time within each segment (knots every ``load_knot_s`` between the
   segment's first and last valid sample, constant beyond them; least squares on F̂_l jointly
   with the velocity and acceleration, so a friction or mass mismatch does not decide it), and
   that fit is kept where it leaves at most 1/``ramp_ratio`` of the constant levels' residual
   RMS and the levels leave more than ``ramp_min_n`` (:func:`follows_ramps`), or where the load on
   the ramps' corners (below) leaves at most 1/``corner_ratio`` of one constant per segment's
   (:func:`corners_pay`: a single ramp at the start of a move hardly moves the grid's ratio, and
   one constant missed a 260 N ramp over 0.5 s on the reference plant, the replay 0.5 mm off over
   that 0.5 s piece). The grid's test compares what the residuals hold above the white noise the
   recorded X leaves in F̂_l (``noise_n2``, subtracted in quadrature): at 10 µm that is ~370 N,
   which drowned a 670 N ramp in the plain ratio (one constant was kept, 318 N off at speed). The
   corner test, which has no floor of its own, stays on the plain ratio: above the noise, a corner
   fit that leaves the noise alone passes any excess, and on `model/`'s plant at 1 µm (~40 N) it
   then followed the noise in segments whose constant left 44–96 N. The regression
   then eliminates the same piecewise-linear load from the motion rows
   (:func:`load_projector`) instead of one constant per segment: a mass acts on the
   acceleration and a friction on the velocity, which change within a move (0.3–0.6 s), faster
   than a load that is linear over 0.1 s can follow, so both stay separable from it.

What the final load leaves of F̂_l along the velocity and the acceleration is the viscous
friction and the mass the model lacks (:func:`motion_mismatch`); the mechanical replay moves the
model's by them, within ``mechanical_friction_rel`` and ``mechanical_mass_rel``; beyond the first,
up to ``load_friction_rel`` more goes into a piecewise-linear load where its knots follow v_X
(:func:`friction_within`). The replay holds the load over each sample interval at its mean there
(:func:`interval_load`).

While the cylinder sticks at the start of a record, before its first observable motion, the load
is unknown (a step may have happened before); the workflow then tries driving the replay with the
load that holds the cylinder (:func:`replay_load`) until it moves and keeps that if it fits better.

The segments also carry the motion equation's nuisance intercepts in the sparse regression
(:mod:`transforms.discrepancy.selection`): one unknown load per segment.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from transforms.discrepancy.corrected import capped_mass_noise, corrected_lstsq
from transforms.discrepancy.settings import DiscrepancySettings

__all__ = ["LoadEstimate", "away_from_steps", "box_half_widths", "box_within", "corners_pay", "estimate_load", "follows_ramps", "friction_within", "interval_load", "load_projector", "load_valid", "missed_knot", "motion_mismatch", "project_out", "ramp_load",
           "replay_load", "second_difference_energy", "segment_knots", "segment_levels", "step_filter", "stuck_spans", "with_missed_knots"]


@lru_cache(maxsize=8)
def _step_kernel(w: int) -> tuple[float, ...]:
    t = np.arange(-w, w + 1, dtype=float) / w
    A = np.column_stack([np.ones_like(t), t, t * t, (t > 0).astype(float)])
    pinv = np.linalg.pinv(A)
    return tuple(float(v) for v in pinv[3])


def step_filter(f: np.ndarray, w: int) -> np.ndarray:
    """Jump at each sample of ``f`` between a quadratic fit over ±w samples and the same plus a
    step after the sample (NaN within w of the ends or where ``f`` is NaN)."""
    k = np.array(_step_kernel(int(w)))
    out = np.full(f.shape, np.nan)
    if f.size < 2 * w + 1:
        return out
    out[w:-w] = np.convolve(f, k[::-1], mode="valid")
    return out


@lru_cache(maxsize=8)
def _kink_kernel(w: int) -> tuple[float, ...]:
    t = np.arange(-w, w + 1, dtype=float)
    A = np.column_stack([np.ones_like(t), t, np.maximum(t, 0.0)])
    return tuple(float(v) for v in np.linalg.pinv(A)[2])


def _kink_filter(f: np.ndarray, w: int) -> np.ndarray:
    """Change of slope [per sample] at each sample of ``f`` between a straight line over ±w samples
    and the same bent at the sample (NaN within w of the ends or of a NaN)."""
    k = np.array(_kink_kernel(int(w)))
    out = np.full(f.shape, np.nan)
    if f.size >= 2 * w + 1:
        out[w:-w] = np.convolve(f, k[::-1], mode="valid")
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the True runs of a boolean array."""
    m = np.r_[False, mask, False].astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


@dataclass(frozen=True)
class LoadEstimate:
    """A piecewise-constant load over one record.

    Attributes
    ----------
    segment : ndarray of int
        Segment number of every sample (0, 1, …).
    steps : ndarray of int
        Sample indices where a new segment starts (the detected steps).
    levels : ndarray
        Load of each segment. [N]
    load : ndarray
        The load at every sample. [N]
    brackets : ndarray of int, shape (len(steps), 2)
        For a step found across a standstill, the last valid sample before it and the first
        after it (where else it may lie); (-1, -1) for a step found while moving.
    valid : ndarray of bool
        Samples whose F̂_l is the load (no sticking within ±L), away from the steps: where
        the levels come from.
    usable : ndarray of bool
        Valid samples with |v_X| > ``v_move_m_s``: where the motion equation is regressed.
    """

    segment: np.ndarray
    steps: np.ndarray
    levels: np.ndarray
    load: np.ndarray
    brackets: np.ndarray
    valid: np.ndarray
    usable: np.ndarray
    hold_until: int = 0
    """A replay holds the cylinder (:func:`replay_load`) while it sticks before this sample:
    the load before the first observable motion was found to differ from the first level."""
    knot_samples: int = 0
    """Knot spacing of the piecewise-linear load within segments (samples); 0: one constant per
    segment (module docstring, step 3)."""
    corners: tuple = ()
    """Per segment, the knots (sample positions) of its piecewise-linear load: its first and last
    valid sample, the ends of its standstills and the ramps' corners (:func:`ramp_load`); empty: the
    regular grid of ``knot_samples``."""
    load_knots: tuple = ()
    """Per segment, the knots the load itself is on: ``corners`` and the missed ones
    (:func:`with_missed_knots`), which shape the load only; empty: ``corners``."""
    friction_mismatch: float = 0.0
    """The viscous friction the model lacks, by what the load leaves of the force balance along
    v_X (:func:`motion_mismatch`). [N s/m]"""
    mass_mismatch: float = 0.0
    """The mass the model lacks, by what the load leaves of the force balance along the
    acceleration (:func:`motion_mismatch`). [kg]"""

    def knots(self, s: int) -> np.ndarray:
        """Knots (sample positions) of segment ``s``'s piecewise-linear load; empty: a constant."""
        if not self.knot_samples:
            return np.zeros(0)
        if self.corners:
            return self.corners[s]
        return segment_knots(self.valid, self.segment, s, self.knot_samples)


    def with_steps(self, steps: np.ndarray, f_hat: np.ndarray, settings: DiscrepancySettings, motion: tuple | None = None) -> "LoadEstimate":
        """The same estimate with the steps moved to ``steps`` (same count, increasing) and the
        levels (and a piecewise-linear load on its ramps' corners, :func:`ramp_load` with the
        ``motion`` columns) re-estimated from ``f_hat``."""
        steps = np.asarray(steps, dtype=np.int64)
        segment = np.zeros(self.segment.size, dtype=np.int64)
        for s in steps:
            segment[s:] += 1
        levels = segment_levels(f_hat, self.valid, segment, len(steps) + 1)
        load = levels[segment]
        corners = ()
        if self.knot_samples:
            knots, load = ramp_load(f_hat, self.valid, self.usable, segment, len(steps) + 1, self.knot_samples, settings, levels, motion)
            load_knots, load = with_missed_knots(f_hat, self.usable, segment, knots, load, levels, self.knot_samples, settings, motion)
            corners = tuple(knots)
        return LoadEstimate(segment, steps, levels, load, self.brackets, self.valid, self.usable, self.hold_until, self.knot_samples, corners,
                            load_knots=tuple(load_knots) if corners else ())

    def refit(self, f_hat: np.ndarray, motion: tuple | None = None) -> "LoadEstimate":
        """The same segments and knots, the levels and the load fitted on ``f_hat`` (jointly with the
        ``motion`` columns where the load ramps, :func:`ramp_load`)."""
        levels = segment_levels(f_hat, self.valid, self.segment, self.levels.size)
        load = levels[self.segment]
        if self.knot_samples:
            knots = list(self.load_knots) if self.load_knots else [self.knots(s) for s in range(self.levels.size)]
            load = _held(_ramp_fit(f_hat, self.usable, self.segment, knots, motion)[0], self.usable, self.segment, levels)
        return replace(self, levels=levels, load=load)

    def with_added_step(self, k: int, guard: int) -> "LoadEstimate":
        """The same estimate with one more step at sample ``k`` (found while moving), the samples
        within ``guard`` of it left out of ``valid`` and ``usable``. Both new segments keep the
        split segment's level and load (what the regression uses are the segments and their knots;
        it eliminates the load)."""
        k = int(k)
        i = int(np.searchsorted(self.steps, k))
        steps = np.insert(self.steps, i, k)
        segment = self.segment + (np.arange(self.segment.size) >= k)
        levels = np.insert(self.levels, i + 1, self.levels[i])
        away = away_from_steps(self.segment.size, [k], guard)
        brackets = np.insert(self.brackets, i, (-1, -1), axis=0)
        valid = self.valid & away
        corners = self.corners
        if corners:  # the split segment's knots: its corners on either side, between its new ends
            kn = corners[i]
            ends = [np.flatnonzero(valid & (segment == s)) for s in (i, i + 1)]
            halves = tuple(np.unique(np.r_[e[0], kn[(kn > e[0]) & (kn < e[-1])], e[-1]]) if e.size > 1 else np.zeros(0) for e in ends)
            corners = corners[:i] + halves + corners[i + 1:]
        return LoadEstimate(segment, steps, levels, self.load, brackets, valid, self.usable & away, self.hold_until, self.knot_samples, corners)


def away_from_steps(n: int, steps, guard: int) -> np.ndarray:
    """Mask of ``n`` samples: False within ``guard`` samples of any of ``steps``, where a load
    estimate's levels hold no sample (the load is unknown there)."""
    away = np.ones(n, dtype=bool)
    for k in steps:
        away[max(0, int(k) - guard):int(k) + guard] = False
    return away


def segment_knots(valid: np.ndarray, segment: np.ndarray, s: int, knot_samples: int) -> np.ndarray:
    """Knots of segment ``s``'s piecewise-linear load: evenly spaced, at most ``knot_samples``
    apart, from its first to its last valid sample (the load is held constant beyond them); empty
    (a constant load) for ``knot_samples`` 0 or fewer than two valid samples."""
    if knot_samples <= 0:
        return np.zeros(0)
    idx = np.flatnonzero(valid & (segment == s))
    if idx.size < 2:
        return np.zeros(0)
    a, b = float(idx[0]), float(idx[-1])
    return np.linspace(a, b, max(1, int(np.ceil((b - a) / knot_samples))) + 1)


def hat_basis(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Piecewise-linear hat functions on ``knots`` at positions ``t``, shape (t.size, knots.size),
    constant beyond the end knots (a single knot: one constant column)."""
    t = np.asarray(t, float)
    B = np.zeros((t.size, knots.size))
    if knots.size == 1:
        B[:, 0] = 1.0
        return B
    j = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
    w = np.clip((t - knots[j]) / (knots[j + 1] - knots[j]), 0.0, 1.0)
    r = np.arange(t.size)
    B[r, j] = 1.0 - w
    B[r, j + 1] = w
    return B


SMOOTHING = 1e-3
"""Second-difference penalty of the piecewise-linear load's knot values (relative to one sample's
weight): it only bridges knots without valid samples (a standstill) linearly."""


def _grid_knots(valid, segment, n_segments, knot_samples) -> list[np.ndarray]:
    """Each segment's regular knots (:func:`segment_knots`; empty for ``knot_samples`` 0)."""
    return [segment_knots(valid, segment, s, knot_samples) for s in range(n_segments)]


def _grid_fit(f_hat, valid, segment, n_segments, knot_samples, motion):
    """:func:`_ramp_fit` on the regular grid of ``knot_samples`` (:func:`_grid_knots`): the fit
    :func:`follows_ramps` decides with and :func:`ramp_load` starts from, made once for both."""
    return _ramp_fit(f_hat, valid, segment, _grid_knots(valid, segment, n_segments, knot_samples), motion)


def _load_design(f_hat, valid, segment, knots: list[np.ndarray], motion):
    """(the ``valid`` samples where ``f_hat`` and the ``motion`` columns are finite, each segment's
    load columns there: hat functions on its ``knots``, one constant where they are empty, zero
    outside the segment; the motion columns there, or None)."""
    m = valid & np.isfinite(f_hat)
    M = None
    if motion is not None:
        M = np.column_stack(motion)
        m &= np.all(np.isfinite(M), axis=1)
    idx = np.flatnonzero(m)
    cols = [hat_basis(kn if kn.size else np.zeros(1), idx) * (segment[idx] == s)[:, None] for s, kn in enumerate(knots)]
    return idx, cols, None if M is None else M[idx]


RAMP_FIT_BLOCK = 256
"""Rows per block that :func:`_ramp_fit` reduces by a QR before its least squares."""


def _hat_entries(knots: list[np.ndarray], segment: np.ndarray, idx: np.ndarray):
    """The load columns of :func:`_load_design` as two entries per row (sample ``idx``): (first
    column, its weight, second column, its weight, number of load columns); a segment without
    knots has one constant column (weight 1, and 0 on the same column)."""
    n = idx.size
    c0, c1 = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    w0, w1 = np.zeros(n), np.zeros(n)
    off = 0
    seg = segment[idx]
    for s, kn in enumerate(knots):
        rows = np.flatnonzero(seg == s)
        if kn.size < 2:
            c0[rows], c1[rows], w0[rows] = off, off, 1.0
        else:
            t = idx[rows].astype(float)
            j = np.clip(np.searchsorted(kn, t, side="right") - 1, 0, kn.size - 2)
            w = np.clip((t - kn[j]) / (kn[j + 1] - kn[j]), 0.0, 1.0)
            c0[rows], c1[rows], w0[rows], w1[rows] = off + j, off + j + 1, 1.0 - w, w
        off += max(kn.size, 1)
    return c0, w0, c1, w1, off


def _reduced_rows(c0, w0, c1, w1, M, y, n_cols: int):
    """(R, Qᵀy) with the same least-squares solutions as the rows (two load entries each, the
    dense ``M`` columns after the ``n_cols`` load columns, right-hand side ``y``): each block of
    :data:`RAMP_FIT_BLOCK` rows replaced by the R of its QR on the columns it touches (an
    orthogonal transform of those rows)."""
    n, nm = y.size, M.shape[1]
    if n == 0:
        return np.zeros((0, n_cols + nm)), np.zeros(0)
    B = RAMP_FIT_BLOCK
    nb = -(-n // B)
    pad = nb * B - n
    c0, c1 = np.r_[c0, np.full(pad, c0[-1])].reshape(nb, B), np.r_[c1, np.full(pad, c1[-1])].reshape(nb, B)
    w0, w1 = np.r_[w0, np.zeros(pad)].reshape(nb, B), np.r_[w1, np.zeros(pad)].reshape(nb, B)
    lo = np.minimum(c0.min(axis=1), c1.min(axis=1))
    width = int(np.max(np.maximum(c0.max(axis=1), c1.max(axis=1)) - lo)) + 1
    W = width + nm
    blocks = np.zeros((nb, B, W))
    b, r = np.arange(nb)[:, None], np.arange(B)[None, :]
    blocks[b, r, c1 - lo[:, None]] = w1
    blocks[b, r, c0 - lo[:, None]] += w0
    blocks[:, :, width:] = np.r_[M, np.zeros((pad, nm))].reshape(nb, B, nm)
    Q, R = np.linalg.qr(blocks)
    qy = np.einsum("bij,bi->bj", Q, np.r_[y, np.zeros(pad)].reshape(nb, B))
    k = R.shape[1]
    # a block's load columns lo .. lo + width - 1 (past n_cols, padding: R is exactly 0 there)
    A = np.zeros((nb, k, n_cols + width))
    A[np.arange(nb)[:, None, None], np.arange(k)[None, :, None], (lo[:, None] + np.arange(width))[:, None, :]] = R[:, :, :width]
    return np.hstack([A.reshape(nb * k, -1)[:, :n_cols], R[:, :, width:].reshape(nb * k, nm)]), qy.reshape(-1)


def _ramp_fit(f_hat, valid, segment, knots: list[np.ndarray], motion):
    """Least squares of ``f_hat`` over the valid samples on the segments' load (piecewise linear on
    each segment's ``knots``, a constant where they are empty) and the ``motion`` columns; returns
    (load at every sample, RMS residual, the motion columns' coefficients). The rows are reduced
    block by block (:func:`_reduced_rows`) before the least squares, which truncates the singular
    values as on the whole rows (relative ``eps`` × their number)."""
    n = f_hat.size
    m = valid & np.isfinite(f_hat)
    M = np.zeros((n, 0))
    if motion is not None:
        M = np.column_stack(motion)
        m &= np.all(np.isfinite(M), axis=1)
    idx = np.flatnonzero(m)
    M = M[idx]
    c0, w0, c1, w1, k = _hat_entries(knots, segment, idx)
    spans = []
    off = 0
    for kn in knots:
        kn = kn if kn.size else np.zeros(1)
        spans.append((off, kn))
        off += kn.size
    N = k + M.shape[1]
    D = []
    for o, kn in spans:
        if kn.size > 2:
            d = np.zeros((kn.size - 2, N))
            for i in range(kn.size - 2):
                d[i, o + i:o + i + 3] = (1.0, -2.0, 1.0)
            D.append(d)
    R, qy = _reduced_rows(c0, w0, c1, w1, M, f_hat[idx], k)
    A = np.vstack([R] + [SMOOTHING * d for d in D])
    y = np.r_[qy, np.zeros(A.shape[0] - qy.size)]
    n_rows = idx.size + sum(d.shape[0] for d in D)
    c = np.linalg.lstsq(A, y, rcond=np.finfo(float).eps * max(n_rows, N))[0]
    res = f_hat[idx] - (w0 * c[c0] + w1 * c[c1] + M @ c[k:])
    rms = float(np.sqrt(np.mean(res ** 2))) if idx.size else 0.0
    load = np.zeros(n)
    for s, (o, kn) in enumerate(spans):
        sel = segment == s
        load[sel] = hat_basis(kn, np.flatnonzero(sel)) @ c[o:o + kn.size] if kn.size > 1 else c[o]
    return load, rms, c[k:]


def robust_sigma(v: np.ndarray) -> float:
    """Robust scale of ``v``'s finite values: 1.4826 × their median absolute deviation (the
    standard deviation for Gaussian values, untouched by a few outliers); 0 with ≤ 10 of them."""
    v = v[np.isfinite(v)]
    return 1.4826 * float(np.median(np.abs(v - np.median(v)))) if v.size > 10 else 0.0


def _corners(rest: np.ndarray, valid: np.ndarray, segment: np.ndarray, n_segments: int, W: int, dt: float, settings: DiscrepancySettings,
             knots: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """Per segment the knots of a piecewise-linear ``rest`` [N] on the ``valid`` samples: those of
    ``knots`` (default: the segment's first and last valid sample and the ends of every gap between
    valid samples, where the load is not observed) and the corners the kink filter finds (slope
    change over ±``W`` samples, local maxima of at least ``settings.corner_min_n_s`` and
    ``settings.corner_sigmas`` robust σ of the filter's output, more than ``W`` from a knot)."""
    kink = _kink_filter(np.where(valid, rest, np.nan), W) / dt  # slope change at every sample [N/s]
    ok = np.isfinite(kink)
    thr = max(settings.corner_min_n_s, settings.corner_sigmas * robust_sigma(kink))
    ak = np.where(ok, np.abs(kink), 0.0)
    out = []
    for s in range(n_segments):
        idx = np.flatnonzero(valid & (segment == s))
        if idx.size < 2:
            out.append(np.zeros(0))
            continue
        if knots is None:
            gap = np.flatnonzero(np.diff(idx) > 1)
            found = np.r_[idx[0], idx[gap], idx[gap + 1], idx[-1]].astype(float)
        else:
            found = knots[s]
        new = [j for j in idx[ak[idx] > thr]
               if ak[j] >= ak[max(0, j - W):j + W + 1].max() and not (ak[max(0, j - W):j] == ak[j]).any()
               and (found.size == 0 or np.min(np.abs(found - j)) > W)]
        out.append(np.unique(np.r_[found, np.asarray(new, float)]))
    return out


def _corner_width(knot_samples: int, settings: DiscrepancySettings) -> int:
    """Half-width of the ±``settings.corner_half_width_s`` kink filter in samples (the sample
    interval being ``settings.load_knot_s`` / ``knot_samples``); at least 2."""
    return max(2, int(round(settings.corner_half_width_s * knot_samples / settings.load_knot_s)))


def ramp_load(f_hat: np.ndarray, valid: np.ndarray, usable: np.ndarray, segment: np.ndarray, n_segments: int, knot_samples: int,
              settings: DiscrepancySettings, levels: np.ndarray, motion: tuple | None = None, grid: tuple | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """(per segment the knots, the load at every sample [N]) of a load that is piecewise linear
    within segments and bends only at the ramps' corners and where the cylinder stood still:

    1. the load on the regular grid of ``knot_samples`` jointly with the ``motion`` columns gives
       a first friction and mass mismatch (a grid that coarse cannot follow them), taken off
       ``f_hat`` to find the corners;
    2. knots at the segments' ends, at the ends of every gap between ``valid`` samples (a load
       that changed while the cylinder stood still or crept) and at the corners of that rest
       (:func:`_corners`);
    3. ``f_hat`` fitted piecewise linear on those knots jointly with the ``motion`` columns (whose
       part is not load) over the ``usable`` samples (moving past the breakaway, where the friction
       model holds; at creeping speeds a Stribeck error of the model would set the load); corners
       the fit missed are looked for in its residual (up to twice) and the fit repeated (a missed
       corner made the velocity column take 14 kN·s/m and the load 1.4 kN off over a record);
    4. the same (up to twice) with the kink filter ``settings.corner_coarse_factor`` times wider
       and the slope floor ``corner_min_n_s`` divided by that factor^1.5 (the filter's noise falls
       as its width^-1.5): a gentle ramp (a few hundred newtons over 0.3 s, 1–2.5 kN/s) hides in
       the noise of the ±W filter, and a load that misses it lets the velocity and acceleration
       columns take its error, so the load drifts over the whole record (reference plant seed 1:
       75 N RMS off at speed, 10 N with this pass);
    5. (:func:`with_missed_knots`, where the ramps are followed) up to
       ``settings.knot_insertions`` single knots, each where it takes most of the fit's
       residual (:func:`missed_knot`): a corner both filters miss or misplace (reference plant
       seed 3 with a new load level every second, window 0: an 8 kN ramp ends at 6.51 s, the
       filters bent the load at 6.35 s; with the plant's true cylinder the mechanical replay went
       0.023 → 0.015 mm, the true load's 0.013 mm). A ramp while the cylinder slows to a stop is
       not taken where its tent follows v_X (seed 4, window 1: 200 N over 8.25–8.63 s, 0.027 mm
       with the true load's 0.011 mm): there the load and the friction cannot be told apart.
       These knots shape the load the replay integrates only: the knots this function returns,
       which the regression eliminates the load on (:func:`load_projector`) and the fits above
       decide with, are the filters'. Chosen where the residual under one model holds most, they
       took part of an effect's pattern there (reference plant seed 4 without commissioning: the clean valve's
       excess along a p1 gain 2.5σ → 4σ, `ambiguous`, and a friction change and a spool offset
       read as that gain).

    A free slope over a long piece between ramps may trade with the velocity column (reference
    plant seed 2: the load 43 N off at speed over 1–2 s levels after steep ramps); the mechanical
    replay takes that column's part as friction (:func:`motion_mismatch`), so what it replays is
    the joint fit. (Such pieces were once tied to one value, which left missed gentle ramps inside
    them to the velocity column; docs/discrepancy.md, "How it works".)

    A segment without usable samples keeps its ``levels`` value. ``grid``: step 1's fit
    (:func:`_grid_fit`) where already made."""
    W = _corner_width(knot_samples, settings)
    dt = settings.load_knot_s / knot_samples

    def motion_part(cm):
        if motion is None:
            return 0.0
        mcols = np.column_stack(motion)
        return np.where(np.all(np.isfinite(mcols), axis=1), mcols @ cm, 0.0)

    _, _, cm = _grid_fit(f_hat, valid, segment, n_segments, knot_samples, motion) if grid is None else grid
    knots = _corners(f_hat - motion_part(cm), valid, segment, n_segments, W, dt, settings)
    f = settings.corner_coarse_factor
    load, _, cm = _ramp_fit(f_hat, usable, segment, knots, motion)
    for w, s_w in ((W, settings), (max(W + 1, int(round(W * f))), replace(settings, corner_min_n_s=settings.corner_min_n_s / f ** 1.5))):
        for _ in range(2):
            more = _corners(f_hat - motion_part(cm) - load, valid, segment, n_segments, w, dt, s_w, knots)
            if all(a.size == b.size for a, b in zip(more, knots)):
                break
            knots = more
            load, _, cm = _ramp_fit(f_hat, usable, segment, knots, motion)
    return knots, _held(load, usable, segment, levels)


def _held(load: np.ndarray, usable: np.ndarray, segment: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """``load`` with each segment without usable samples at its ``levels`` value."""
    for s in range(levels.size):
        if not np.any(usable[segment == s]):
            load[segment == s] = levels[s]
    return load


def with_missed_knots(f_hat: np.ndarray, usable: np.ndarray, segment: np.ndarray, knots: list[np.ndarray], load: np.ndarray, levels: np.ndarray,
                      knot_samples: int, settings: DiscrepancySettings, motion: tuple | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """(knots, load [N]): the load of :func:`ramp_load` (its ``knots`` and ``load``) with up to
    ``settings.knot_insertions`` more knots, one at a time where the joint fit's residual holds most
    (:func:`missed_knot`; :func:`ramp_load`'s step 5). Made only where the ramps are followed: the
    decision and the regression keep the filters' knots."""
    W = _corner_width(knot_samples, settings)
    more = list(knots)
    added = False
    for _ in range(settings.knot_insertions):
        k = missed_knot(f_hat, usable, segment, more, motion, W, settings.knot_rss_share, 2 * settings.interval_samples + 1,
                        settings.knot_velocity_corr2)
        if k is None:
            break
        more[k[0]] = np.unique(np.r_[more[k[0]], float(k[1])])
        added = True
    if not added:
        return list(knots), load
    return more, _held(_ramp_fit(f_hat, usable, segment, more, motion)[0], usable, segment, levels)


def _column_basis(X: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the columns of ``X`` (QR, columns with a negligible diagonal of R
    dropped)."""
    Q, R = np.linalg.qr(X)
    d = np.abs(np.diag(R))
    return Q[:, d > 1e-9 * d.max()]


class _TentProducts:
    """Products with the tent functions of knots (a, c, b), c each of ``cands``: 0 at a and b, 1
    at c, linear between, on the samples ``sub`` (sorted) and 0 where ``inside`` is False. A
    tent's products are its rising part's prefix sum over the samples up to c and its falling
    part's suffix sum after it, so every candidate costs O(1) once the sums are made."""

    def __init__(self, sub: np.ndarray, inside: np.ndarray, a: float, b: float, cands: np.ndarray):
        self.up, self.down = np.where(inside, sub - a, 0.0), np.where(inside, b - sub, 0.0)
        self.split = np.searchsorted(sub, cands, side="right")  # the samples at or before c rise
        self.rise, self.fall = 1.0 / (cands - a), 1.0 / (b - cands)

    def _sums(self, terms_up: np.ndarray, terms_down: np.ndarray, power: int = 1) -> np.ndarray:
        """Σ terms_up over each tent's rising samples × its rise**power, plus the same of
        terms_down over its falling samples and its fall."""
        z = np.zeros((1,) + terms_up.shape[1:])
        before = np.concatenate([z, np.cumsum(terms_up, axis=0)])
        after = np.concatenate([np.cumsum(terms_down[::-1], axis=0)[::-1], z])
        w = (slice(None),) + (None,) * (terms_up.ndim - 1)
        return before[self.split] * (self.rise ** power)[w] + after[self.split] * (self.fall ** power)[w]

    def dot(self, y: np.ndarray) -> np.ndarray:
        """yᵀ t for every tent t: (candidates,) for y (samples,), (candidates, k) for y (samples, k)."""
        w = (slice(None),) + (None,) * (y.ndim - 1)
        return self._sums(y * self.up[w], y * self.down[w])

    def dot_self(self) -> np.ndarray:
        """tᵀ t for every tent t."""
        return self._sums(self.up * self.up, self.down * self.down, 2)


def missed_knot(f_hat: np.ndarray, usable: np.ndarray, segment: np.ndarray, knots: list[np.ndarray], motion: tuple | None, W: int,
                share: float, lowpass: int, max_corr2: float, stride: int = 5) -> tuple[int, float] | None:
    """(segment, sample) of the one knot that, added to ``knots``, takes the most of the residual
    sum of squares of the joint fit (:func:`_ramp_fit` without its smoothing rows, the ``motion``
    columns included) over the ``usable`` samples; None unless that is at least ``share`` of the
    sum of squares of the residual's mean over ``lowpass`` samples.

    A knot between two knots adds their tent function to the load's basis, so its gain is
    (rᵀt)² / |t⊥|² with r the residual and t⊥ the tent apart from the fit's columns. Candidates
    are every ``stride``-th usable sample with ``W`` usable samples on either side (a knot where
    there are none would be a guess) and more than ``W`` samples from a knot. The yardstick is the
    residual's slow part: the force balance's noise is mostly the position's second difference
    over the triangle (:func:`transforms.discrepancy.residuals.triangular_force_balance`), which
    has no power at the slow rates a load ramps at, so it would hide a missed ramp in a share of
    the whole residual.
    A candidate whose tent, apart from the other load columns and the acceleration, has a squared
    correlation above ``max_corr2`` with v_X (the first ``motion`` column) is not taken: it would
    trade with the friction, which is a finding, not load."""
    idx, cols, M = _load_design(f_hat, usable, segment, knots, motion)
    if idx.size < 50:
        return None
    X = np.hstack(cols if M is None else cols + [M])
    Q = _column_basis(X)
    r = f_hat[idx] - Q @ (Q.T @ f_hat[idx])
    v0 = None
    if M is not None:  # v_X apart from the load and the acceleration: what tells the friction
        Q0 = _column_basis(np.hstack(cols + [M[:, 1:]]))
        v0 = M[:, 0] - Q0 @ (Q0.T @ M[:, 0])
        vv = float(v0 @ v0)
    best = (0.0, None)
    for s, kn in enumerate(knots):
        for a, b in zip(kn[:-1], kn[1:]):
            lo, hi = np.searchsorted(idx, a), np.searchsorted(idx, b, side="right")
            if hi - lo < 10:
                continue
            sub = idx[lo:hi].astype(float)
            cands = sub[W:sub.size - W:stride]  # with W usable samples on either side
            cands = cands[(cands > a + W) & (cands < b - W)]
            if not cands.size:
                continue
            tent = _TentProducts(sub, segment[idx[lo:hi]] == s, a, b, cands)
            tt = tent.dot_self()
            qt = tent.dot(Q[lo:hi])
            den = tt - np.einsum("jk,jk->j", qt, qt)
            ok = den > 1e-9 * tt
            score = np.where(ok, tent.dot(r[lo:hi]) ** 2 / np.where(ok, den, 1.0), 0.0)
            if v0 is not None:
                q0 = tent.dot(Q0[lo:hi])
                score[tent.dot(v0[lo:hi]) ** 2 > max_corr2 * (tt - np.einsum("jk,jk->j", q0, q0)) * vv] = 0.0
            j = int(np.argmax(score))
            if score[j] > best[0]:
                best = (float(score[j]), (s, float(cands[j])))
    full = np.zeros(f_hat.size)
    full[idx] = r
    slow = np.convolve(full, np.ones(lowpass) / lowpass, mode="same")[idx]
    if best[1] is None or best[0] < share * float(slow @ slow):
        return None
    return best[1]


def _above_noise(rms: float, noise_n2: float) -> float:
    """What a residual RMS [N] holds above white noise of variance ``noise_n2`` [N²]."""
    return float(np.sqrt(max(rms * rms - noise_n2, 0.0)))


def follows_ramps(f_hat: np.ndarray, valid: np.ndarray, segment: np.ndarray, n_segments: int, knot_samples: int, settings: DiscrepancySettings,
                  motion: tuple | None = None, grid: tuple | None = None, noise_n2: float = 0.0) -> bool:
    """Does the load vary within its segments? The piecewise-linear fit on the regular grid of
    ``knot_samples`` (jointly with the ``motion`` columns) leaves at most 1/``settings.ramp_ratio``
    of the residual RMS of one constant per segment (jointly with the same columns), and that is
    above ``settings.ramp_min_n``; both RMS taken above white noise of variance ``noise_n2`` [N²]
    (:func:`_above_noise`). ``grid``: the grid's fit (:func:`_grid_fit`) where already made."""
    if knot_samples <= 0:
        return False
    _, rms_const, _ = _ramp_fit(f_hat, valid, segment, _grid_knots(valid, segment, n_segments, 0), motion)
    _, rms_ramp, _ = _grid_fit(f_hat, valid, segment, n_segments, knot_samples, motion) if grid is None else grid
    const, ramp = _above_noise(rms_const, noise_n2), _above_noise(rms_ramp, noise_n2)
    return const > settings.ramp_min_n and ramp * settings.ramp_ratio <= const


def corners_pay(f_hat: np.ndarray, usable: np.ndarray, segment: np.ndarray, n_segments: int, knots: list[np.ndarray], settings: DiscrepancySettings,
                motion: tuple | None = None) -> bool:
    """Does the load on its ramps' corners (``knots``, :func:`ramp_load`) leave materially less of
    ``f_hat`` than one constant per segment, where :func:`follows_ramps` found the 0.1 s grid does
    not? Both fitted jointly with the ``motion`` columns over the ``usable`` samples; the corner
    fit's residual RMS is at most 1/``settings.corner_ratio`` of the constants'. Where its corners
    are right, the corner fit leaves the force balance's noise, so this asks whether the ramps stand
    out of that noise; the grid, with its many more columns, hardly changes its residual for one
    ramp at the start of one move (a 260 N ramp over 0.5 s: one constant leaves 1.8× the grid's,
    and 1.8× the corner fit's)."""
    _, rms_const, _ = _ramp_fit(f_hat, usable, segment, [np.zeros(0)] * n_segments, motion)
    _, rms_corner, _ = _ramp_fit(f_hat, usable, segment, knots, motion)
    return rms_corner * settings.corner_ratio <= rms_const


def motion_mismatch(f_hat: np.ndarray, load: np.ndarray, usable: np.ndarray, motion: tuple, noise: tuple | None = None) -> tuple[float, float]:
    """(Δd_v [N s/m], Δm [kg]): the least squares of what ``load`` leaves of the force balance
    ``f_hat`` on the ``motion`` columns (v_X, the acceleration) over the ``usable`` samples. The
    force balance is the load plus Δd_v v_X + Δm a where the model's viscous friction and mass are
    Δd_v and Δm short of the plant's (the weight Δm g a load cannot tell from its own level); where
    the load was fitted jointly with these columns (:func:`ramp_load`) these are the joint fit's
    coefficients. (0, 0) with fewer than 10 samples.

    ``noise`` (the acceleration's noise variance per sample [m²/s⁴], the model's mass [kg]): the
    recorded position's noise enters the acceleration and, times the mass, the force balance, so
    plain least squares reads Δm short (errors in variables; at 10 µm and unaveraged, 1–3 t of the
    reference plant's 6 t); the fit then takes that noise's expected part out
    (:func:`transforms.discrepancy.corrected.corrected_lstsq`)."""
    M = np.column_stack(motion)
    m = usable & np.isfinite(f_hat) & np.isfinite(load) & np.all(np.isfinite(M), axis=1)
    if m.sum() < 10:
        return 0.0, 0.0
    A, b = M[m], (f_hat - load)[m]
    if noise is None:
        dv, dm = np.linalg.lstsq(A, b, rcond=None)[0]
    else:
        g = np.array([0.0, 1.0])
        dv, dm = corrected_lstsq(A, b, g, capped_mass_noise(float(np.sum(noise[0][m])), A, g), noise[1])[0]
    return float(dv), float(dm)


def load_projector(group: np.ndarray, sample: np.ndarray, knots: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """The least-squares elimination of the load from motion rows (Frisch–Waugh): per group
    (record × segment) its rows' positions and an orthonormal basis Q of its load columns
    (one constant, or the hat functions on ``knots[group]`` at the rows' ``sample``); a value
    vector loses Q Qᵀ of itself (:func:`project_out`)."""
    out = []
    for g in np.unique(group):
        pos = np.flatnonzero(group == g)
        kn = knots.get(int(g))
        if kn is None or kn.size < 2:
            out.append((pos, np.full((pos.size, 1), 1.0 / np.sqrt(pos.size))))
            continue
        B = hat_basis(kn, sample[pos])
        U, sv, _ = np.linalg.svd(B, full_matrices=False)
        out.append((pos, U[:, sv > 1e-9 * sv[0]]))
    return out


def project_out(values: np.ndarray, projector: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """``values`` (shape (n,) or (n, k)) minus their least-squares fit on each group's load
    columns (:func:`load_projector`)."""
    out = np.array(values, dtype=float, copy=True)
    for pos, Q in projector:
        v = out[pos]
        out[pos] = v - Q @ (Q.T @ v)
    return out


def segment_levels(f_hat: np.ndarray, valid: np.ndarray, segment: np.ndarray, n_segments: int) -> np.ndarray:
    """Median of ``f_hat`` over the valid samples of each segment; segments without any take the
    next segment's level (else the previous one's, else 0)."""
    levels = np.full(n_segments, np.nan)
    for s in range(n_segments):
        sel = valid & (segment == s) & np.isfinite(f_hat)
        if sel.any():
            levels[s] = float(np.median(f_hat[sel]))
    if np.all(np.isnan(levels)):
        return np.zeros(n_segments)
    for s in range(n_segments - 2, -1, -1):  # backward fill
        if np.isnan(levels[s]):
            levels[s] = levels[s + 1]
    for s in range(1, n_segments):  # forward fill what is left at the end
        if np.isnan(levels[s]):
            levels[s] = levels[s - 1]
    return levels


def _not_stuck(f: np.ndarray, v: np.ndarray, settings: DiscrepancySettings) -> np.ndarray:
    """Samples with ``f`` and ``v`` finite and |v| above ``v_load_m_s``."""
    return np.isfinite(f) & np.isfinite(v) & (np.abs(v) > settings.v_load_m_s)


def load_valid(f: np.ndarray, v: np.ndarray, settings: DiscrepancySettings) -> np.ndarray:
    """The samples where the force balance ``f`` [N] is the load: finite, and the cylinder's
    velocity ``v`` [m/s] above ``v_load_m_s`` on every sample within ``interval_samples`` (a
    sticking cylinder's friction is unknown)."""
    return _window_all(_not_stuck(f, v, settings), settings.interval_samples)


def box_within(y: np.ndarray, ok: np.ndarray, half: int) -> np.ndarray:
    """Centred moving average of ``y`` over up to 2·``half`` + 1 samples, the window shrunk at each
    sample of ``ok`` to stay within its run of ``ok`` samples (so a record's ends and a standstill's
    edges keep their samples, averaged over fewer); ``y`` itself where not ``ok``. An average of
    exact load readings is an exact reading of the averaged load."""
    y = np.asarray(y, float)
    h = box_half_widths(ok, half)
    k = np.flatnonzero(ok)
    c = np.r_[0.0, np.cumsum(np.where(ok, y, 0.0))]
    out = y.copy()
    out[k] = (c[k + h[k] + 1] - c[k - h[k]]) / (2 * h[k] + 1)
    return out


def box_half_widths(ok: np.ndarray, half: int) -> np.ndarray:
    """The half-widths :func:`box_within` averages over at each sample (0 where not ``ok``)."""
    h = np.zeros(ok.size, dtype=np.int64)
    for a, b in _runs(ok):
        k = np.arange(a, b)
        h[a:b] = np.minimum(max(int(half), 0), np.minimum(k - a, b - 1 - k))
    return h


@lru_cache(maxsize=64)
def second_difference_energy(length: int, half: int) -> float:
    """Σ c² of the weights c that take the second difference X₊ − 2X + X₋ over ±``length``
    samples averaged over 2·``half`` + 1 shifts: its noise power per unit of white noise power
    (6 unaveraged; 0.27 over 21 shifts of a 20-sample difference)."""
    d = np.zeros(2 * length + 1)
    d[[0, length, 2 * length]] = (1.0, -2.0, 1.0)
    return float(np.sum(np.convolve(d, np.full(2 * half + 1, 1.0 / (2 * half + 1))) ** 2))


def _window_all(mask: np.ndarray, half: int) -> np.ndarray:
    """True where ``mask`` holds on every sample of [k − half, k + half]."""
    n = mask.size
    c = np.r_[0, np.cumsum(mask.astype(np.int64))]
    k = np.arange(n)
    lo = k - half
    hi = k + half + 1
    ok = (lo >= 0) & (hi <= n)
    out = np.zeros(n, dtype=bool)
    out[ok] = (c[hi[ok]] - c[lo[ok]]) == (2 * half + 1)
    return out


def _place_in_gap(j: int, idx: np.ndarray, f_hat: np.ndarray, f_point: np.ndarray | None, not_stuck: np.ndarray, w: int) -> int:
    """Where a step found between valid samples idx[j] and idx[j + 1] starts: the first slip
    fragment in between whose pointwise load is nearer the new level than the old one, else
    idx[j + 1]."""
    a, b = int(idx[j]), int(idx[j + 1]) if j + 1 < idx.size else int(idx[j])
    if f_point is None or b - a <= 1:
        return b
    old = float(np.median(f_hat[idx[max(0, j - w + 1):j + 1]]))
    new = float(np.median(f_hat[idx[j + 1:j + 1 + w]]))
    for fa, fb in _runs(not_stuck[a + 1:b]):
        vals = f_point[a + 1 + fa:a + 1 + fb]
        if not np.all(np.isfinite(vals)):
            continue
        if abs(float(np.median(vals)) - new) < abs(float(np.median(vals)) - old):
            # the split within the fragment that fits (old | new) best
            c_old = np.r_[0.0, np.cumsum((vals - old) ** 2)]
            c_new = np.r_[0.0, np.cumsum((vals - new) ** 2)]
            cost = c_old + (c_new[-1] - c_new)
            return a + 1 + fa + int(np.argmin(cost))
    return b


def stuck_spans(v: np.ndarray, v_stuck: float, min_samples: int = 5) -> np.ndarray:
    """True on runs of at least ``min_samples`` samples with |v_X| ≤ ``v_stuck``: where the
    cylinder sticks and its load cannot be observed."""
    m = np.isfinite(v) & (np.abs(v) <= v_stuck)
    out = np.zeros(v.size, dtype=bool)
    for a, b in _runs(m):
        if b - a >= min_samples:
            out[a:b] = True
    return out


def friction_within(est: LoadEstimate, v: np.ndarray, limit: float, load_limit: float) -> LoadEstimate:
    """``est`` with its friction mismatch beyond ±``limit`` [N s/m] (the most the mechanical replay
    moves the model's viscous friction by, ``rows._mechanical_model``) moved into the load, up to
    ``load_limit`` [N s/m] of it, where the load is piecewise linear (:func:`ramp_load`): along the
    part of ``v`` [m/s] that the load's own basis follows (least squares per segment over the
    usable samples), which the joint fit cannot tell from a load. In a long slow move whose speed
    is nearly linear between the load's knots the two trade freely; on the reference plant's seed
    4 with 1 s loads, window 1, 3.9 mm/s RMS of v_X's 99 mm/s lay off the basis, the velocity
    column took −2,620 N s/m and the load was 260 N off. The replay took only the first −1,000,
    and X was 0.38 mm off. Only the moved part times what the basis cannot follow then stays out
    of the replay. A larger mismatch (a friction change of the library's typical 20 %) keeps all
    but ``limit`` + ``load_limit`` of itself in the force balance."""
    c = est.friction_mismatch
    excess = float(np.clip(c - np.clip(c, -limit, limit), -load_limit, load_limit))
    if excess == 0.0 or not est.knot_samples:
        return est
    ok = est.usable & np.isfinite(v)
    along = np.zeros(est.load.size)
    for s in range(len(est.levels)):
        kn, sel = est.knots(s), est.segment == s
        fit = np.flatnonzero(ok & sel)
        if kn.size == 0 or fit.size < kn.size:
            continue
        beta = np.linalg.lstsq(hat_basis(kn, fit), v[fit], rcond=None)[0]
        along[sel] = hat_basis(kn, np.flatnonzero(sel)) @ beta
    return replace(est, load=est.load + excess * along, friction_mismatch=c - excess)


def interval_load(est: LoadEstimate) -> np.ndarray:
    """The load a replay holds over each sample interval [k, k + 1) [N] (``model.replay`` holds
    F_l between samples): within a segment the mean of the estimate at the interval's two ends,
    exact for its piecewise-linear ramps; across a step the level before it. Holding the sample's
    value instead puts a ramp's force half a sample late: on the reference plant's load ramps of
    up to 63 kN/s that is 32 N for the ramp's 0.1–0.4 s, and the mechanical replay of a clean
    valve, noise-free and with the true load, was 0.039 mm off over such a 0.5 s piece (0.001 mm
    elsewhere)."""
    load = np.asarray(est.load, dtype=float)
    out = load.copy()
    within = est.segment[1:] == est.segment[:-1]
    out[:-1][within] = 0.5 * (load[:-1][within] + load[1:][within])
    return out


def replay_load(levels_per_sample: np.ndarray, holding_force: np.ndarray, stuck: np.ndarray) -> np.ndarray:
    """The load a replay is driven with: the segment levels, except while the measured cylinder
    sticks, where the load cannot be observed and only decides when it breaks away: there the
    force that holds the cylinder, m g + A1 p1 − A2 p2 (measured, F_R = 0), so the replayed
    cylinder rests while the real one does and breaks away when the real one does."""
    out = np.array(levels_per_sample, dtype=float, copy=True)
    sel = stuck & np.isfinite(holding_force)
    out[sel] = holding_force[sel]
    return out


def estimate_load(f_hat: np.ndarray, v: np.ndarray, settings: DiscrepancySettings, f_point: np.ndarray | None = None,
                  accel: np.ndarray | None = None, dt: float | None = None, noise_n2: float = 0.0) -> LoadEstimate:
    """Piecewise-constant load of one record from the triangular force balance ``f_hat`` [N]
    (:func:`transforms.discrepancy.residuals.triangular_force_balance` with
    ``settings.interval_samples``) and the cylinder velocity ``v`` [m/s] (module docstring).

    ``f_point`` (optional): a pointwise load estimate (with a Savitzky–Golay acceleration),
    noisier but available in the short slip fragments of a creeping cylinder; a step found
    across a standstill is then placed at the first fragment that already shows the new level
    (a load step is often what makes a resting cylinder creep).

    ``accel`` [m/s²] (the acceleration averaged as in ``f_hat``) and ``dt`` [s]: with both, the
    load is made piecewise linear within segments where it ramps (module docstring, step 3),
    judged above white noise of variance ``noise_n2`` in ``f_hat`` [N²] (X's, 0 if unknown)."""
    n = f_hat.size
    w = settings.step_half_width
    L = settings.interval_samples
    not_stuck = _not_stuck(f_hat, v, settings)
    valid = _window_all(not_stuck, L)
    idx = np.flatnonzero(valid)
    steps: list[int] = []
    brackets: dict[int, tuple[int, int]] = {}
    if idx.size >= 2 * w + 1:
        jump = step_filter(f_hat[idx], w)
        ok = np.isfinite(jump)
        thr = max(settings.step_threshold_n, settings.step_threshold_sigmas * robust_sigma(jump))
        aj = np.where(ok, np.abs(jump), 0.0)
        last = -10 * w
        for j in np.flatnonzero(aj > thr):
            lo, hi = max(0, j - w), min(idx.size, j + w + 1)
            if aj[j] >= aj[lo:hi].max() and j - last > w:
                # the largest gap between valid samples near the peak: a step across a standstill
                gaps = np.diff(idx[lo:hi])
                g = int(np.argmax(gaps)) + lo if gaps.size else j
                if gaps.size and gaps.max() > 2 * L + 1:
                    steps.append(_place_in_gap(g, idx, f_hat, f_point, not_stuck, w))
                    # where else it may lie: the whole neighbourhood of the peak
                    brackets[steps[-1]] = (int(idx[lo]), int(idx[hi - 1]))
                else:
                    steps.append(int(idx[j + 1]) if j + 1 < idx.size else int(idx[j]))
                last = j
    steps_arr = np.array(sorted(set(steps)), dtype=np.int64)
    segment = np.zeros(n, dtype=np.int64)
    for s in steps_arr:
        segment[s:] += 1
    valid = valid & away_from_steps(n, steps_arr, settings.step_guard_samples)
    levels = segment_levels(f_hat, valid, segment, len(steps_arr) + 1)
    usable = valid & (np.abs(v) > settings.v_move_m_s)
    br = np.array([brackets.get(int(s), (-1, -1)) for s in steps_arr], dtype=np.int64).reshape(-1, 2)
    est = LoadEstimate(segment=segment, steps=steps_arr, levels=levels, load=levels[segment], brackets=br, valid=valid, usable=usable)
    if accel is None or dt is None:
        return est
    k = max(2, int(round(settings.load_knot_s / dt)))
    motion = (v, accel)
    n_seg = len(steps_arr) + 1
    grid = _grid_fit(f_hat, valid, segment, n_seg, k, motion)
    ramps = follows_ramps(f_hat, valid, segment, n_seg, k, settings, motion, grid, noise_n2)
    knots, load = ramp_load(f_hat, valid, usable, segment, n_seg, k, settings, levels, motion, grid)
    if not (ramps or corners_pay(f_hat, usable, segment, n_seg, knots, settings, motion)):
        return est
    load_knots, load = with_missed_knots(f_hat, usable, segment, knots, load, levels, k, settings, motion)
    return replace(est, knot_samples=k, corners=tuple(knots), load_knots=tuple(load_knots), load=load)

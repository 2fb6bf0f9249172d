"""Naming the missing effect: sparse regression of the equation residuals on the library's
regressors, selected by blocked cross-validation.

The data are the stacked, weighted residuals y (the negative residuals of the base model, so
that y ≈ Σ θ_j φ_j) and one regressor column φ_j per candidate (the derivative of the residuals
with respect to the candidate's parameter at its neutral value; every effect enters the
chamber or motion equation linearly or nearly so). Samples are grouped into blocks (1 s of one
record); the blocks are the units of cross-validation, because residuals are correlated within
a block (the integration intervals share the smooth part of any model error) but hardly across
blocks.

Forward selection (a greedy sparse regression, one candidate = one coefficient):

1. For the current set S (at first empty) and every candidate j outside it, the leave-one-block-
   out prediction loss of S ∪ {j} is computed for every block b from per-block sufficient
   statistics (ΦᵀΦ, Φᵀy, yᵀy): θ̂₋b = (G − G_b)⁻¹ (c − c_b),
   loss_b = y_bᵀy_b − 2 θ̂₋bᵀ c_b + θ̂₋bᵀ G_b θ̂₋b.
2. The gain of j is d_b = loss_b(S) − loss_b(S ∪ {j}). j is *significant* if
   (a) Σ d_b ≥ ``min_relative_gain`` · Σ loss_b(S) — it explains a real share of what is left,
   (b) the t statistic of the blocks' relative gains d_b / loss_b(S) ≥ ``min_t_stat`` — it
       helps consistently across blocks, not by one window's accident (relative gains, because
       the absolute ones are heavy-tailed: a supply-line effect lives where the flow is large);
       over the blocks where the candidate has leverage (:data:`LEVERAGE_FRACTION`),
   (c) its coefficient is ≥ ``min_z`` jackknife standard errors (over blocks) from 0, and
   (d) it has the physical sign where the parameter has one (leakage, air, line resistance ≥ 0).
3. The significant candidate with the largest mean relative gain over blocks, mean_b d_b /
   loss_b(S), joins S (its rank is the step number; the mean of relative gains weighs every
   block alike, as the t statistic of (b) does, where Σ d_b would let a few blocks with large
   residuals decide -- between a small transmitter gain and the same transmitter's offset they
   chose the offset in seeds where the blocks favoured the gain); stop
   when none is significant or ``max_effects`` are named. No candidate at step 1 means ``none``.
   The runner-up of each step is kept with the t statistic of the winner's blockwise advantage
   over it: a small t means the two are hard to tell apart on these data (e.g. a small
   transmitter gain and the same transmitter's offset over a narrow pressure range).

The thresholds are set for no false naming on the model's own noise (tests/discrepancy, the
null case over several seeds, and the sweep in ``bench/discrepancy_limits.py``).

Intervals: the jackknife over blocks, θ̂ ± t_{B−1, (1+level)/2} · SE_jack, with
SE²_jack = (B − 1)/B Σ_b (θ̂₋b − θ̄)².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["BlockStats", "CandidateScore", "SelectionResult", "block_stats", "cv_losses", "forward_select", "score_candidates"]


@dataclass(frozen=True)
class BlockStats:
    """Per-block sufficient statistics of a weighted least-squares problem y ≈ Φ θ.

    Attributes
    ----------
    G : ndarray (B, p, p)
        Φ_bᵀ Φ_b.
    c : ndarray (B, p)
        Φ_bᵀ y_b.
    s : ndarray (B,)
        y_bᵀ y_b.
    n : ndarray (B,)
        Rows per block.
    scale : ndarray (p,)
        The columns were divided by these (their RMS) before the sums; coefficients are
        reported in the columns' own units.
    """

    G: np.ndarray
    c: np.ndarray
    s: np.ndarray
    n: np.ndarray
    scale: np.ndarray

    @property
    def n_blocks(self) -> int:
        return int(self.s.shape[0])


def block_stats(y: np.ndarray, Phi: np.ndarray, block: np.ndarray, noise: tuple | None = None) -> BlockStats:
    """Sufficient statistics per block of the rows (y, Φ) (rows with a non-finite value are
    dropped; columns are scaled to unit RMS).

    ``noise`` = (j, e2, m0): column j is a regressor recorded with noise that enters the rows too,
    as the mass's column of the motion rows (y ∋ m0 u, Φ_j ∋ −u with E u² = e2 per row,
    ``transforms.discrepancy.rows.mass_term_noise``): each block's sums are corrected by the
    noise's expectation (Φ_jᵀΦ_j − Σ e2, Φ_jᵀy + m0 Σ e2, yᵀy − m0² Σ e2), so that the
    coefficients and the losses are those of the noise-free regressor (a corrected score)."""
    y = np.asarray(y, float)
    Phi = np.asarray(Phi, float).reshape(y.shape[0], -1)
    ok = np.isfinite(y) & np.all(np.isfinite(Phi), axis=1)
    e2 = np.asarray(noise[1], float)[ok] if noise is not None else None
    y, Phi, block = y[ok], Phi[ok], np.asarray(block)[ok]
    scale = np.sqrt(np.mean(Phi * Phi, axis=0)) if y.size else np.ones(Phi.shape[1])
    scale = np.where(scale > 0, scale, 1.0)
    Z = Phi / scale
    uniq, inv = np.unique(block, return_inverse=True)
    B, p = uniq.size, Z.shape[1]
    G = np.zeros((B, p, p))
    c = np.zeros((B, p))
    s = np.zeros(B)
    n = np.bincount(inv, minlength=B)
    order = np.argsort(inv, kind="stable")
    bounds = np.r_[0, np.cumsum(n)]
    Zs, ys = Z[order], y[order]
    for b in range(B):
        zb, yb = Zs[bounds[b]:bounds[b + 1]], ys[bounds[b]:bounds[b + 1]]
        G[b] = zb.T @ zb
        c[b] = zb.T @ yb
        s[b] = yb @ yb
    if e2 is not None:
        j, m0 = noise[0], noise[2]
        eb = np.bincount(inv, weights=e2, minlength=B)
        G[:, j, j] -= eb / scale[j] ** 2
        c[:, j] += m0 * eb / scale[j]
        s -= m0**2 * eb
    return BlockStats(G=G, c=c, s=s, n=n, scale=scale)


def _solve(G: np.ndarray, c: np.ndarray) -> np.ndarray:
    ridge = 1e-12 * max(float(np.trace(G)), 1e-300)
    return np.linalg.solve(G + ridge * np.eye(G.shape[0]), c)


def cv_losses(st: BlockStats, cols: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leave-one-block-out losses of the model with the columns ``cols``.

    Returns
    -------
    (loss, theta, theta_loo) : per-block losses (B,), the full-data coefficients (k,) and the
    leave-one-out coefficients (B, k), all in scaled units."""
    B = st.n_blocks
    if not cols:
        return st.s.copy(), np.zeros(0), np.zeros((B, 0))
    idx = np.ix_(cols, cols)
    Gt = st.G.sum(axis=0)[idx]
    ct = st.c.sum(axis=0)[cols]
    theta = _solve(Gt, ct)
    loo = np.empty((B, len(cols)))
    loss = np.empty(B)
    for b in range(B):
        Gb, cb = st.G[b][idx], st.c[b][cols]
        th = _solve(Gt - Gb, ct - cb)
        loo[b] = th
        loss[b] = st.s[b] - 2.0 * th @ cb + th @ Gb @ th
    return loss, theta, loo


@dataclass(frozen=True)
class CandidateScore:
    """One candidate's score against a base set of already named columns.

    Attributes
    ----------
    column : int
        Its column.
    theta, se : float
        Its coefficient (in the column's own units) and jackknife standard error.
    gain : float
        Σ_b d_b, the cross-validated loss reduction.
    relative_gain : float
        gain / Σ_b loss_b(base).
    t_stat : float
        mean/se over blocks of the relative gains d_b / loss_b(base).
    z : float
        |theta| / se.
    significant : bool
    block_gain : float
        Mean over blocks of the relative gains d_b / loss_b(base): what the choice among the
        significant candidates maximises.
    """

    column: int
    theta: float
    se: float
    gain: float
    relative_gain: float
    t_stat: float
    z: float
    significant: bool
    block_gain: float = 0.0

    def interval(self, n_blocks: int, level: float) -> tuple[float, float]:
        """θ ± t_{B−1} SE at ``level``."""
        q = float(stats.t.ppf(0.5 + level / 2.0, max(n_blocks - 1, 1)))
        return self.theta - q * self.se, self.theta + q * self.se


LEVERAGE_FRACTION = 0.05
"""The t statistic of (b) is taken over the blocks where the candidate's regressor has at least
this fraction of its largest per-block energy Φ_bᵀΦ_b. A block where the candidate has no leverage
says nothing about it; counted with a zero gain, k such blocks of B cap t at √(k B / (B − k)) for an
effect visible in k blocks however large it is (a 600 kg mass change on slow minimum-jerk moves is
visible in 6–11 of 20 blocks: t 2.7–3.9 over all blocks, 4.4–6.4 over those)."""
MIN_LEVERAGE_BLOCKS = 5
"""... if there are at least this many such blocks (else over all blocks)."""


def _jackknife_se(loo: np.ndarray) -> np.ndarray:
    B = loo.shape[0]
    if B < 2:
        return np.full(loo.shape[1], np.inf)
    return np.sqrt((B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0))


def score_candidates(st: BlockStats, base: list[int], candidates: list[int], *, min_t_stat: float, min_relative_gain: float, min_z: float, positive: frozenset[int] = frozenset()) -> list[CandidateScore]:
    """Score every candidate column outside ``base`` for joining it (module docstring).
    Columns in ``positive`` are significant only with a positive coefficient (a physical sign
    constraint: a leakage conductance, an air fraction, a line resistance)."""
    base_loss, _, _ = cv_losses(st, base)
    total = float(base_loss.sum())
    out = []
    for j in candidates:
        if j in base:
            continue
        cols = base + [j]
        loss, theta, loo = cv_losses(st, cols)
        d = base_loss - loss
        gain = float(d.sum())
        rd = d / np.where(base_loss > 0, base_loss, 1.0)  # each block's relative gain
        lev = st.G[:, j, j]
        held = lev >= LEVERAGE_FRACTION * lev.max()  # the blocks that say something about j
        rt = rd[held] if held.sum() >= MIN_LEVERAGE_BLOCKS else rd
        sd = float(rt.std(ddof=1)) if rt.size > 1 else np.inf
        t = float(rt.mean() / (sd / np.sqrt(rt.size))) if sd > 0 else (np.inf if gain > 0 else 0.0)
        se = _jackknife_se(loo)[-1] / st.scale[j]
        th = float(theta[-1] / st.scale[j])
        z = abs(th) / se if se > 0 else np.inf
        rel = gain / total if total > 0 else 0.0
        sig = bool(rel >= min_relative_gain and t >= min_t_stat and z >= min_z and (j not in positive or th > 0))
        out.append(CandidateScore(j, th, float(se), gain, rel, t, float(z), sig, float(rd.mean())))
    return out


@dataclass(frozen=True)
class SelectionResult:
    """Forward selection's outcome.

    Attributes
    ----------
    named : list of CandidateScore
        The named columns in the order they were named (rank 1 first); their theta/se are from
        the step at which they joined.
    first_step : list of CandidateScore
        Every candidate's score against the empty model (the ranking table).
    final_theta, final_se : ndarray
        Coefficients and jackknife SEs of the named columns fitted together (column units).
    n_blocks : int
    null_loss : float
        Σ_b yᵀy of the base model (no effect).
    """

    named: list[CandidateScore]
    first_step: list[CandidateScore]
    final_theta: np.ndarray
    final_se: np.ndarray
    n_blocks: int
    null_loss: float
    rivals: list[tuple[int | None, float]] = None  # type: ignore[assignment]
    """Per named column: (the runner-up's column, t statistic of the named one's advantage over
    it, blockwise relative CV losses); (None, inf) without a runner-up."""


def forward_select(st: BlockStats, candidates: list[int], *, max_effects: int, min_t_stat: float, min_relative_gain: float, min_z: float, positive: frozenset[int] = frozenset()) -> SelectionResult:
    """Greedy forward selection by blocked cross-validation (module docstring); ``positive`` as
    in :func:`score_candidates`."""
    kw = dict(min_t_stat=min_t_stat, min_relative_gain=min_relative_gain, min_z=min_z, positive=frozenset(positive))
    base: list[int] = []
    named: list[CandidateScore] = []
    rivals: list[tuple[int | None, float]] = []
    first = score_candidates(st, [], candidates, **kw)
    scores = first
    while len(base) < max_effects:
        sig = [s for s in scores if s.significant]
        if not sig:
            break
        best = max(sig, key=lambda s: s.block_gain)
        others = [s for s in scores if s.column != best.column]
        if others:
            rival = max(others, key=lambda s: s.block_gain)
            base_loss, _, _ = cv_losses(st, base)
            lb, _, _ = cv_losses(st, base + [best.column])
            lr, _, _ = cv_losses(st, base + [rival.column])
            rd = (lr - lb) / np.where(base_loss > 0, base_loss, 1.0)
            sd = float(rd.std(ddof=1)) if rd.size > 1 else np.inf
            t = float(rd.mean() / (sd / np.sqrt(rd.size))) if sd > 0 else np.inf
            rivals.append((rival.column, t))
        else:
            rivals.append((None, float("inf")))
        named.append(best)
        base.append(best.column)
        scores = score_candidates(st, base, [c for c in candidates if c not in base], **kw)
    if base:
        _, theta, loo = cv_losses(st, base)
        th = theta / st.scale[base]
        se = _jackknife_se(loo) / st.scale[base]
    else:
        th, se = np.zeros(0), np.zeros(0)
    return SelectionResult(named=named, first_step=first, final_theta=th, final_se=se, n_blocks=st.n_blocks, null_loss=float(st.s.sum()), rivals=rivals)

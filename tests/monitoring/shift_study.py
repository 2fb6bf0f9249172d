"""A valve shifted and scaled by known amounts: x̂ and α̂ against the truth on any valve family.

The new valve (Table 1's nominal condition with the manufacturing scatter of ``seed``) is
commissioned from ``commissioning`` 10 s snapshots; then each window has every edge's underlap
grown by a shift and its α scaled by a factor (one window per pair). The monitor's design data
stay Table 1's (the configured family is Eq. 3's), as in the accuracy study.
"""

from __future__ import annotations

import itertools

import numpy as np
import polars as pl

from model import TABLE1, ValveCondition
from model.condition import manufactured
from model.params import EDGES
from transforms.monitor import commissioning_baseline, monitor

from .sim_lake import START, simulated_lake
from .test_accuracy import LAWS, NOMINAL, PARAMS, STUDY_TRAJECTORY

WINDOW_SEED_OFFSET = 1000
"""The windows' moves, loads and supply are drawn from seed + this (not the commissioning's)."""


def shifted(base: ValveCondition, shift_m: float, alpha_factor: float) -> ValveCondition:
    """``base`` with every edge's underlap grown by ``shift_m`` [m] and its α times ``alpha_factor``."""
    return ValveCondition(tuple(x + shift_m for x in base.underlap_m), tuple(a * alpha_factor for a in base.alpha),
                          base.x_l_fraction)


def commissioned(geometry, seed: int, commissioning: int = 6, sensors=None, params=None):
    """(base condition, :func:`commissioning_baseline` of its ``commissioning`` 10 s snapshots)."""
    base = manufactured(TABLE1.nominal_condition, seed)
    lake = simulated_lake([base] * commissioning, seed, trajectory=STUDY_TRAJECTORY, sensors=sensors, geometry=geometry)
    return base, commissioning_baseline(lake, params or PARAMS, NOMINAL, laws=LAWS)


def shift_study(geometry, seed: int, shifts_m, alphas, *, duration_s: float = 10.0, commissioning: int = 6,
                sensors=None, params=None, baseline=None) -> pl.DataFrame:
    """:func:`fits_against_truth` of the windows of every (shift, α) pair in ``itertools.product``
    order on model/'s plant of ``geometry``, commissioned by :func:`commissioned`."""
    params = params or PARAMS
    base, fitted = baseline or commissioned(geometry, seed, commissioning, sensors, params)
    pairs = list(itertools.product(shifts_m, alphas))
    lake = simulated_lake([shifted(base, s, a) for s, a in pairs], seed + WINDOW_SEED_OFFSET, duration_s=duration_s,
                          trajectory=STUDY_TRAJECTORY, sensors=sensors, geometry=geometry)
    return fits_against_truth(lake, fitted, pairs, params)


def refplant_study(law: str, seed: int, pairs, *, commissioning: int = 6, noiseless: bool = False,
                   window_seeds=None, params=None) -> pl.DataFrame:
    """:func:`fits_against_truth` on the second reference plant (``tests/refplant``): its
    manufactured valve ``seed`` with every edge on ``law``, commissioned from ``commissioning`` 10 s
    snapshots, then one 10 s window per (shift [m], α factor) of ``pairs``, every edge worn so, drawn
    from ``window_seeds`` (default seed·1000 + 500 + i). ``noiseless``: its acquisition without
    noise or quantisation."""
    from tests import refplant as rp

    params = params or PARAMS
    base = rp.family(rp.manufactured(rp.NAMEPLATE, seed=seed), law)
    if noiseless:
        base = rp.without_noise(base)
    comm = rp.to_lake_frame(rp.simulate_windows(base, commissioning, seed), "V1", START)
    fitted = commissioning_baseline(comm, params, NOMINAL, laws=LAWS)
    seeds = window_seeds or [seed * 1000 + 500 + i for i in range(len(pairs))]
    recs = [rp.simulate(rp.worn(base, alpha_scale=(a,) * 4, underlap_shift_m=(s,) * 4), 10.0, int(k))
            for (s, a), k in zip(pairs, seeds, strict=True)]
    return fits_against_truth(rp.to_lake_frame(recs, "V1", START), fitted, pairs, params)


def fits_against_truth(lake: pl.DataFrame, fitted, pairs, params=None) -> pl.DataFrame:
    """Fit rows of every window of ``lake`` (``window_id`` 1…; window i shifted and scaled by
    ``pairs[i]`` = (shift [m], α factor) against the commissioning state) and edge, against the
    baselines ``fitted`` (:func:`commissioning_baseline`), with ``x_true_m``, ``alpha_true``,
    ``x_err_m``, ``alpha_err``; window 0 carries the commissioning values (``leak_scale_baseline``,
    ``edge_law``, the points' ``u_min_m``, ``u_max_m``; no fit)."""
    res = monitor(
        lake, params or PARAMS, {"V1": {e: b.characteristic for e, b in fitted.items()}},
        leakage={"V1": {e: b.leakage for e, b in fitted.items()}},
        leak_scale={"V1": {e: b.leak_scale for e, b in fitted.items()}},
        leak_reference={"V1": {e: b.leak_reference for e, b in fitted.items()}},
    )  # fmt: skip
    w = res.fits["window_id"].to_numpy().astype(int)
    fits = res.fits.with_columns(
        pl.Series("window_id", w + 1, dtype=pl.UInt32),
        pl.Series("x_true_m", np.array([pairs[i][0] for i in w])),
        pl.Series("alpha_true", np.array([pairs[i][1] for i in w])),
    ).with_columns(
        (pl.col("alpha_hat") / pl.col("alpha_true") - 1).alias("alpha_err"),
        (pl.col("x_hat_m") - pl.col("x_true_m")).alias("x_err_m"),
    )
    comm = pl.DataFrame({"window_id": pl.Series([0] * 4, dtype=pl.UInt32), "edge": list(EDGES),
                         "leak_scale_baseline": [fitted[e].leak_scale for e in EDGES],
                         "leak_scale_baseline_se": [fitted[e].leak_scale_se for e in EDGES],
                         "edge_law": [fitted[e].edge_law for e in EDGES],
                         "u_min_m": [fitted[e].u_range_m[0] for e in EDGES],
                         "u_max_m": [fitted[e].u_range_m[1] for e in EDGES]})  # fmt: skip
    return pl.concat([comm, fits], how="diagonal_relaxed")

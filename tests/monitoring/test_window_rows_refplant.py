"""Every k-th row keeps the verdicts of every row (``[monitor] window_rows``, issue 45), on the second
reference plant written apart from ``model/``: operated as a positioning cylinder on a mill (moves
between positions, dwells of 2–10 s), its positions recorded at the noisy end of plant sensors,
and busy. The same continuous recording is fitted at every row and at a stride of 10 (20 s windows
at 2,000 rows: the default's 60 s at 6,000, each evaluated row the mean of the 10 it stands for),
and gives the same ``ok`` windows, its estimates well within the every-row intervals. ``bench/refplant_window_rows.py --operation sparse`` measures an
hour of 60 s windows.
"""

from __future__ import annotations

import dataclasses

import polars as pl
import pytest

from tests import refplant as rp
from transforms.monitor import THIN_MARGIN, commissioning_baseline

from .shift_study import fits_against_truth
from .sim_lake import START
from .test_accuracy import LAWS, NOMINAL, PARAMS

pytestmark = pytest.mark.xdist_group("window_rows_refplant")  # one worker builds the shared `plant` once

WINDOW_S, WINDOW_ROWS, STRIDE = 20.0, 2000, 10
WEAR = (0.05e-3, 0.95)
"""Every edge's shift [m] and α factor in the recording, against the commissioning."""


@pytest.fixture(scope="module")
def plant():
    """A manufactured Eq. 3 valve with plant-grade position noise, commissioned from three busy 10 s
    snapshots."""
    base = rp.noisy_end(rp.manufactured(rp.NAMEPLATE, seed=1))
    comm = rp.to_lake_frame(rp.simulate_windows(base, 3, 1), "V1", START)
    return base, commissioning_baseline(comm, PARAMS, NOMINAL, laws=LAWS)


def _both(plant, operation: str, duration_s: float) -> tuple[pl.DataFrame, pl.DataFrame]:
    base, fitted = plant
    p = rp.sparse(base) if operation == "sparse" else base
    rec = rp.simulate(rp.worn(p, alpha_scale=(WEAR[1],) * 4, underlap_shift_m=(WEAR[0],) * 4), duration_s, 4242)
    lake = rp.to_lake_frame(rec, "V1", START)
    out = []
    for rows in (None, WINDOW_ROWS):
        params = dataclasses.replace(PARAMS, window_s=WINDOW_S, window_rows=rows)
        out.append(fits_against_truth(lake, fitted, [WEAR] * 100, params).filter(pl.col("window_id") > 0))
    return out[0], out[1]


def _same_verdicts(every: pl.DataFrame, thinned: pl.DataFrame) -> pl.DataFrame:
    key = ["window_id", "edge"]
    assert every.select(key).equals(thinned.select(key))
    assert (every["status"] == "ok").to_list() == (thinned["status"] == "ok").to_list(), pl.concat(
        [every.select(*key, "status", "n_points"), thinned.select(pl.col("status").alias("thinned"), pl.col("n_points").alias("n_thin"))],
        how="horizontal",
    )
    both = every.join(thinned, on=key, suffix="_k").filter(pl.col("status") == "ok")
    assert both.height > 0
    outside = both.filter(~pl.col("alpha_hat_k").is_between("alpha_ci_low", "alpha_ci_high")
                          | ~pl.col("x_hat_m_k").is_between("x_hat_ci_low_m", "x_hat_ci_high_m"))  # fmt: skip
    assert outside.height == 0, outside.select(*key, "alpha_hat", "alpha_hat_k", "alpha_ci_low", "alpha_ci_high", "x_hat_m", "x_hat_m_k")
    # a thinned point is the mean of the k rows it stands for, so it keeps their information: the
    # thinned estimates sit well inside the every-row intervals (every k-th row alone, without
    # the mean, strays up to 0.88 of the half-width here on busy operation)
    shift = both.filter(pl.col("row_stride_k") > 1).select(
        ((pl.col("alpha_hat_k") - pl.col("alpha_hat")).abs() / (pl.col("alpha_ci_high") - pl.col("alpha_ci_low")) * 2).max(),
        ((pl.col("x_hat_m_k") - pl.col("x_hat_m")).abs() / (pl.col("x_hat_ci_high_m") - pl.col("x_hat_ci_low_m")) * 2).max(),
    )
    assert (shift.row(0)[0] or 0.0) < 0.25 and (shift.row(0)[1] or 0.0) < 0.25, shift
    return both


def test_sparse_operation_keeps_every_ok_window(plant):
    """Sparse motion: a window whose thinned populations would fall short of a threshold is
    evaluated at every row; the others stay thinned. Among the ok windows at every row there is one
    with fewer than STRIDE × min_points points (the old rule, min_points thinned points, dropped
    it as too_few_points)."""
    every, thinned = _both(plant, "sparse", 2 * WINDOW_S)
    both = _same_verdicts(every, thinned)
    assert (every["row_stride"] == 1).all()
    assert set(thinned["row_stride"]) == {1, STRIDE}, thinned.select("window_id", "edge", "n_points", "row_stride")
    assert (both["n_points"] < STRIDE * PARAMS.min_points).any()
    # a thinned window has every population clear of THIN_MARGIN × min_points samples or none at all
    strided = thinned.filter(pl.col("row_stride") == STRIDE)
    n_eff = strided["n_points"] * STRIDE
    assert ((n_eff >= THIN_MARGIN * PARAMS.min_points) | (n_eff == 0)).all()
    # its points are a tenth of every row's
    ratio = strided.join(every, on=["window_id", "edge"], suffix="_all").select(pl.col("n_points_all") / pl.col("n_points"))
    assert ratio.to_series().is_between(STRIDE - 0.2, STRIDE + 0.2).all()


def test_busy_operation_stays_thinned(plant):
    """Busy motion: every window keeps its stride, with the same ok windows and estimates."""
    every, thinned = _both(plant, "busy", WINDOW_S)
    _same_verdicts(every, thinned)
    assert (thinned["row_stride"] == STRIDE).all()

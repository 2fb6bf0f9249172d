"""Opening-area points: Eq. 7 and its three siblings (model.md), as polars expressions.

With V1 = V01 + A1 X and V2 = V02 − A2 X, and the nominally closed edge of the same port taken
as carrying no flow:

    α_s1 A_s1(x) = sqrt(ρ/2) (dp1/dt V1 + β A1 v_X) / (β sign(p_s − p1) sqrt|p_s − p1|)   x ≥  max(x_1r, x_s2)
    α_2r A_2r(x) = sqrt(ρ/2) (β A2 v_X − dp2/dt V2) / (β sign(p2 − p_r) sqrt|p2 − p_r|)   x ≥  max(x_1r, x_s2)
    α_1r A_1r(x) = sqrt(ρ/2) (dp1/dt V1 + β A1 v_X) / (β sign(p_r − p1) sqrt|p_r − p1|)   x ≤ −max(x_s1, x_2r)
    α_s2 A_s2(x) = sqrt(ρ/2) (β A2 v_X − dp2/dt V2) / (β sign(p2 − p_s) sqrt|p2 − p_s|)   x ≤ −max(x_s1, x_2r)

Each point is reported at the edge's opening coordinate u = +x (s1, 2r) or u = −x (1r, s2).
Which samples become points is step 3 (:mod:`transforms.selection`); here only the formulas.

Optionally (model.md's alternative to a wide spool margin) the flow through the nominally closed
edge o of the same port is subtracted, using a given characteristic α_o·A_o (e.g. the nominal
one) at that edge's own opening coordinate u_o = −u:

    α_e A_e(x) = [ sqrt(ρ/2) N / β − α_o A_o(−u) sign(Δp_o) sqrt|Δp_o| ] / (sign(Δp_e) sqrt|Δp_e|)

with N the numerator above. On simulated states this removes the few per cent of leakage bias
left at 1 mm from closing (worst on s2). A baseline and the windows fitted against it must be
computed the same way (both with or both without the correction).

The formulas exist as polars expressions (:func:`area_expr`, :func:`opening_area_points`: the
reference, usable on any frame) and as one compiled pass over numpy arrays
(:func:`points_arrays`: what the monitor runs). The tests hold the two equal.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from math import sqrt

import numba
import numpy as np
import polars as pl

from transforms.characteristic import Characteristic
from transforms.arrays import float_array
from transforms.params import EDGES, MonitorParams

__all__ = [
    "EDGE_PORT",
    "EDGE_SIGN",
    "OPPOSITE_EDGE",
    "POINT_COLUMNS",
    "Signals",
    "area_expr",
    "characteristic_expr",
    "edge_dp_expr",
    "leak_ratio_expr",
    "opening_area_points",
    "opening_coordinate_expr",
    "points_arrays",
    "port_numerator_expr",
]

EDGE_PORT: dict[str, int] = {"s1": 1, "1r": 1, "s2": 2, "2r": 2}
EDGE_SIGN: dict[str, int] = {"s1": +1, "1r": -1, "s2": -1, "2r": +1}
"""u = EDGE_SIGN[edge] · x."""
OPPOSITE_EDGE: dict[str, str] = {"s1": "1r", "1r": "s1", "s2": "2r", "2r": "s2"}
"""The other edge of the same port (closed when ``edge`` is open)."""

POINT_COLUMNS = ("valve_id", "window_id", "window_start", "timestamp_utc", "edge", "u_m", "area_m2")


@dataclass(frozen=True)
class Signals:
    """Which columns carry each quantity of Eq. 7 (defaults: lake + :mod:`transforms.derivatives`).

    The chamber pressures default to the Savitzky–Golay smoothed values (noise factor 0.33, and
    the same time support as the derivatives); X enters only the volumes, where its noise is
    irrelevant, so the raw column is used.
    """

    ps: str = "ps_pa"
    pr: str = "pr_pa"
    p1: str = "p1_smooth_pa"
    p2: str = "p2_smooth_pa"
    x_spool: str = "x_spool_m"
    x_cyl: str = "x_cyl_m"
    dp1_dt: str = "dp1_dt_pa_s"
    dp2_dt: str = "dp2_dt_pa_s"
    v_cyl: str = "v_cyl_m_s"


DEFAULT_SIGNALS = Signals()


def _check_edge(edge: str) -> None:
    if edge not in EDGES:
        raise ValueError(f"unknown edge {edge!r}; edges are {EDGES}")


def port_numerator_expr(port: int, params: MonitorParams, signals: Signals = DEFAULT_SIGNALS) -> pl.Expr:
    """Numerator of Eq. 7 without sqrt(ρ/2): port 1 ``dp1/dt V1 + β A1 v_X``,
    port 2 ``β A2 v_X − dp2/dt V2`` (β times the flow into chamber 1 / out of chamber 2)."""
    beta = params.bulk_modulus_pa
    x_cyl, v = pl.col(signals.x_cyl), pl.col(signals.v_cyl)
    if port == 1:
        v1 = params.v01_m3 + params.piston_area_m2 * x_cyl
        return pl.col(signals.dp1_dt) * v1 + (beta * params.piston_area_m2) * v
    if port == 2:
        v2 = params.v02_m3 - params.annulus_area_m2 * x_cyl
        return (beta * params.annulus_area_m2) * v - pl.col(signals.dp2_dt) * v2
    raise ValueError(f"port must be 1 or 2, got {port}")


def edge_dp_expr(edge: str, signals: Signals = DEFAULT_SIGNALS) -> pl.Expr:
    """Pressure difference whose sign is the flow direction in Eq. 4:
    s1: p_s − p1, 1r: p_r − p1, s2: p2 − p_s, 2r: p2 − p_r."""
    _check_edge(edge)
    ps, pr, p1, p2 = (pl.col(c) for c in (signals.ps, signals.pr, signals.p1, signals.p2))
    return {"s1": ps - p1, "1r": pr - p1, "s2": p2 - ps, "2r": p2 - pr}[edge]


def opening_coordinate_expr(edge: str, signals: Signals = DEFAULT_SIGNALS) -> pl.Expr:
    """u = +x for s1 and 2r, u = −x for 1r and s2."""
    _check_edge(edge)
    x = pl.col(signals.x_spool)
    return x if EDGE_SIGN[edge] > 0 else -x


def leak_ratio_expr(edge: str, signals: Signals = DEFAULT_SIGNALS) -> pl.Expr:
    """sign(Δp_o) sqrt|Δp_o| / (sign(Δp_e) sqrt|Δp_e|), o the closed edge of the same port:
    the closed-edge term of :func:`area_expr` is ``L(−u) ·`` this, for any characteristic L."""
    _check_edge(edge)
    dp = edge_dp_expr(edge, signals)
    dpo = edge_dp_expr(OPPOSITE_EDGE[edge], signals)
    return (dpo.sign() * dpo.abs().sqrt()) / (dp.sign() * dp.abs().sqrt())


def characteristic_expr(characteristic: Characteristic, u: pl.Expr) -> pl.Expr:
    """A piecewise-linear characteristic evaluated on an expression (numpy inside a batch)."""
    return u.map_batches(
        lambda s: pl.Series(characteristic.evaluate(s.to_numpy()), dtype=pl.Float64),
        return_dtype=pl.Float64,
    )


def area_expr(
    edge: str,
    params: MonitorParams,
    signals: Signals = DEFAULT_SIGNALS,
    *,
    leakage: Characteristic | None = None,
) -> pl.Expr:
    """α·A of ``edge`` by Eq. 7 (or its sibling), exactly as model.md writes it.

    ``leakage``: α·A of the *other* edge of the same port (:data:`OPPOSITE_EDGE`) in its own
    opening coordinate; when given, that edge's flow is subtracted (module docstring).
    Infinite/NaN where Δp = 0; step 3 removes such samples (minimum |Δp|).
    """
    _check_edge(edge)
    dp = edge_dp_expr(edge, signals)
    num = port_numerator_expr(EDGE_PORT[edge], params, signals)
    denom = params.bulk_modulus_pa * dp.sign() * dp.abs().sqrt()
    if leakage is None:
        return (sqrt(params.density_kg_m3 / 2.0) * num) / denom
    other = OPPOSITE_EDGE[edge]
    dpo = edge_dp_expr(other, signals)
    leak = characteristic_expr(leakage, opening_coordinate_expr(other, signals)) * dpo.sign() * dpo.abs().sqrt()
    return (sqrt(params.density_kg_m3 / 2.0) * num / params.bulk_modulus_pa - leak) / (dp.sign() * dp.abs().sqrt())


def opening_area_points(
    frame: pl.DataFrame | pl.LazyFrame,
    params: MonitorParams,
    *,
    selected: Mapping[str, pl.Expr] | None = None,
    signals: Signals = DEFAULT_SIGNALS,
    edges: tuple[str, ...] = EDGES,
    leakage: Mapping[str, Characteristic] | None = None,
    with_ratio: bool = False,
) -> pl.DataFrame | pl.LazyFrame:
    """Long frame of points ``valve_id, window_id, window_start, timestamp_utc, edge, u_m, area_m2``
    (and ``leak_ratio``, :func:`leak_ratio_expr`, when ``with_ratio``).

    ``selected[edge]`` is a boolean expression choosing the rows that become the edge's points
    (from :func:`transforms.selection.selected_expr`); without it every row with a derivative
    becomes a point of every edge. Rows are grouped by edge (in :data:`EDGES` order), in time
    order within an edge. ``leakage[edge]``: α·A of each edge for the closed-edge correction
    (:func:`area_expr`); edge e uses ``leakage[OPPOSITE_EDGE[e]]``.
    """
    parts = []
    for edge in edges:
        keep = selected[edge] if selected is not None else pl.col(signals.dp1_dt).is_not_null()
        parts.append(
            frame.filter(keep).select(
                pl.col("valve_id"),
                pl.col("window_id"),
                pl.col("window_start"),
                pl.col("timestamp_utc"),
                pl.lit(edge, dtype=pl.Utf8).alias("edge"),
                opening_coordinate_expr(edge, signals).alias("u_m"),
                area_expr(
                    edge, params, signals,
                    leakage=None if leakage is None else leakage[OPPOSITE_EDGE[edge]],
                ).alias("area_m2"),
                *([leak_ratio_expr(edge, signals).alias("leak_ratio")] if with_ratio else []),
            )
        )
    return pl.concat(parts, how="vertical")


# --------------------------------------------------------------------------------------------
# compiled path (same formulas; used by transforms.monitor for throughput)
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _pwl(kn, kv, k0, k1, t):
    """Piecewise-linear characteristic kn[k0:k1], kv[k0:k1] at t (linear beyond the ends)."""
    if t <= kn[k0 + 1]:
        j = k0
    elif t >= kn[k1 - 2]:
        j = k1 - 2
    else:
        lo = k0 + 1
        hi = k1 - 2
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if kn[mid] <= t:
                lo = mid
            else:
                hi = mid
        j = lo
    return kv[j] + (kv[j + 1] - kv[j]) / (kn[j + 1] - kn[j]) * (t - kn[j])


@numba.njit(cache=True)
def _points_kernel(codes, selected_code, n_selected, ps, pr, p1, p2, x, xc, dp1, dp2, v, c, lkn, lkv, loff, use_leak, want_ratio):
    """``n_selected``: the number of selected rows per edge (the selection counted them)."""
    sq, beta, a1, a2, v01, v02 = c[0], c[1], c[2], c[3], c[4], c[5]
    offsets = np.zeros(5, dtype=np.int64)
    for e in range(4):
        offsets[e + 1] = offsets[e] + n_selected[e]
    idx = np.empty(offsets[4], dtype=np.int64)
    area = np.empty(offsets[4], dtype=np.float64)
    u = np.empty(offsets[4], dtype=np.float64)
    ratio = np.empty(offsets[4] if want_ratio else 0, dtype=np.float64)
    cursor = offsets[:4].copy()
    for i in range(x.shape[0]):
        for e in range(4):
            if codes[i, e] != selected_code:
                continue
            if e < 2:
                num = dp1[i] * (v01 + a1 * xc[i]) + (beta * a1) * v[i]
            else:
                num = (beta * a2) * v[i] - dp2[i] * (v02 - a2 * xc[i])
            if e == 0:
                dp, dpo, other, sign_u = ps[i] - p1[i], pr[i] - p1[i], 1, 1.0
            elif e == 1:
                dp, dpo, other, sign_u = pr[i] - p1[i], ps[i] - p1[i], 0, -1.0
            elif e == 2:
                dp, dpo, other, sign_u = p2[i] - ps[i], p2[i] - pr[i], 3, -1.0
            else:
                dp, dpo, other, sign_u = p2[i] - pr[i], p2[i] - ps[i], 2, 1.0
            den = np.sign(dp) * np.sqrt(abs(dp))
            k = cursor[e]
            if want_ratio:
                ratio[k] = np.sign(dpo) * np.sqrt(abs(dpo)) / den
            if use_leak:
                leak = _pwl(lkn, lkv, loff[other], loff[other + 1], -sign_u * x[i])
                area[k] = (sq * num / beta - leak * np.sign(dpo) * np.sqrt(abs(dpo))) / den
            else:
                area[k] = (sq * num) / (beta * den)
            idx[k] = i
            u[k] = sign_u * x[i]
            cursor[e] = k + 1
    return idx, area, offsets, ratio, u


def points_arrays(
    arrays: dict[str, np.ndarray],
    codes: np.ndarray,
    selected_code: int,
    n_selected: np.ndarray,
    params: MonitorParams,
    *,
    leakage: Mapping[str, Characteristic] | None = None,
    with_ratio: bool = False,
):
    """Eq. 7 (and its siblings) for the rows whose ``codes[:, e]`` equal ``selected_code``
    (:func:`transforms.selection.selection_codes`), in one compiled pass per edge.
    ``n_selected``: how many rows each edge has selected (the per-window ``selected`` counts of
    :func:`~transforms.selection.selection_codes`, summed over the windows).

    Returns ``(idx, area, offsets, ratio, u)``: row indices, α·A and the opening coordinate u of
    edge e in ``offsets[e]:offsets[e + 1]`` (edges in :data:`EDGES` order, rows in input order).
    Same formulas as :func:`area_expr`, same optional closed-edge correction. ``ratio`` (empty
    unless ``with_ratio``): :func:`leak_ratio_expr` per point, so that any closed-edge
    characteristic L can be subtracted later as ``area − L(−u)·ratio``.
    """
    s = DEFAULT_SIGNALS
    c = np.array(
        [sqrt(params.density_kg_m3 / 2.0), params.bulk_modulus_pa, params.piston_area_m2,
         params.annulus_area_m2, params.v01_m3, params.v02_m3],
        dtype=np.float64,
    )
    if leakage is not None:
        chars = [leakage[e] for e in EDGES]
        lkn = np.concatenate([ch.knots_u_m for ch in chars])
        lkv = np.concatenate([ch.values_m2 for ch in chars])
        loff = np.concatenate([[0], np.cumsum([ch.knots_u_m.shape[0] for ch in chars])]).astype(np.int64)
    else:
        lkn = lkv = np.zeros(2)
        loff = np.zeros(5, dtype=np.int64)
    return _points_kernel(
        codes, codes.dtype.type(selected_code),
        np.ascontiguousarray(n_selected, dtype=np.int64),
        *(float_array(arrays[k]) for k in (
            s.ps, s.pr, s.p1, s.p2, s.x_spool, s.x_cyl, s.dp1_dt, s.dp2_dt, s.v_cyl)),
        c, lkn, lkv, loff, leakage is not None, bool(with_ratio),
    )

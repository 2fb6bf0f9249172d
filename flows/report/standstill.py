"""The Eq. 9 residual a valve's design gives at rest, which the report compares the lake's standstill
checks with (:mod:`transforms.standstill` computes them per window; table ``standstill_checks``)."""

from __future__ import annotations

import math


def expected_residual(valve, export) -> float:
    """Eq. 9 residual of the valve's design at rest (F_R = 0, nominal supply), from Eq. 3/4.

    The residual hardly depends on the load or on where in the static-friction band the
    cylinder stuck (Table 1: −0.164 … −0.171 over ±d_s and 190–210 bar), so the simulator's
    plant parameters for this valve serve. Falls back to Table 1's −0.17 if the rest state cannot
    be solved.
    """
    from flows.simulate.archive import plant_params_for_valve
    from model.standstill import eq9_residual, standstill

    try:
        params = plant_params_for_valve(valve, export)
        rest = standstill(params)
        value = float(eq9_residual(rest.p1_pa, rest.p2_pa, params.supply.p_s_nominal_pa, params.supply.p_r_nominal_pa))
    except Exception:  # noqa: BLE001 - a design the model cannot bring to rest: use Table 1
        return TABLE1_RESIDUAL
    return value if math.isfinite(value) else TABLE1_RESIDUAL


TABLE1_RESIDUAL = -0.17
"""Eq. 9 residual of Table 1's healthy valve at rest (model.standstill, p_s = 200 bar)."""

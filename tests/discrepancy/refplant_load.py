"""The load estimate on the second reference plant (``tests/refplant``: loads ramping to a new level
every 1–4 s) against the plant's true load, per 10 s window of the robustness study's clean valve:
the load error on the samples at speed and the mechanical replay's gap (X on the recorded pressures,
``transforms.discrepancy.gaps``) with the estimated load and with the true one. The model is
Table 1's with the reference plant's true cylinder (mass, friction), so what is left is the load
estimate's (``bench/refplant_load.py`` prints it per seed; a test holds seed 1's gentle ramps)."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime, timezone
from functools import lru_cache

import numpy as np


@lru_cache(maxsize=4)
def _simulated(seed: int, n_windows: int, load_interval_s: tuple[float, float] | None, quiet: bool = False, noisy_end: bool = False) -> list:
    """The clean windows of valve ``seed``, the study's (``n_windows`` drawn from 100 + ``seed``;
    ``load_interval_s`` the range of the load's intervals between new levels [s], None: the plant's
    1–4 s; ``quiet``: recorded without noise or quantisation; ``noisy_end``: positions as noisy as
    plants record them, :func:`tests.refplant.noisy_end`); simulated once per process for every
    model diagnosed on them."""
    from tests.refplant import NAMEPLATE, manufactured, noisy_end as noisier, simulate_windows, without_noise

    ref = manufactured(NAMEPLATE, seed=seed)
    if load_interval_s is not None:
        ref = replace(ref, operation=replace(ref.operation, load_interval_s=tuple(load_interval_s)))
    if quiet:
        ref = without_noise(ref)
    if noisy_end:
        ref = noisier(ref)
    return simulate_windows(ref, n_windows, 100 + seed)


def true_cylinder_model(seed: int, n_windows: int, load_interval_s: tuple[float, float] | None = None, d_v_factor: float = 1.0,
                        mass_factor: float = 1.0) -> tuple:
    """(plant, condition): Table 1's with valve ``seed``'s true cylinder (mass, friction), its
    viscous friction d_v times ``d_v_factor`` and its mass times ``mass_factor``."""
    from model import TABLE1

    tc = _simulated(seed, n_windows, None if load_interval_s is None else tuple(load_interval_s))[0].plant.cylinder
    plant = replace(TABLE1, cylinder=replace(TABLE1.cylinder, mass_kg=tc.mass_kg * mass_factor, d_v_n_s_m=tc.d_v_n_s_m * d_v_factor, d_c_n=tc.d_c_n,
                                              d_s_n=tc.d_s_n, v0_m_s=tc.v0_m_s))
    return plant, plant.nominal_condition


def window_figures(seed: int, n_windows: int, only: int | None = None, load_interval_s: tuple[float, float] | None = None,
                   model: tuple | None = None, quiet: bool = False, noisy_end: bool = False) -> list[dict]:
    """Per window of valve ``seed`` (``n_windows`` drawn from 100 + ``seed``, as the study's; only
    window ``only`` if given; ``load_interval_s`` the range of the load's intervals between new
    levels [s], None: the plant's 1–4 s): the load (``"ramps"`` or ``"constant"``), its RMS error at speed [N],
    the velocity and acceleration parts the estimate leaves (:func:`transforms.discrepancy.load.motion_mismatch`)
    [N·s/m], [kg]: a friction and mass mismatch of the model, or, with the true cylinder, load
    error that follows v_X or the acceleration; the RMS error at speed of the force the mechanical
    replay takes for the load, the load plus the friction and the mass it moves by those parts
    (``rows._mechanical_model``) times v_X and the acceleration [N]; and the mechanical gap with
    the estimate and with the true load (its own parts) [mm].

    ``model``: (plant, condition) to diagnose with instead of Table 1's with the plant's true
    cylinder (e.g. a commissioning calibration's; its true-load gap then carries the model's own
    force error). ``quiet``: the windows recorded without noise or quantisation; ``noisy_end``: with
    positions as noisy as plants record them."""
    from model.effects import Effects
    from tests.refplant import to_lake_frame
    from transforms.discrepancy import DiscrepancySettings, split_records
    from transforms.discrepancy.alignment import align_records
    from transforms.discrepancy.load import motion_mismatch
    from transforms.discrepancy.rows import _force_balance, _load_motion, _mechanical_model, _replay_record, prepare_records

    s = DiscrepancySettings()
    truth = _simulated(seed, n_windows, None if load_interval_s is None else tuple(load_interval_s), quiet, noisy_end)
    plant, cond = true_cylinder_model(seed, n_windows, load_interval_s) if model is None else model
    lake = to_lake_frame(truth, "V1", datetime(2025, 3, 1, tzinfo=timezone.utc))
    recs, _ = align_records(split_records(lake, s), plant, cond, s)
    windows = list(range(len(recs))) if only is None else [only]
    fx = Effects()
    key = (plant, cond, fx)
    out = []
    for i, p in zip(windows, prepare_records([recs[i] for i in windows], plant, cond, s)):
        r = truth[i]
        est = p.base_load
        true_load = r.true["F_l"][:p.rec.n].astype(float)
        at_speed = est.usable
        mc = _mechanical_model(p, plant, cond, fx, s, est.load)[0].cylinder
        v, a = _load_motion(p.rec, s)
        force = est.load + (mc.d_v_n_s_m - plant.cylinder.d_v_n_s_m) * v + (mc.mass_kg - plant.cylinder.mass_kg) * a
        # the true load ramps (0.1-0.4 s), never jumps: one segment, held at its interval means
        dv, dm = motion_mismatch(_force_balance(p.rec, plant, cond, fx, s), true_load, at_speed, (v, a))
        true_est = replace(est, load=true_load, segment=np.zeros(p.rec.n, dtype=int), hold_until=0, friction_mismatch=dv, mass_mismatch=dm)
        gaps = []
        for load in (est, true_est):
            p.loads[key] = load
            e = _replay_record(p, plant, cond, fx, s)["X_mechanical"] - p.rec.raw["X"]
            gaps.append(float(np.sqrt(np.nanmean(e ** 2))) * 1e3)
        out.append({"seed": seed, "window": i, "load": "ramps" if est.knot_samples else "constant",
                    "load_error_n": float(np.sqrt(np.mean((est.load[at_speed] - true_load[at_speed]) ** 2))),
                    "velocity_part_n_s_m": est.friction_mismatch, "mass_part_kg": est.mass_mismatch,
                    "replayed_force_error_n": float(np.sqrt(np.nanmean((force[at_speed] - true_load[at_speed]) ** 2))),
                    "mechanical_gap_mm": gaps[0], "true_load_gap_mm": gaps[1]})
    return out

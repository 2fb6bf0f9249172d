"""``valvemon discrepancy``: where the model and a valve's measurements disagree, which library
effect explains it, what adding it does to the gap and to the monitoring (issue 7).

:func:`run_discrepancy` reads the valve's lake rows in [start, end), cuts them into records
(:func:`flows.discrepancy.lake_records.lake_records`: the records are chosen from the time stamps,
read in chunks, then only their rows are read; on a continuous recording no record straddles a
monitoring window of the configuration's ``[monitor] window_s``, ``DiscrepancySettings.window_s``), builds the plant model from the plant
configuration (:func:`plant_params_for`) -- its uncertain parameters (edges, β, volumes, friction,
mass) calibrated on its commissioning window (the configuration's ``baseline_window``) when there
is one, else calibrated by the diagnosis itself within the valve's ``[valves.tolerances]``
(:func:`valve_condition`, :func:`nuisance_priors`) --, runs :func:`transforms.discrepancy.pipeline.diagnose`
and stores, in one transaction,

* ``discrepancy_findings`` -- one row per named effect (or one ``none`` row), interfaces.md;
* ``discrepancy_candidates`` -- every library candidate scored against the base model;
* ``discrepancy_gaps`` -- replay gap per model stage, signal and operating region;
* ``discrepancy_residuals`` -- equation residuals per stage and region;
* ``discrepancy_monitoring`` -- α̂, x̂, e per edge as recorded and with the effects accounted for;
* ``discrepancy_condition`` -- the valve condition (α, underlap per edge) the model used;

and writes the overlay pictures to ``WAREHOUSE/reports/discrepancy/``. Every run appends (its
rows carry ``run_id`` and ``run_at``); nothing is replaced. :func:`discrepancy_flow` is the
Prefect flow the command line runs.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import polars as pl

from flows.common.config import load_plant_config, plant_valves
from flows.common.errors import ValvemonError
from flows.common.instants import utc_instant
from flows.common.prefect_run import flow, task
from flows.common.warehouse_db import add_missing_columns, connect, ensure_tables, insert_frame, transaction
from flows.discrepancy.lake_records import lake_records
from model.effects import effect_key
from model.params import PlantParams, ValveCondition
from schemas.fields import (
    DISCREPANCY_CANDIDATE_FIELDS,
    DISCREPANCY_CONDITION_FIELDS,
    DISCREPANCY_FINDING_FIELDS,
    DISCREPANCY_GAP_FIELDS,
    DISCREPANCY_MONITORING_FIELDS,
    DISCREPANCY_RESIDUAL_FIELDS,
    polars_schema,
)
from schemas.plant_config import ValveSpec
from transforms.discrepancy.gaps import NOISE_GAP
from transforms.discrepancy.nuisance import NuisancePriors
from transforms.discrepancy.pipeline import ConditionFit, Diagnosis, diagnose
from transforms.discrepancy.records import REFERENCE_COLUMN
from transforms.discrepancy.settings import DiscrepancySettings

DISCREPANCY_TABLES = {
    "discrepancy_findings": DISCREPANCY_FINDING_FIELDS,
    "discrepancy_candidates": DISCREPANCY_CANDIDATE_FIELDS,
    "discrepancy_gaps": DISCREPANCY_GAP_FIELDS,
    "discrepancy_residuals": DISCREPANCY_RESIDUAL_FIELDS,
    "discrepancy_monitoring": DISCREPANCY_MONITORING_FIELDS,
    "discrepancy_condition": DISCREPANCY_CONDITION_FIELDS,
}
CONDITION_MODES = ("auto", "design", "commissioning")


def plant_params_for(valve: ValveSpec, export) -> PlantParams:
    """The plant model of one configured valve, built as ``valvemon simulate`` builds it
    (:func:`flows.simulate.archive.plant_params_for_valve`): design data, cylinder, volumes and fluid from
    the configuration, the sample rate from ``export``; what the configuration does not hold
    (moving mass, friction, spool dynamics) from :data:`model.params.TABLE1`."""
    from flows.simulate.archive import plant_params_for_valve

    return plant_params_for_valve(valve, export)


def ensure_discrepancy_tables(con) -> None:
    """Create the discrepancy tables if missing, and add columns a newer registry names to a
    table an older version created (`add_missing_columns`: null, or 0 / '' where the field is not nullable)."""
    ensure_tables(con, {name: (fields, None) for name, fields in DISCREPANCY_TABLES.items()})
    add_missing_columns(con, DISCREPANCY_TABLES)


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def effects_label(diagnosis: Diagnosis) -> str:
    """``name[variant] parameter=value; …`` of the named effects ('' if none)."""
    return "; ".join(f"{n.spec.key} {n.spec.parameter_name}={_fmt(n.value)} {n.spec.unit}" for n in diagnosis.named)


def _gap_rms(diagnosis: Diagnosis, stage: int, signal: str) -> float:
    for r in diagnosis.gap_rows:
        if r["stage"] == stage and r["signal"] == signal and r["region"] == "all":
            return r["rms"]
    return float("nan")


def _nn(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


@dataclass
class DiscrepancyReport:
    """What one run found, for the command line."""

    valve_id: str
    run_id: str
    n_records: int
    findings: list[dict]
    plots: list[Path]
    gap_before: float
    gap_after: float
    condition_source: str = "design"
    model_note: str = ""
    """What the commissioning calibration found about the model itself (``ConditionFit.reason``)."""
    spool_noise_m: float = float("nan")
    """The recorded spool position's noise over the records (``Diagnosis.position_noise``). [m]"""
    spool_stroke_m: float = float("nan")
    """The spool's x_max (the configured valve's). [m]"""
    cylinder_noise_m: float = float("nan")
    """The recorded cylinder position's noise over the records. [m]"""
    spool_reconstructed: int = 0
    """Records whose spool was taken as Eq. 1's response to x_ref (``Diagnosis.spool_reconstructed``)."""
    spool_reference_records: int = 0
    """Records that hold the spool reference x_ref, which ``--reconstruct-spool`` needs."""


PLANT_GRADE_SPOOL_NOISE = 0.001
"""A spool reading this noisy (a fraction of x_max: the low end of plant LVDTs, 0.1–0.3 %) with
x_ref recorded gets the hint to reconstruct it (:func:`summary_lines`): on the reference plant
the reconstruction read better at 0.2 % and worse at 0.03 % (docs/discrepancy.md)."""


def nuisance_priors(valve: ValveSpec) -> NuisancePriors:
    """The nuisance priors of a valve: its ``[valves.tolerances]`` or the documented defaults."""
    from dataclasses import asdict

    return NuisancePriors(**asdict(valve.tolerances)) if valve.tolerances is not None else NuisancePriors()


def valve_condition(valve: ValveSpec, plant: PlantParams, warehouse: Path, mode: str, settings: DiscrepancySettings) -> tuple[str, PlantParams, ValveCondition, ConditionFit | None]:
    """The base model of the diagnosis: ``design`` (the configured design data; the diagnosis then
    calibrates the uncertain parameters itself, within the valve's tolerances), or
    ``commissioning`` (the uncertain parameters -- α and underlap per edge, β, V01, V02, friction,
    mass -- calibrated on the lake rows of the configured ``baseline_window``,
    :func:`transforms.discrepancy.calibration.calibrate`, and then taken as exact); ``auto`` is
    commissioning when the valve has a baseline_window, else design. Returns (source, plant,
    condition, fit or None)."""
    from transforms.discrepancy.calibration import calibrate

    if mode not in CONDITION_MODES:
        raise ValvemonError(f"--valve-condition must be one of {', '.join(CONDITION_MODES)}, got {mode!r}")
    if mode == "design" or (mode == "auto" and valve.baseline_window is None):
        return "design", plant, plant.nominal_condition, None
    if valve.baseline_window is None:
        raise ValvemonError(f"valve {valve.id}: --valve-condition commissioning needs a baseline_window in the plant configuration")
    a, b = valve.baseline_window
    records, _ = lake_records(warehouse, valve.id, a, b, replace(settings, max_records=max(settings.max_records, 12)))
    if not records:
        raise ValvemonError(f"valve {valve.id}: its baseline_window {a.isoformat()} – {b.isoformat()} holds no record of at least {settings.min_record_s:g} s in the lake")
    cal = calibrate(records, plant, plant.nominal_condition, nuisance_priors(valve), settings)
    sig = cal.nm.sigma
    se = np.zeros(sig.size)
    se[list(cal.nm.active)] = cal.z_se * sig[list(cal.nm.active)]
    fit = ConditionFit(condition=cal.condition, alpha_se=tuple(float(x) for x in se[0:4]), underlap_se_m=tuple(float(x) for x in se[4:8]),
                       gap_design=cal.gap_nominal, gap_fitted=cal.gap_calibrated, n_records=len(records), reason=cal.reason)
    return "commissioning", cal.plant, cal.condition, fit


def _condition_rows(common: dict, source: str, cond: ValveCondition, fit: ConditionFit | None) -> list[dict]:
    from model.params import EDGES

    return [
        {**common, "edge": e, "source": source, "alpha": cond.alpha[i], "underlap_mm": cond.underlap_m[i] * 1e3,
         "alpha_se": None if fit is None else _nn(fit.alpha_se[i]),
         "underlap_se_mm": None if fit is None else _nn(fit.underlap_se_m[i] * 1e3),
         "gap_design": None if fit is None else _nn(fit.gap_design), "gap_fitted": None if fit is None else _nn(fit.gap_fitted)}
        for i, e in enumerate(EDGES)
    ]


def nuisance_text(rows: list[dict]) -> str:
    """'name=value unit (zσ); …' of calibrated nuisances (underlaps in µm)."""
    out = []
    for r in rows:
        if r["prior_sigma"] <= 0:
            continue
        if r["unit"] == "m":
            out.append(f"{r['name']}={r['value'] * 1e6:.2f} µm ({r['z']:+.1f}σ)")
        else:
            out.append(f"{r['name']}={r['value']:.4g} {r['unit']} ({r['z']:+.1f}σ)")
    return "; ".join(out)


def verdict_columns(d: Diagnosis, rank: int) -> dict:
    """The verdict columns of a findings row: the verdict, how sure, the other readings, why,
    the calibrated nuisances (exact model: the verdict of the selection alone), and the gap where
    the effect acts (docs/warehouse.md)."""
    from scipy import stats

    v = d.verdict
    n = d.named[rank - 1] if d.named and rank <= len(d.named) else None
    acting = {"gap_kind": n.gap_kind, "gap_kind_before": _nn(n.acting_before), "gap_kind_after": _nn(n.acting_after),
              "gap_kind_floor": _nn(n.floor)} if n is not None else {"gap_kind": None, "gap_kind_before": None, "gap_kind_after": None, "gap_kind_floor": None}
    if v is not None and v.verdict == "unexplained":
        acting = {"gap_kind": v.gap_kind, "gap_kind_before": _nn(v.gap_before), "gap_kind_after": _nn(v.gap_after), "gap_kind_floor": _nn(v.floor)}
    elif n is None and v is not None and v.gap_kind:  # a reading of the nuisance verdict, replayed with its joint fit
        acting = {"gap_kind": v.gap_kind, "gap_kind_before": _nn(v.acting_before), "gap_kind_after": _nn(v.acting_after), "gap_kind_floor": _nn(v.floor)}
    common = {"gap_nominal": _nn(d.gap_nominal), **acting, "disagreement": ((v.where if v is not None else "") or d.lag_finding) or None}
    if v is not None:
        if rank > 1:
            return {"verdict": "named", "confidence": None, "alternatives": None, "separate_by": None, "verdict_reason": None,
                    "nuisances": nuisance_text(v.nuisances), **common}
        return {"verdict": v.verdict, "confidence": _nn(v.confidence), "alternatives": "; ".join(v.alternatives) or None,
                "separate_by": v.separate_by or None, "verdict_reason": v.reason or None, "nuisances": nuisance_text(v.nuisances),
                **common}
    if not d.named:
        return {"verdict": "none", "confidence": None, "alternatives": None, "separate_by": None,
                "verdict_reason": "no library effect explains a significant share of the residuals of the model taken as exact",
                "nuisances": None, **common}
    conf = float(min(0.999, stats.norm.cdf(n.alternative_t))) if math.isfinite(n.alternative_t) else 0.999
    return {"verdict": "ambiguous" if n.alternative else "named", "confidence": conf,
            "alternatives": n.alternative.key if n.alternative else None, "separate_by": None,
            "verdict_reason": f"explains {n.relative_gain:.0%} of the cross-validated residuals of the model taken as exact (t = {n.t_stat:.3g})",
            "nuisances": None, **common}


def _tables(valve_id: str, run_id: str, run_at: datetime, d: Diagnosis, plots: list[Path | None], level: float, source: str = "design", cond: ValveCondition | None = None, fit: ConditionFit | None = None) -> dict[str, pl.DataFrame]:
    t0 = datetime.fromtimestamp(min(a for a, _ in d.records) / 1e6, tz=timezone.utc)
    t1 = datetime.fromtimestamp(max(b for _, b in d.records) / 1e6, tz=timezone.utc)
    common = {"run_id": run_id, "valve_id": valve_id, "run_at": run_at}
    findings = []
    unexplained = d.verdict is not None and d.verdict.verdict == "unexplained"  # no name: one row effect none
    if d.named and not unexplained:
        for n, path in zip(d.named, plots):
            k = n.rank
            findings.append({
                **common, "effect": n.spec.name, "parameter_name": n.spec.parameter_name, "parameter_value": n.value,
                "parameter_unit": n.spec.unit, "gap_before": n.gap_before, "gap_after": n.gap_after, "rank": k,
                "parameter_ci_low": n.ci_low, "parameter_ci_high": n.ci_high, "ci_level": level, "variant": n.spec.variant,
                "cv_relative_gain": n.relative_gain, "t_stat": _nn(n.t_stat), "z_score": _nn(n.z),
                "gap_p1_before_bar": _gap_rms(d, k - 1, "p1") / 1e5, "gap_p1_after_bar": _gap_rms(d, k, "p1") / 1e5,
                "gap_p2_before_bar": _gap_rms(d, k - 1, "p2") / 1e5, "gap_p2_after_bar": _gap_rms(d, k, "p2") / 1e5,
                "gap_x_before_mm": _gap_rms(d, k - 1, "X") * 1e3, "gap_x_after_mm": _gap_rms(d, k, "X") * 1e3,
                "window_start": t0, "window_end": t1, "n_records": d.n_records, "plot_path": str(path) if path else None,
                "condition_source": source, "gap_explained": _nn(1.0 - (n.gap_after / n.gap_before) ** 2) if n.gap_before > 0 else None,
                "alternative_effect": n.alternative.key if n.alternative else None, "alternative_t": _nn(n.alternative_t),
                **verdict_columns(d, k),
            })
    elif d.verdict is not None and d.verdict.effect is not None and not unexplained:
        # named or ambiguous against the nuisance tolerances (no residual left for the selection)
        v = d.verdict
        g0, g1 = v.gap_before, v.gap_after if math.isfinite(v.gap_after) else v.gap_before
        findings.append({
            **common, "effect": v.effect.name, "parameter_name": v.effect.parameter_name, "parameter_value": v.value,
            "parameter_unit": v.effect.unit, "gap_before": g0, "gap_after": g1, "rank": 1, "parameter_ci_low": None,
            "parameter_ci_high": None, "ci_level": level, "variant": v.effect.variant, "cv_relative_gain": None, "t_stat": None,
            "z_score": None, "gap_p1_before_bar": _gap_rms(d, 0, "p1") / 1e5, "gap_p1_after_bar": _gap_rms(d, 0, "p1") / 1e5,
            "gap_p2_before_bar": _gap_rms(d, 0, "p2") / 1e5, "gap_p2_after_bar": _gap_rms(d, 0, "p2") / 1e5,
            "gap_x_before_mm": _gap_rms(d, 0, "X") * 1e3, "gap_x_after_mm": _gap_rms(d, 0, "X") * 1e3,
            "window_start": t0, "window_end": t1, "n_records": d.n_records, "plot_path": str(plots[0]) if plots and plots[0] else None,
            "condition_source": source, "gap_explained": _nn(1.0 - (g1 / g0) ** 2) if g0 > 0 else None,
            "alternative_effect": None, "alternative_t": None, **verdict_columns(d, 1),
        })
    else:
        g = d.stage_gaps[0]
        findings.append({
            **common, "effect": "none", "parameter_name": None, "parameter_value": None, "parameter_unit": None,
            "gap_before": g, "gap_after": g, "rank": 1, "parameter_ci_low": None, "parameter_ci_high": None,
            "ci_level": level, "variant": "", "cv_relative_gain": None, "t_stat": None, "z_score": None,
            "gap_p1_before_bar": _gap_rms(d, 0, "p1") / 1e5, "gap_p1_after_bar": _gap_rms(d, 0, "p1") / 1e5,
            "gap_p2_before_bar": _gap_rms(d, 0, "p2") / 1e5, "gap_p2_after_bar": _gap_rms(d, 0, "p2") / 1e5,
            "gap_x_before_mm": _gap_rms(d, 0, "X") * 1e3, "gap_x_after_mm": _gap_rms(d, 0, "X") * 1e3,
            "window_start": t0, "window_end": t1, "n_records": d.n_records, "plot_path": str(plots[0]) if plots and plots[0] else None,
            "condition_source": source, "gap_explained": None, "alternative_effect": None, "alternative_t": None,
            **verdict_columns(d, 1),
        })
    candidates = [
        {**common, "effect": c["effect"], "variant": c["variant"], "parameter_name": c["parameter_name"],
         "parameter_unit": c["parameter_unit"], "parameter_value": c["linear_value"], "parameter_se": _nn(c["se"]),
         "cv_relative_gain": c["relative_gain"], "t_stat": c["t_stat"], "z_score": _nn(c["z"]),
         "significant": c["significant"], "unconfirmed": c["unconfirmed"], "score_rank": i + 1}
        for i, c in enumerate(d.candidates)
    ]
    gaps = [{**common, **{k: r[k] for k in ("stage", "signal", "region", "unit", "n_samples")}, "rms": _nn(r["rms"])} for r in d.gap_rows]
    residuals = [
        {**common, **{k: r[k] for k in ("stage", "equation", "region", "unit", "n_samples")}, "rms": _nn(r["rms"]), "mean": _nn(r["mean"])}
        for r in d.residual_rows
    ]
    label = effects_label(d)
    monitoring = [
        {**common, "edge": m["edge"], "effects": label, "n_windows": m["n_windows"],
         "alpha_hat_recorded": _nn(m["alpha_hat_recorded"]), "alpha_hat_corrected": _nn(m["alpha_hat_corrected"]),
         "x_hat_mm_recorded": _nn(m["x_hat_m_recorded"] * 1e3), "x_hat_mm_corrected": _nn(m["x_hat_m_corrected"] * 1e3),
         "e_mm2_recorded": _nn(m["e_m2_recorded"] * 1e6), "e_mm2_corrected": _nn(m["e_m2_corrected"] * 1e6)}
        for m in d.monitoring
    ]
    conditions = _condition_rows(common, source, cond, fit) if cond is not None else []
    out = {}
    for name, rows in (("discrepancy_findings", findings), ("discrepancy_candidates", candidates), ("discrepancy_gaps", gaps),
                       ("discrepancy_residuals", residuals), ("discrepancy_monitoring", monitoring), ("discrepancy_condition", conditions)):
        schema = polars_schema(DISCREPANCY_TABLES[name])
        out[name] = pl.DataFrame(rows, schema=schema) if rows else pl.DataFrame(schema=schema)
    return out


def _plots(valve_id: str, run_id: str, d: Diagnosis, warehouse: Path) -> list[Path | None]:
    from flows.discrepancy.plots import overlay_figure
    from flows.report.flow import DISCREPANCY_DIR

    folder = warehouse / DISCREPANCY_DIR
    if not d.traces:
        return [None] * max(1, len(d.named))
    trace = d.traces[0]
    short = run_id[:8]
    if not d.named:
        path = folder / f"{valve_id}_{short}_none.png"
        return [overlay_figure(trace, 0, 0, f"{valve_id}: no library effect named (gap {d.stage_gaps[0]:.3g})", path)]
    out = []
    for n in d.named:
        path = folder / f"{valve_id}_{short}_{n.rank}_{n.spec.key.replace('[', '_').replace(']', '')}.png"
        title = (f"{valve_id}: rank {n.rank} {n.spec.key}, {n.spec.parameter_name} = {_fmt(n.value)} {n.spec.unit} "
                 f"[{_fmt(n.ci_low)}, {_fmt(n.ci_high)}]; gap {n.gap_before:.3g} → {n.gap_after:.3g}")
        out.append(overlay_figure(trace, n.rank - 1, n.rank, title, path))
    return out


def store_run(warehouse: Path, tables: dict[str, pl.DataFrame]) -> None:
    """Append one run's rows to every discrepancy table in one transaction."""
    with connect(warehouse) as con:
        ensure_discrepancy_tables(con)
        with transaction(con):
            for name, frame in tables.items():
                insert_frame(con, name, frame)


def discrepancy_valve(config, valve_id: str, warehouse: Path, start: datetime | None, end: datetime | None, settings: DiscrepancySettings | None = None, condition_mode: str = "auto") -> DiscrepancyReport:
    """Steps 1–4 for one valve over [start, end) of its lake; stores and draws the results."""
    settings = settings or DiscrepancySettings()
    valve = config.valve(valve_id)
    fs = config.export.sample_rate_hz
    settings = replace(settings, sample_period_s=1.0 / fs) if settings.sample_period_s is None else settings
    settings = replace(settings, window_s=config.monitor.window_s) if settings.window_s is None else settings
    run_at = datetime.now(timezone.utc)
    run_id = uuid.uuid4().hex
    records, n_rows = lake_records(warehouse, valve.id, start, end, settings)
    if n_rows == 0:
        raise ValvemonError(f"valve {valve.id}: no lake data in the span; ingest its exports first")
    if not records:
        raise ValvemonError(f"valve {valve.id}: no contiguous record of at least {settings.min_record_s:g} s in the span")
    key, column = REFERENCE_COLUMN
    with_reference = sum(key in r.raw for r in records)
    if settings.reconstruct_spool and not with_reference:
        raise ValvemonError(f"valve {valve.id}: --reconstruct-spool needs the spool reference ({column}) in the lake; none of the span's {len(records)} records holds it")
    plant = plant_params_for(valve, config.export)
    source, plant, cond, fit = valve_condition(valve, plant, warehouse, condition_mode, settings)
    d = diagnose(records, plant, cond, settings, priors=nuisance_priors(valve) if source == "design" else None)
    plots = _plots(valve.id, run_id, d, warehouse)
    tables = _tables(valve.id, run_id, run_at, d, plots, settings.ci_level, source, cond, fit)
    store_run(warehouse, tables)
    return DiscrepancyReport(
        valve_id=valve.id, run_id=run_id, n_records=d.n_records, findings=tables["discrepancy_findings"].to_dicts(),
        plots=[p for p in plots if p is not None], gap_before=d.gap_before, gap_after=d.gap_after, condition_source=source,
        model_note=fit.reason if fit is not None else "", spool_noise_m=d.position_noise.get("x", float("nan")),
        spool_stroke_m=plant.geometry.x_max_m, cylinder_noise_m=d.position_noise.get("X", float("nan")), spool_reconstructed=d.spool_reconstructed,
        spool_reference_records=with_reference,
    )


def check_arguments(config_path: str | Path, valve_id: str, start=None, end=None, condition_mode: str = "auto", max_records: int | None = None):
    """The checks that need no data: the configuration, the valve, the span and the options.
    Returns the configuration and the span (UTC)."""
    config = load_plant_config(config_path)
    plant_valves(config, [valve_id], config_path)
    t0, t1 = utc_instant(start, "--from"), utc_instant(end, "--to")
    if t0 and t1 and t1 <= t0:
        raise ValvemonError("--to must be later than --from")
    if condition_mode not in CONDITION_MODES:
        raise ValvemonError(f"--valve-condition must be one of {', '.join(CONDITION_MODES)}, got {condition_mode!r}")
    if condition_mode == "commissioning" and config.valve(valve_id).baseline_window is None:
        raise ValvemonError(f"valve {valve_id}: --valve-condition commissioning needs a baseline_window in the plant configuration")
    if max_records is not None and max_records < 1:
        raise ValvemonError("--max-records must be at least 1")
    return config, t0, t1


def run_discrepancy(config_path: str | Path, warehouse: str | Path, valve_id: str, start=None, end=None, *, settings: DiscrepancySettings | None = None, condition_mode: str = "auto", runner=discrepancy_valve) -> DiscrepancyReport:
    """Check the arguments and diagnose one valve; ``runner`` lets the flow pass its task."""
    config, t0, t1 = check_arguments(config_path, valve_id, start, end, condition_mode, settings.max_records if settings else None)
    return runner(config, valve_id, Path(warehouse), t0, t1, settings, condition_mode)


@task(name="discrepancy-valve", persist_result=False)
def discrepancy_valve_task(config, valve_id: str, warehouse: Path, start, end, settings=None, condition_mode: str = "auto") -> DiscrepancyReport:
    """One valve's discrepancy workflow as a Prefect task."""
    return discrepancy_valve(config, valve_id, warehouse, start, end, settings, condition_mode)


@flow(name="valvemon-discrepancy", persist_result=False, validate_parameters=False)
def discrepancy_flow(config_path: str, warehouse: str, valve_id: str, start: str | None = None, end: str | None = None, max_records: int | None = None, condition_mode: str = "auto",
                     reconstruct_spool: bool = False) -> DiscrepancyReport:
    """The Prefect flow behind ``valvemon discrepancy`` (``reconstruct_spool``: ``DiscrepancySettings.reconstruct_spool``)."""
    check_arguments(config_path, valve_id, start, end, condition_mode, max_records)
    settings = DiscrepancySettings(reconstruct_spool=bool(reconstruct_spool), **({} if max_records is None else {"max_records": max_records}))
    return run_discrepancy(config_path, warehouse, valve_id, start, end, settings=settings, condition_mode=condition_mode, runner=discrepancy_valve_task)


def summary_lines(report: DiscrepancyReport) -> list[str]:
    """The command line's account of a run."""
    src = ("the base model calibrated on the commissioning window" if report.condition_source == "commissioning"
           else "the design data, its uncertain parameters calibrated within their tolerances")
    lines = [f"{report.valve_id}: model from {src}, {report.n_records} records"]
    if report.model_note:
        lines.append(f"    {report.model_note}")
    if math.isfinite(report.spool_noise_m):
        spool = f"Eq. 1's response to x_ref in {report.spool_reconstructed} of {report.n_records} records" if report.spool_reconstructed else "the reading smoothed"
        lines.append(f"    positions as recorded: spool noise {report.spool_noise_m * 1e6:.2g} µm ({report.spool_noise_m / report.spool_stroke_m:.2%} of x_max), "
                     f"cylinder {report.cylinder_noise_m * 1e6:.2g} µm; the spool taken as {spool}")
        if not report.spool_reconstructed and report.spool_reference_records and report.spool_noise_m >= PLANT_GRADE_SPOOL_NOISE * report.spool_stroke_m:
            lines.append("    the spool reading is as noisy as a plant LVDT and x_ref is recorded: --reconstruct-spool takes the spool as "
                         "Eq. 1's response to x_ref, which reads such valves better (docs/discrepancy.md, \"Positions as plants record them\")")
    first = report.findings[0] if report.findings else {}
    if first.get("verdict"):
        conf = f", confidence {first['confidence']:.0%}" if first.get("confidence") is not None else ""
        what = {"named": f"found {first['effect']}", "ambiguous": f"cannot tell: {first['effect']} or another reading",
                "unexplained": "the data disagree with the model in a way no library effect explains",
                "none": "found no effect beyond the base model"}[first["verdict"]]
        lines.append(f"{report.valve_id}: verdict {first['verdict'].upper()} -- {what}{conf}")
        if first.get("verdict_reason"):
            lines.append(f"    why: {first['verdict_reason']}")
        if first.get("disagreement"):
            lines.append(f"    where: {first['disagreement']}")
        if first.get("alternatives"):
            lines.append(f"    other readings: {first['alternatives']}")
        if first.get("separate_by"):
            lines.append(f"    to tell them apart: {first['separate_by']}")
        if first.get("nuisances"):
            off = [p for p in first["nuisances"].split("; ") if abs(float(p.split("(")[-1].rstrip("σ)"))) >= 1.0]
            gn = first.get("gap_nominal")
            gaps = f"gap {gn:.3g} with the design data → {first['gap_before']:.3g}; " if gn is not None else ""
            lines.append(f"    calibrated base model ({gaps}off nominal by ≥ 1σ: {', '.join(off) or 'nothing'})")
    for f in report.findings:
        if f["effect"] == "none":
            lines.append(f"{report.valve_id}: no library effect named; gap {f['gap_before']:.3g}")
        elif f.get("parameter_ci_low") is None:
            lines.append(f"{report.valve_id}: #{f['rank']} {effect_key(f['effect'], f['variant'])} {f['parameter_name']} = {_fmt(f['parameter_value'])} {f['parameter_unit']}, "
                         f"gap {f['gap_before']:.3g} → {f['gap_after']:.3g}")
        else:
            lines.append(
                f"{report.valve_id}: #{f['rank']} {effect_key(f['effect'], f['variant'])} {f['parameter_name']} = {_fmt(f['parameter_value'])} {f['parameter_unit']} "
                f"[{_fmt(f['parameter_ci_low'])}, {_fmt(f['parameter_ci_high'])}], gap {f['gap_before']:.3g} → {f['gap_after']:.3g} "
                f"({f['gap_explained']:.0%} of the squared gap)"
            )
            if f["alternative_effect"]:
                lines.append(f"    hard to tell from {f['alternative_effect']} on these data (advantage t = {f['alternative_t']:.2g})")
    if report.gap_after > NOISE_GAP:
        hint = (" (is the valve's condition right? --valve-condition commissioning fits it on the configured baseline_window)"
                if report.condition_source == "design" else "")
        lines.append(f"  the model still disagrees: gap {report.gap_after:.3g} > {NOISE_GAP:g}, more than the library explains{hint}")
    for p in report.plots:
        lines.append(f"  overlay: {p}")
    lines.append(f"  run {report.run_id} → discrepancy_findings (and discrepancy_candidates, _gaps, _residuals, _monitoring)")
    return lines

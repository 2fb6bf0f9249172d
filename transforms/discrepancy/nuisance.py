"""The base model's uncertain parameters as nuisance parameters of the discrepancy workflow.

A real valve is never its design data: the edges scatter (α a few %, underlaps some µm), the bulk
modulus and the dead volumes are known to 5–10 %, friction and breakaway to ~30 %, the moving mass
to a few %. Each of these is a nuisance parameter θ_k with a Gaussian prior N(θ_k0, σ_k²) around
its nominal value (the plant configuration's design data), σ_k from :class:`NuisancePriors`
(the plant TOML's ``[valve_types.X.tolerances]`` or the documented defaults). The workflow works
in standardised units z_k = (θ_k − θ_k0) / σ_k, so the prior is z ~ N(0, I) and
|z|² is the nuisances' prior χ² (docs/discrepancy.md, "Nuisance parameters").

The load (piecewise constant, one level per load segment) is a nuisance as well; it is eliminated
exactly by demeaning the motion rows within segments (:mod:`transforms.discrepancy.residuals`).

The nuisances, in this order (:data:`NUISANCES`):

| name | parameter | σ (default) |
|---|---|---|
| alpha_s1 … alpha_2r | contraction coefficient α per edge [-] | 3 % of nominal (manufacturing scatter) |
| underlap_s1 … underlap_2r | underlap x_u per edge [m] | 5 µm (grinding tolerance ±10 µm at 2σ) |
| bulk_modulus | β [Pa] | 7 % (Table 1: 1.4–1.6 GPa; temperature, dissolved air) |
| v01, v02 | dead volumes V01, V02 [m³] | 7 % (piping lengths from drawings) |
| d_v, d_c, d_s | viscous, Coulomb, breakaway friction [N s/m, N, N] | 30 % (seal datasheets) |
| mass | moving mass m [kg] | 2 % (weighed or from drawings) |
| clearance | radial clearance R − r of the Eq. 3 edges [m] | 50 % (a sharp-edged spool, no intercept, is −2σ) |
| land_leakage | closed lands' leakage, Eq. 3's times this [-] | 100 % (worn lands leaking 3× are +2σ) |

The last two are the edges' shape beyond manufacturing scatter (issue 16's valve families): near
zero opening Eq. 3's area has an intercept of 2πR (R − r) cos φ, worth (R − r)/tan φ = 55 µm of
opening at Table 1's port 1 and 109 µm at port 2; a sharp-edged spool has none, and no underlap
scatter can stand in for it. They are exact (σ = 0) for a valve configured ``area_law = "sharp"``,
whose area does not depend on them.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from model.params import EDGES, PlantParams, ValveCondition
from schemas.plant_config import ModelTolerances

__all__ = ["NUISANCES", "NUISANCE_UNITS", "SCATTER", "NuisancePriors", "apply_nuisances", "nuisance_sigmas", "nuisance_values"]

NUISANCES: tuple[str, ...] = tuple(f"alpha_{e}" for e in EDGES) + tuple(f"underlap_{e}" for e in EDGES) + (
    "bulk_modulus", "v01", "v02", "d_v", "d_c", "d_s", "mass", "clearance", "land_leakage")
"""Names of the nuisance parameters, in the order of every nuisance vector."""
SCATTER: tuple[str, ...] = NUISANCES[:-2]
"""The nuisances of a valve's scatter around its design data (all but the edge shape's)."""
NUISANCE_UNITS: dict[str, str] = {**{f"alpha_{e}": "-" for e in EDGES}, **{f"underlap_{e}": "m" for e in EDGES},
                                  "bulk_modulus": "Pa", "v01": "m3", "v02": "m3", "d_v": "N*s/m", "d_c": "N", "d_s": "N", "mass": "kg",
                                  "clearance": "m", "land_leakage": "-"}


@dataclass(frozen=True)
class NuisancePriors(ModelTolerances):
    """Standard deviations of the nuisance priors (0 = the parameter is taken as exact): the plant
    TOML's ``[valves.tolerances]`` (:class:`schemas.plant_config.ModelTolerances`, whose
    defaults are documented there and in docs/configuration.md).

    Attributes
    ----------
    alpha_rel : relative σ of every edge's contraction coefficient [-]
    underlap_m : σ of every edge's underlap [m]
    bulk_modulus_rel, volume_rel : relative σ of β and of V01, V02 [-]
    friction_rel : relative σ of d_v, d_c and d_s [-]
    mass_rel : relative σ of the moving mass [-]
    clearance_rel, land_leakage_rel : relative σ of the radial clearance and of the closed lands' leakage factor [-]
    """

    def __post_init__(self):
        for f in fields(self):
            v = float(getattr(self, f.name))
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"nuisance tolerance {f.name} must be finite and >= 0, got {v}")
            object.__setattr__(self, f.name, v)

    @classmethod
    def exact(cls) -> "NuisancePriors":
        """Every parameter exact: the base model as given (no nuisance is estimated)."""
        return cls(*(0.0 for _ in fields(cls)))

    @property
    def is_exact(self) -> bool:
        return all(getattr(self, f.name) == 0.0 for f in fields(self))


def nuisance_values(plant: PlantParams, condition: ValveCondition) -> np.ndarray:
    """The nuisance parameters of (plant, condition) in :data:`NUISANCES` order (SI)."""
    c, f, g = plant.cylinder, plant.fluid, plant.geometry
    return np.array([*condition.alpha, *condition.underlap_m, f.bulk_modulus_pa, c.v01_m3, c.v02_m3,
                     c.d_v_n_s_m, c.d_c_n, c.d_s_n, c.mass_kg, g.bore_radius_m - g.spool_radius_m, g.leakage_factor], dtype=float)


def nuisance_sigmas(plant: PlantParams, condition: ValveCondition, priors: NuisancePriors) -> np.ndarray:
    """σ_k of every nuisance (SI) around the nominal (plant, condition); the edge shape's are 0
    for a sharp-edged valve (its area does not depend on them)."""
    v = nuisance_values(plant, condition)
    shape = [0.0, 0.0] if plant.geometry.area_law == "sharp" else [priors.clearance_rel, priors.land_leakage_rel]
    rel = np.array([priors.alpha_rel] * 4 + [0.0] * 4 + [priors.bulk_modulus_rel, priors.volume_rel, priors.volume_rel]
                   + [priors.friction_rel] * 3 + [priors.mass_rel] + shape)
    sig = np.abs(v) * rel
    sig[4:8] = priors.underlap_m
    return sig


def apply_nuisances(plant: PlantParams, condition: ValveCondition, values: np.ndarray) -> tuple[PlantParams, ValveCondition]:
    """(plant, condition) with the nuisance parameters ``values`` (SI, :data:`NUISANCES` order);
    values outside the physical range are clipped (α, β, volumes, mass > 0; underlap > 0.1 µm;
    friction ≥ 0, d_s ≥ d_c; V02 large enough for the stroke; clearance ≥ 1 nm, leakage factor
    ≥ 0.01)."""
    v = np.asarray(values, float)
    c, f, g = plant.cylinder, plant.fluid, plant.geometry
    alpha = tuple(float(max(a, 1e-3)) for a in v[0:4])
    xu = tuple(float(max(u, 1e-7)) for u in v[4:8])
    d_c = float(max(v[12], 0.0))
    d_s = float(max(v[13], d_c))
    v02_min = 1.02 * c.A2 * c.stroke_m
    cyl = replace(c, v01_m3=float(max(v[9], 1e-5)), v02_m3=float(max(v[10], v02_min)), d_v_n_s_m=float(max(v[11], 0.0)),
                  d_c_n=d_c, d_s_n=d_s, mass_kg=float(max(v[14], 1.0)))
    gap = g.bore_radius_m - g.spool_radius_m
    geo = replace(g, spool_radius_m=g.spool_radius_m if v[15] == gap else g.bore_radius_m - float(max(v[15], 1e-9)),
                  leakage_factor=float(max(v[16], 0.01)))
    p = replace(plant, cylinder=cyl, fluid=replace(f, bulk_modulus_pa=float(max(v[8], 1e7))), geometry=geo)
    return p, ValveCondition(underlap_m=xu, alpha=alpha, x_l_fraction=condition.x_l_fraction)

"""Valve condition over operating hours: healthy, wear and broken-edge scenarios.

The condition of the four edges (underlap x_u and contraction coefficient alpha per edge, in
:data:`~model.params.EDGES` order and each edge's opening coordinate) as a function of the
operating hours t [h]:

* manufacturing scatter (optional, any scenario): x_u,i += N(0, sigma_x), alpha_i *= 1 + N(0,
  sigma_alpha), drawn once from ``scatter_seed`` -- even new valves differ (paper Sec. 2.1);
* wear (paper Sec. 4): the underlap grows at a constant rate and alpha grows at a rate that
  falls over time as the edges round off,

      x_u,i(t)   = x_u,i(0) + r_i t
      alpha_i(t) = alpha_i(0) (1 + a_inf,i (1 - exp(-t / tau)))

  The preset :data:`WEAR` is calibrated on the paper's Table 3 (edge s2, measured):
  alpha-hat = 1.04 and x-hat = 0.1 % x_max at 700 h, alpha-hat = 1.17 and x-hat = 3.7 % x_max at
  16,700 h. With r = 3.7 % x_max / 16,700 h = 7.75 nm/h, a_inf = 0.18 and tau = 3000 h the
  model gives 1.037 / 0.16 % at 700 h, 1.179 / 3.7 % at 16,700 h, and 1.180 / 4.4 % at
  20,000 h.
* broken edge (paper Sec. 5.1, Table 2, edge 1r): from ``broken_from_h`` on, the edge's alpha
  is multiplied by 2.5 and its underlap grows by 11.8 % of x_max (0.413 mm for x_max = 3.5 mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .params import EDGES, TABLE1, ValveCondition, edge_index

_X_MAX_TABLE1 = TABLE1.geometry.x_max_m


def _four(v) -> tuple[float, float, float, float]:
    if np.ndim(v) == 0:
        return (float(v),) * 4
    t = tuple(float(a) for a in v)
    if len(t) != 4:
        raise ValueError(f"need 4 values in EDGES order {EDGES}")
    return t  # type: ignore[return-value]


@dataclass(frozen=True)
class Scenario:
    """How a valve's condition develops with operating hours (module docstring).

    Attributes
    ----------
    name : str
        Label, e.g. ``"healthy"``, ``"wear"``, ``"broken_edge"``.
    underlap_rate_m_per_h : tuple of 4 float
        Constant underlap growth r per edge. [m/h]
    alpha_gain_inf : tuple of 4 float
        Final relative growth a_inf of alpha per edge. [-]
    alpha_tau_h : float
        Time constant tau of the alpha growth. [h]
    broken_edge : str or None
        Edge that breaks (``None``: none).
    broken_from_h : float
        Operating hour from which the edge is broken. [h]
    broken_alpha_factor : float
        Factor on the broken edge's alpha. [-] (Table 2: 2.5)
    broken_underlap_increase_m : float
        Underlap increase of the broken edge. [m] (Table 2: 11.8 % of 3.5 mm = 0.413 mm)
    scatter_seed : int or None
        Seed of the manufacturing scatter; ``None``: the base condition as given.
    underlap_scatter_m : float
        Standard deviation of the underlap scatter. [m] (5 um: a tight grinding tolerance of
        the control edges, +-10 um at 2 sigma)
    alpha_scatter_rel : float
        Relative standard deviation of alpha. [-] (3 %)
    """

    name: str
    underlap_rate_m_per_h: tuple[float, float, float, float] = (0.0,) * 4
    alpha_gain_inf: tuple[float, float, float, float] = (0.0,) * 4
    alpha_tau_h: float = 3000.0
    broken_edge: str | None = None
    broken_from_h: float = 0.0
    broken_alpha_factor: float = 2.5
    broken_underlap_increase_m: float = 0.118 * _X_MAX_TABLE1
    scatter_seed: int | None = None
    underlap_scatter_m: float = 5.0e-6
    alpha_scatter_rel: float = 0.03

    def __post_init__(self):
        object.__setattr__(self, "underlap_rate_m_per_h", _four(self.underlap_rate_m_per_h))
        object.__setattr__(self, "alpha_gain_inf", _four(self.alpha_gain_inf))
        if self.alpha_tau_h <= 0:
            raise ValueError("alpha_tau_h must be > 0")
        if self.broken_edge is not None:
            edge_index(self.broken_edge)


def manufactured(base: ValveCondition, seed: int, underlap_scatter_m: float = 5.0e-6,
                 alpha_scatter_rel: float = 0.03) -> ValveCondition:
    """A new valve's condition: ``base`` with manufacturing scatter drawn from ``seed``.

    Underlaps get additive N(0, underlap_scatter_m) [m] (kept > 0), alphas a relative
    N(0, alpha_scatter_rel) [-]. Deterministic for a seed.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5CA7]))
    xu = np.asarray(base.underlap_m) + rng.normal(0.0, underlap_scatter_m, 4)
    xu = np.maximum(xu, 1.0e-6)
    al = np.asarray(base.alpha) * (1.0 + rng.normal(0.0, alpha_scatter_rel, 4))
    return ValveCondition(tuple(xu), tuple(al), base.x_l_fraction)


def condition_arrays(scenario: Scenario, hours, base: ValveCondition | None = None):
    """Underlap and alpha per edge at the given operating hours.

    Parameters
    ----------
    scenario : Scenario
    hours : array_like, shape (n,)
        Operating hours since commissioning (>= 0). [h]
    base : ValveCondition, optional
        Condition at 0 h before scatter; default ``TABLE1.nominal_condition``.

    Returns
    -------
    (underlap_m, alpha) : ndarray, shape (n, 4) each
        [m] and [-], columns in EDGES order.
    """
    base = TABLE1.nominal_condition if base is None else base
    t = np.atleast_1d(np.asarray(hours, dtype=np.float64))
    if np.any(t < 0):
        raise ValueError("operating hours must be >= 0")
    if scenario.scatter_seed is not None:
        base = manufactured(base, scenario.scatter_seed, scenario.underlap_scatter_m,
                            scenario.alpha_scatter_rel)
    xu = np.asarray(base.underlap_m)[None, :] + t[:, None] * np.asarray(
        scenario.underlap_rate_m_per_h)[None, :]
    growth = 1.0 + np.asarray(scenario.alpha_gain_inf)[None, :] * (
        1.0 - np.exp(-t[:, None] / scenario.alpha_tau_h))
    al = np.asarray(base.alpha)[None, :] * growth
    if scenario.broken_edge is not None:
        i = edge_index(scenario.broken_edge)
        broken = t >= scenario.broken_from_h
        al[broken, i] *= scenario.broken_alpha_factor
        xu[broken, i] += scenario.broken_underlap_increase_m
    return xu, al


def condition_at(scenario: Scenario, hours, base: ValveCondition | None = None) -> list[ValveCondition]:
    """The valve condition at each of ``hours`` [h] under ``scenario`` (see
    :func:`condition_arrays`), as a list of :class:`~model.params.ValveCondition`."""
    base = TABLE1.nominal_condition if base is None else base
    xu, al = condition_arrays(scenario, hours, base)
    return [ValveCondition(tuple(xu[i]), tuple(al[i]), base.x_l_fraction) for i in range(len(xu))]


def healthy(scatter_seed: int | None = None, **kw) -> Scenario:
    """A healthy valve that does not change; with manufacturing scatter if a seed is given."""
    return Scenario("healthy", scatter_seed=scatter_seed, **kw)


def wear(underlap_rate_m_per_h=7.75e-9, alpha_gain_inf=0.18, alpha_tau_h: float = 3000.0,
         scatter_seed: int | None = None, **kw) -> Scenario:
    """Gradual wear of all edges (defaults calibrated on Table 3; module docstring)."""
    return Scenario("wear", underlap_rate_m_per_h=underlap_rate_m_per_h,
                    alpha_gain_inf=alpha_gain_inf, alpha_tau_h=alpha_tau_h,
                    scatter_seed=scatter_seed, **kw)


def broken_edge(edge: str = "1r", from_hours: float = 0.0, alpha_factor: float = 2.5,
                underlap_increase_m: float = 0.118 * _X_MAX_TABLE1,
                scatter_seed: int | None = None, **kw) -> Scenario:
    """A control edge that breaks at ``from_hours`` (defaults: Table 2, edge 1r)."""
    return Scenario("broken_edge", broken_edge=edge, broken_from_h=from_hours,
                    broken_alpha_factor=alpha_factor,
                    broken_underlap_increase_m=underlap_increase_m,
                    scatter_seed=scatter_seed, **kw)


#: No change over time, no scatter.
HEALTHY: Scenario = healthy()
#: Table 3 calibrated wear on all four edges.
WEAR: Scenario = wear()
#: Table 2: edge 1r broken from 0 h on.
BROKEN_1R: Scenario = broken_edge()

"""The second reference plant: the valve and positioning unit of the method, written apart from
``model/`` (it imports nothing of ``model``, ``transforms``, ``flows`` or ``schemas``), from the
same equations with different choices, so that a structural difference between a plant and
``model/`` reaches the tests.

What differs from ``model/`` on purpose:

* integration: scipy's LSODA (or ``solve_ivp``'s BDF or Radau, ``Integration.method``), one
  integration per 10 s window, its dense output sampled at 1 kHz; a continuous-time PI position controller with its
  own closed-form feed-forward (``model/``: fixed-step RK4 and a digital PI);
* friction: Karnopp sticking inside a band |v_X| < 1 mm/s while |F_R| <= d_s, Stribeck (Eq. 5)
  when sliding;
* loads: a new level every 1-4 s (0 or uniform in +-6 kN), reached by a linear ramp (a rolling
  force: continuous, piecewise linear);
* transmitters: first-order lag of 1 ms on every pressure, the pressures recorded one sample late
  against the positions, noise and 16-bit quantisation; positions at 1 um by default, or as a
  plant records them (:func:`plant_grade` draws spool 0.05-0.3 % of x_max and cylinder 1-20 um in
  steps of 1-5 um per plant; :func:`noisy_end`: spool 0.2 %, cylinder 10 um in 5 um steps);
* operation: busy (dwells 0.2-0.8 s) by default, or :func:`sparse` (dwells 2-10 s between moves);
* edge families per edge: Eq. 3 (written again), a sharp edge without radial clearance, a linear
  gradient with a hard corner (alpha A = C_q g max(u + x_u, 0), g = sin(phi) pi 2R per port), and
  that gradient with a laminar region at small openings (the discharge coefficient falls with the
  slot's flow number: an orifice law other than Eq. 4's near the corner);
* a valve as built (underlap and alpha scatter per edge, beta 2.5 % off its nameplate), wear per
  edge, and hidden effects (the discrepancy library's, in this package's own implementation, and
  two outside it: pressure-dependent seal friction, an extra lag on one transmitter).

Public API::

    plant = worn(family(manufactured(NAMEPLATE, seed=3), "linear"),
                 alpha_scale={"s2": 1.15}, underlap_shift_m={"s2": 0.03e-3})
    rec = simulate(plant, 10.0, seed=7, effects=effect("external_leakage", 1e-12))
    rec.p1, rec.x_spool, ...            # recorded signals [SI], rec.true[...] the truth
    rec.edge_truth()                    # per edge: law, alpha, underlap_m, gradient_m
    lake = to_lake_frame(simulate_windows(plant, 3, seed=7), "V1", start)   # canonical lake rows

``lake`` is what ``transforms.discrepancy.split_records`` and ``transforms.monitor.monitor`` take, and
what ``flows.common.lake.write_partition`` writes per (valve, date).
"""

from .edges import edge_area, valve_areas
from .lake import COLUMNS, simulate_windows, to_lake_frame
from .params import (EDGES, LAWS, NAMEPLATE, Channel, Controller, Cylinder, Edge, Fluid, Integration,
                     Operation, RefPlant, Sensors, Spool, Supply, Valve, family, idealised, manufactured,
                     noisy_end, plant_grade, position_sensors, sparse, worn)
from .recording import RefRecording, simulate, without_noise
from .scenarios import LIBRARY, OUTSIDE, TYPICAL, Effects, Load, Trajectory, draw_load, draw_trajectory, effect

__all__ = [
    "EDGES", "LAWS", "NAMEPLATE", "Channel", "Controller", "Cylinder", "Edge", "Fluid", "Integration",
    "Operation", "RefPlant", "Sensors", "Spool", "Supply", "Valve", "family", "idealised", "manufactured",
    "noisy_end", "plant_grade", "position_sensors", "sparse", "worn",
    "edge_area", "valve_areas", "RefRecording", "simulate", "without_noise", "COLUMNS", "simulate_windows",
    "to_lake_frame", "LIBRARY", "OUTSIDE", "TYPICAL", "Effects", "Load", "Trajectory", "draw_load",
    "draw_trajectory", "effect",
]

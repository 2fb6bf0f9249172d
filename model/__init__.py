"""valvemon.model: the physics of Steinboeck et al. (2013) -- parameters, Eqs. 1-6 and 9,
the closed-loop plant, a fast batch simulator, sensor models and valve-condition scenarios.

Pure functions over numpy arrays (numba kernels inside), SI units throughout, no I/O, no
imports from the project's other packages. The equations with their recovered signs are in
``docs/model.md``.
"""

from .area import edge_area, opening_coordinate, valve_areas
from .condition import (BROKEN_1R, HEALTHY, WEAR, Scenario, broken_edge, condition_arrays,
                        condition_at, healthy, manufactured, wear)
from .controller import feedforward, feedforward_table, pi_step
from .effects import EFFECT_LIBRARY, EFFECT_NAMES, EffectSpec, Effects
from .cylinder import (chamber_volumes, cylinder_acceleration, friction_force,
                       pressure_derivatives, resultant_force)
from .orifice import orifice_flow, port_flows, port_flows_from_areas
from .params import (AREA_LAWS, EDGES, OPENING_SIGN, TABLE1, ControllerParams, CylinderParams,
                     FluidParams, LoadParams, PlantParams, SensorChannel, SensorParams,
                     SpoolParams, SupplyParams, TrajectoryParams, ValveCondition, ValveGeometry,
                     edge_index)
from .sensors import MeasuredSignals, measure
from .replay import ReplayResult, replay
from .simulate import (SimulationResult, rhs, simulate_inputs, simulate_windows, window_seed)
from .spool import spool_acceleration
from .standstill import RestState, eq9_residual, standstill, steady_state, steady_states
from .trajectory import (SupplyProfile, WindowInputs, draw_supply, load_profile,
                         minimum_jerk, reference_trajectory, window_inputs)

__all__ = [
    "AREA_LAWS", "EDGES", "OPENING_SIGN", "TABLE1", "ControllerParams", "CylinderParams", "FluidParams",
    "LoadParams", "PlantParams", "SensorChannel", "SensorParams", "SpoolParams", "SupplyParams",
    "TrajectoryParams", "ValveCondition", "ValveGeometry", "edge_index",
    "edge_area", "opening_coordinate", "valve_areas",
    "orifice_flow", "port_flows", "port_flows_from_areas",
    "spool_acceleration",
    "chamber_volumes", "cylinder_acceleration", "friction_force", "pressure_derivatives",
    "resultant_force",
    "RestState", "eq9_residual", "standstill", "steady_state", "steady_states",
    "feedforward", "feedforward_table", "pi_step",
    "SupplyProfile", "WindowInputs", "draw_supply", "load_profile", "minimum_jerk",
    "reference_trajectory", "window_inputs",
    "BROKEN_1R", "HEALTHY", "WEAR", "Scenario", "broken_edge", "condition_arrays",
    "condition_at", "healthy", "manufactured", "wear",
    "SimulationResult", "rhs", "simulate_inputs", "simulate_windows", "window_seed",
    "MeasuredSignals", "measure",
    "EFFECT_LIBRARY", "EFFECT_NAMES", "EffectSpec", "Effects", "ReplayResult", "replay",
]

"""The reference plant against ``model/``: both implement the same equations.

With every deliberate difference switched off (no transmitter lag or skew, a near-exact stick
condition instead of Karnopp's band, Eq. 3 edges, the nominal valve, a constant load) and the
same inputs -- reference, load, supply, and the spool command of ``model``'s digital PI replayed
into this plant in open loop (the controllers differ on purpose) -- the two agree to 0.05 bar in
p1 and p2, 1 um in X and 0.05 um in x over a window with moves and dwells (measured on 10 s:
3.6 mbar, 0.13 um, 0.009 um). The package itself imports nothing of the project's packages.
"""

import ast
from pathlib import Path

import numpy as np

from . import NAMEPLATE, Load, Trajectory, idealised, simulate, without_noise

HERE = Path(__file__).parent


def test_agrees_with_model_on_the_same_inputs():
    from model import TABLE1, simulate_inputs
    from model.trajectory import SupplyProfile, WindowInputs

    plant = without_noise(idealised(NAMEPLATE))
    dur, fs = 2.5, 1000.0
    n = int(dur * fs)
    traj = Trajectory.moves(0.40, [(0.2, 0.9, 0.25), (1.5, 0.8, 0.35)])  # retract, dwell, extend, dwell
    Xr, vr = traj.at(np.arange(n) / fs)
    F_l, sup = 3.0e3, (200e5, 0.05e5, 0.3e5, 225.0, 0.7, 0.5e5)
    ref = simulate_inputs(TABLE1, [TABLE1.nominal_condition], [WindowInputs(Xr, vr, np.full(n, F_l), SupplyProfile(*sup))],
                          substeps=4)
    y0 = np.array([ref.x_m[0, 0], 0.0, ref.X_m[0, 0], 0.0, ref.p1_pa[0, 0], ref.p2_pa[0, 0], 0.0])
    rec = simulate(plant, dur, 0, load=Load.constant(F_l), trajectory=traj, supply=sup, spool_command=ref.x_ref_m[0],
                   initial_state=y0)
    T = rec.true
    assert np.ptp(ref.X_m[0]) > 0.1 and np.mean(ref.vX_m_s[0] == 0) > 0.05  # moves and sticking dwells
    assert np.abs(T["p1"] - ref.p1_pa[0]).max() < 0.05e5
    assert np.abs(T["p2"] - ref.p2_pa[0]).max() < 0.05e5
    assert np.abs(T["X"] - ref.X_m[0]).max() < 1e-6
    assert np.abs(T["x"] - ref.x_m[0]).max() < 0.05e-6


def test_the_plant_imports_nothing_of_the_project():
    forbidden = ("model", "transforms", "flows", "schemas", "tests")
    for path in HERE.glob("*.py"):
        if path.name.startswith("test_"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            bad = [m for m in names if m.split(".")[0] in forbidden]
            assert not bad, f"{path.name} imports {bad}"

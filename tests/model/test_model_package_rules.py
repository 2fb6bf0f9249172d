"""docs/architecture.md: model/ imports none of the project's other packages and does no I/O."""

import ast
from pathlib import Path

import model

MODEL_DIR = Path(model.__file__).parent
FORBIDDEN_IMPORTS = {"schemas", "transforms", "flows", "sql", "prefect", "polars", "duckdb",
                     "pyarrow", "pandas"}
FORBIDDEN_CALLS = {"open", "print", "input"}


def _sources():
    files = sorted(MODEL_DIR.glob("*.py"))
    assert len(files) >= 12
    return [(f, ast.parse(f.read_text())) for f in files]


def test_model_imports_nothing_of_the_project():
    for path, tree in _sources():
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""] if node.level == 0 else []
            else:
                continue
            for name in names:
                assert name.split(".")[0] not in FORBIDDEN_IMPORTS, (path.name, name)


def test_model_does_no_io():
    for path, tree in _sources():
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id not in FORBIDDEN_CALLS, (path.name, node.func.id)
            if isinstance(node, ast.Attribute):
                assert node.attr not in {"read_text", "write_text", "read_bytes", "write_bytes",
                                         "to_csv", "to_parquet", "savez", "save"}, path.name


def test_public_api_names():
    for name in ("EDGES", "TABLE1", "ValveGeometry", "ValveCondition", "SpoolParams",
                 "CylinderParams", "FluidParams", "SupplyParams", "ControllerParams",
                 "SensorParams", "PlantParams", "edge_area", "opening_coordinate", "valve_areas",
                 "port_flows", "eq9_residual", "standstill", "condition_at", "Scenario", "rhs",
                 "simulate_windows", "SimulationResult", "measure", "MeasuredSignals"):
        assert hasattr(model, name), name
    assert model.EDGES == ("s1", "1r", "s2", "2r")

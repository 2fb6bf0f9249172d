"""docs/architecture.md: imports point one way and never in a circle; flows/ is laid out by stage."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("flows", "transforms", "model", "schemas")
ALLOWED = {
    "flows": {"flows", "transforms", "model", "schemas"},
    "transforms": {"transforms", "model", "schemas"},
    "model": {"model"},
    "schemas": {"schemas"},
}
NO_IO_OR_ORCHESTRATION = {"prefect", "prefect_dask", "duckdb", "typer", "rich", "matplotlib"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(path: Path) -> set[str]:
    """Every module imported anywhere in the file, functions included (a deferred import is still an edge)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


MODULES = _modules()


def _graph() -> dict[str, set[str]]:
    return {m: {n for n in _imports(p) if n in MODULES and n != m and not m.startswith(n + ".")} for m, p in MODULES.items()}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_one_way(module):
    pkg = module.split(".")[0]
    for name in _imports(MODULES[module]):
        top = name.split(".")[0]
        if top in PACKAGES:
            assert top in ALLOWED[pkg], f"{module} imports {name}"
        if pkg != "flows":
            assert top not in NO_IO_OR_ORCHESTRATION, f"{module} imports {name}: only flows/ does I/O or knows Prefect"


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return path[path.index(n):] + [n]
            if n not in state and (found := visit(n, path + [n])):
                return found
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m, [m])):
            return found
    return None


def test_no_import_circles():
    assert _find_cycle(_graph()) is None


def test_circle_detector_finds_the_old_circle():
    """characteristic imported fit inside two functions while fit imported characteristic."""
    graph = _graph()
    graph["transforms.characteristic"] = graph["transforms.characteristic"] | {"transforms.fit"}
    cycle = _find_cycle(graph)
    assert cycle is not None and {"transforms.characteristic", "transforms.fit"} <= set(cycle)


def test_flows_is_laid_out_by_stage():
    stages = {"common", "simulate", "ingest", "monitor", "report", "discrepancy", "orchestration", "retention"}
    folders = {p.name for p in (ROOT / "flows").iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert stages <= folders
    loose = sorted(p.name for p in (ROOT / "flows").glob("*.py"))
    assert loose == ["__init__.py", "cli.py", "demo.py"], loose

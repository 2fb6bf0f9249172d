"""The command line's values converted without pydantic (`flows.common.cli_values`) are typer's own:
the same value and type, or the same error, for every parameter of every command."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import typer
from hypothesis import given, settings
from hypothesis import strategies as st
from typer._click import Context
from typer._click.exceptions import BadParameter
from typer._coercion import build_runtime_param

from flows.cli import app
from flows.common.cli_values import PlainValue, convert_plainly, plain_value

ROOT = Path(__file__).resolve().parents[1]


def _parameters() -> list[tuple[str, object, object]]:
    """(name, command, parameter) of every parameter of every command, help options included."""
    group = typer.main.get_command(app)
    out = []
    for cmd in [group, *group.commands.values()]:
        help_option = cmd.get_help_option(Context(cmd))
        for p in [*cmd.params, help_option]:
            out.append((f"{cmd.name}.{p.name}", cmd, p))
    return out


PARAMETERS = _parameters()
PLAIN = [(name, cmd, p) for name, cmd, p in PARAMETERS if plain_value(p) is not None]


def _convert(converter, value, cmd, param):
    try:
        out = converter.coerce(value, param=param, ctx=Context(cmd))
    except BadParameter as exc:
        return ("error", exc.format_message())
    return ("value", type(out).__name__, [(type(v).__name__, v) for v in out] if isinstance(out, list) else out)


def _same(value, cmd, param):
    ours = _convert(plain_value(param), value, cmd, param)
    typers = _convert(build_runtime_param(param.type_descriptor), value, cmd, param)
    assert ours == typers, (param.name, value)


def test_every_parameter_of_the_monitor_command_converts_plainly():
    """What makes `valvemon monitor` run without pydantic (the subprocess test below)."""
    names = {name for name, _, _ in PLAIN}
    monitor = {f"monitor.{p}" for p in ("config", "valves", "start", "end", "warehouse", "help")}
    assert monitor <= names, monitor - names
    kinds = {type(plain_value(p)).__name__ for _, _, p in PLAIN}
    assert kinds == {PlainValue.__name__}


@pytest.fixture(scope="module")
def paths(tmp_path_factory) -> list[str]:
    root = tmp_path_factory.mktemp("paths")
    (root / "file.toml").write_text("x")
    (root / "dir").mkdir()
    return [str(root / "file.toml"), str(root / "dir"), str(root / "missing"), str(root / "dir") + "/", "", "-", ".", "a//b", "~/x"]


@pytest.mark.parametrize("name, cmd, param", PLAIN, ids=[n for n, _, _ in PLAIN])
def test_the_values_a_command_line_gives(name, cmd, param, paths):
    """Strings, lists of them, flags' bools, the defaults, None, and values typer rejects."""
    values = [None, param.default, True, False, 0, 3, 2.5, "3", "2.5", "yes", "x y", Path("p"), "\x00", "a\x00b", *paths]
    for v in values:
        _same(v, cmd, param)
    for v in ([], ("a", "b"), ["3", "x"], ("a", "\x00"), (Path("p"),), tuple(paths)):
        _same(v, cmd, param)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(PLAIN), st.one_of(st.text(), st.lists(st.text(), max_size=3)))
def test_any_text(parameter, value):
    _, cmd, param = parameter
    _same(value, cmd, param)


def test_the_others_keep_typers_converter():
    """A parameter left out (a choice, a parser, a range …) is not given one; each command's
    parameters that are given one get it on the command line `valvemon` runs."""
    group = typer.main.get_command(app)
    convert_plainly(group)
    for cmd in [group, *group.commands.values()]:
        for p in [*cmd.params, cmd.get_help_option(Context(cmd))]:
            assert isinstance(p._runtime_param, PlainValue) == (plain_value(p) is not None), p.name


_RUN = textwrap.dedent("""
    import json, sys
    import flows.common.prefect_run as prefect_run
    import flows.report.publish
    from flows.cli import main

    def run_flow(flow, **parameters):  # the command's parameters, as typer gave them
        print(json.dumps({k: [type(v).__name__, str(v) if not isinstance(v, list) else v] for k, v in parameters.items()}))
        return []

    prefect_run.run_flow = run_flow
    flows.report.publish.publish = lambda config, warehouse: None
    sys.argv = ["valvemon", *sys.argv[1:]]
    try:
        main()
    except SystemExit as exc:
        print(json.dumps({"code": exc.code, "pydantic": "pydantic" in sys.modules}))
""")


def test_the_monitor_command_line_without_pydantic(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")}
    env |= {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp_path / "prefect-home")}
    config = tmp_path / "plant.toml"
    config.write_text("")
    args = ["monitor", "--config", str(config), "--valves", "V1", "--valves", "V2", "--from", "2025-01-01", "--warehouse", str(tmp_path / "wh")]
    proc = subprocess.run([sys.executable, "-c", _RUN, *args], env=env, capture_output=True, text=True, timeout=120)
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    assert lines[-1] == {"code": 0, "pydantic": False}, proc.stderr
    assert lines[0] == {
        "config_path": ["str", str(config)],
        "warehouse": ["str", str(tmp_path / "wh")],
        "valve_ids": ["list", ["V1", "V2"]],
        "start": ["str", "2025-01-01"],
        "end": ["NoneType", "None"],
    }

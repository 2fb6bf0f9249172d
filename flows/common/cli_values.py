"""The command line's values converted as typer converts them, without pydantic.

typer (0.29) converts every option's and argument's value with a pydantic ``TypeAdapter`` that
it builds on first use: importing pydantic and building the adapters cost every command
0.15–0.2 CPU-s (BENCHMARKS.md, row LAT-7), ten times what
parsing the command line costs otherwise. The values valvemon's commands get need none of it:
:func:`convert_plainly` gives each parameter whose annotation is ``str``, ``Path``, ``bool``,
``int`` or ``float`` (or a list of one) a converter that returns what typer's would for the
values a command line gives it (a string, a list of strings, a flag's bool, the default) and
hands every other value to typer's own converter, so a value typer would reject fails with
typer's own message. ``tests/test_cli_values.py`` holds the two to the same results for every
parameter of every command.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, get_args, get_origin

from typer._click import Command, Context
from typer._click.exceptions import BadParameter
from typer._coercion import RuntimeParam, build_runtime_param
from typer._param_types import coerce_cli_path, routes_to_path

PLAIN_TYPES = (str, Path, bool, int, float)


class _Typers(Exception):
    """A value :class:`PlainValue` leaves to typer's converter."""


@dataclass(frozen=True)
class PlainValue(RuntimeParam):
    """typer's conversion of one parameter's values (``RuntimeParam``; typer's handles ``None``
    and the checks of several values) with the values of :data:`PLAIN_TYPES` converted here."""

    leaf: type = str
    many: bool = False
    typers: list = field(default_factory=list, compare=False)
    """typer's own converter, built when first needed."""

    def _coerce_value(self, value: Any, param, ctx: Context) -> Any:
        try:
            if self.many:
                return [self._one(v, param, ctx) for v in (value if isinstance(value, (list, tuple)) else [value])]
            return self._one(value, param, ctx)
        except (_Typers, BadParameter):  # typer's converter, its result or its message
            if not self.typers:
                self.typers.append(build_runtime_param(param.type_descriptor))
            return self.typers[0]._coerce_value(value, param=param, ctx=ctx)

    def _one(self, value: Any, param, ctx: Context) -> Any:
        if self.leaf is Path and isinstance(value, (str, Path)):
            if "\x00" in str(value):  # pydantic rejects a NUL in a path with its own message: typer's
                raise _Typers
            # typer's: the string as a Path (pydantic's Path(value)), then its checks of the path
            return coerce_cli_path(Path(value), self.parameter_info, path_type=Path, param=param, ctx=ctx)
        if type(value) is self.leaf:  # a string as given, a flag's bool, a default of the type
            return value
        raise _Typers


def plain_value(param) -> PlainValue | None:
    """The converter of a typer parameter whose values convert plainly (None: typer's)."""
    desc = getattr(param, "type_descriptor", None)
    if desc is None or desc.file_annotation is not None:
        return None
    info, annotation = desc.parameter_info, desc.annotation
    many = get_origin(annotation) is list
    leaf = get_args(annotation)[0] if many else annotation
    if leaf not in PLAIN_TYPES or info.parser is not None or desc.is_choice:
        return None
    if routes_to_path(leaf, info) != (leaf is Path) or (leaf is Path and info.path_type is not None):
        return None  # a string with path options, a Path converted to another type: typer's
    if leaf in (int, float) and desc.is_ranged:
        return None
    return PlainValue(info, annotation, leaf, many)


def convert_plainly(command: Command) -> None:
    """Give every parameter of ``command`` and of its subcommands (help options included) a
    :class:`PlainValue` converter where :func:`plain_value` has one; the others keep typer's."""
    commands = [command, *getattr(command, "commands", {}).values()]
    for cmd in commands:
        cmd.get_help_option(Context(cmd))  # made now (then kept), so that it gets one too
        for param in cmd.params + [p for p in (getattr(cmd, "_help_option", None),) if p is not None]:
            if getattr(param, "_runtime_param", False) is None:
                plain = plain_value(param)
                if plain is not None:
                    param._runtime_param = plain

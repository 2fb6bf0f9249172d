"""Reading the plant configuration and locating the warehouse (the only I/O around them)."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING

from flows.common.errors import ValvemonError
from schemas.errors import ConfigError

if TYPE_CHECKING:
    from schemas.plant_config import PlantConfig

WAREHOUSE_ENV = "VALVEMON_WAREHOUSE"
DEFAULT_WAREHOUSE = Path("warehouse")


def load_plant_config(path: str | Path) -> PlantConfig:
    """Read and validate a plant TOML file; errors name the file and the key."""
    from schemas.plant_config import parse_plant_config  # the field registry imports polars: not for every command

    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such configuration file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    try:
        return parse_plant_config(data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def warehouse_dir(option: str | Path | None) -> Path:
    """The warehouse folder: ``--warehouse``, else ``$VALVEMON_WAREHOUSE``, else ``warehouse/``."""
    if option:
        return Path(option)
    env = os.environ.get(WAREHOUSE_ENV)
    return Path(env) if env else DEFAULT_WAREHOUSE


def plant_valves(config: PlantConfig, valve_ids, where: str | Path) -> list[str]:
    """The valves a command works on: ``valve_ids`` (all of the plant's when empty), each checked
    against the plant; an unknown one fails naming ``where`` (the file or option), the valve and
    the plant's valves."""
    known = [v.id for v in config.valves]
    unknown = sorted(set(valve_ids or []) - set(known))
    if unknown:
        raise ValvemonError(f"{where}: no valve {unknown[0]!r} in plant {config.name!r} (valves: {', '.join(known)})")
    return list(valve_ids or known)

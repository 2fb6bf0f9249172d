"""Reading the plant configuration and locating the warehouse (the only I/O around them)."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING

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

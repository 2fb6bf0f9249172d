"""Engineering units accepted in plant configurations and exports, and their SI factors.

Only multiplicative units occur (gauge pressures, positions), so a unit is one factor to SI.
The spool position may also be given in % of x_max; its factor depends on the valve.
"""

from __future__ import annotations

PSI_PA = 6894.757293168361
"""One pound-force per square inch. [Pa]"""

PRESSURE_UNITS: dict[str, float] = {"bar": 1e5, "Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "psi": PSI_PA}
POSITION_UNITS: dict[str, float] = {"mm": 1e-3, "m": 1.0, "um": 1e-6}
PERCENT_OF_X_MAX = "%"


class UnitError(ValueError):
    """A unit that is not accepted for a signal."""


def si_factor(unit: str, kind: str, x_max_m: float | None = None) -> float:
    """Factor that converts a value in ``unit`` to SI.

    Parameters
    ----------
    unit : str
        Unit as written in the configuration, e.g. ``"bar"``, ``"mm"``, ``"%"``.
    kind : str
        ``"pressure"``, ``"position"`` or ``"spool_position"`` (which also accepts ``%`` of x_max).
    x_max_m : float, optional
        Largest spool displacement, needed for ``%``. [m]
    """
    if kind == "pressure":
        table = PRESSURE_UNITS
    elif kind in ("position", "spool_position"):
        table = POSITION_UNITS
        if kind == "spool_position" and unit == PERCENT_OF_X_MAX:
            if x_max_m is None:
                raise UnitError("'%' needs x_max")
            return x_max_m / 100.0
    else:
        raise UnitError(f"unknown signal kind {kind!r}")
    if unit not in table:
        accepted = list(table) + ([PERCENT_OF_X_MAX] if kind == "spool_position" else [])
        raise UnitError(f"unknown {kind.replace('_', ' ')} unit {unit!r} (expected one of {', '.join(accepted)})")
    return table[unit]

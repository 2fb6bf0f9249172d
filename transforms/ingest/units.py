"""Units an export file states (a unit header row, TDMS ``unit_string``) against the configuration's.

A recorder's file says each signal's unit. :func:`tags_with_file_units` checks it against
``[valves.tags] unit`` (a different unit refuses the file, naming the column and both units) and,
where the configuration leaves the unit out (allowed when ``export.header_rows`` has a ``"unit"``
line), takes the file's: the SI factors of that file's tags come from its own header.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from schemas.fields import SIGNAL_KIND
from schemas.plant_config import PlantConfig
from schemas.units import UnitError, si_factor
from transforms.ingest.errors import IngestError
from transforms.ingest.samples import TagTable

UNIT_SPELLINGS = {"µm": "um", "μm": "um"}
"""Other spellings recorders write for units of ``schemas.units`` (the micro and the mu sign)."""

FileUnits = dict[str, tuple[str, str]]
"""Tag → (the unit as the file writes it, where: ``column 3`` or ``channel 'group'/'tag'``)."""


def canonical_unit(text: str) -> str:
    """A unit as written in a file → the configuration's spelling (``µm`` → ``um``)."""
    text = text.strip()
    return UNIT_SPELLINGS.get(text, text)


def tags_with_file_units(tags: TagTable, config: PlantConfig, units: FileUnits | None) -> TagTable:
    """The tag table with the SI factors the file's units give (``units`` None: the format states
    no units, the configuration's hold).

    Raises
    ------
    IngestError
        A unit of the file that is not accepted for the signal, one that differs from the
        configuration's, or a tag with a unit in neither.
    """
    missing = [t for t, f in zip(tags.tags, tags.factors) if np.isnan(f)]
    if units is None:
        if missing:
            raise IngestError(f"tag {missing[0]}: the file states no units and the configuration leaves this tag's unit out (give [valves.tags] unit)")
        return tags
    where_in_config = {t.tag: (i, v, s) for i, v in enumerate(config.valves) for s, t in v.tags.items()}
    factors = tags.factors.copy()
    for k, tag in enumerate(tags.tags):
        if tag not in units:
            continue
        text, where = units[tag]
        i, valve, signal = where_in_config[tag]
        configured = valve.tags[signal].unit
        key = f"valves[{i}].tags.{signal}.unit"
        unit = canonical_unit(text)
        if not unit:
            if configured is None:
                raise IngestError(f"{where} (tag {tag}): no unit in the file and none in the configuration ({key})")
            continue
        try:
            factor = si_factor(unit, SIGNAL_KIND[signal], valve.design.x_max_m)
        except UnitError as exc:
            raise IngestError(f"{where} (tag {tag}): {exc} in the file") from None
        if configured is not None and unit != configured:
            raise IngestError(f"{where} (tag {tag}): unit {text.strip()!r} in the file, {configured!r} in the configuration ({key})")
        factors[k] = factor
    return replace(tags, factors=factors)

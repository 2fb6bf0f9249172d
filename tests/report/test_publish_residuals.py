"""The Eq. 9 residual at rest, solved once per design and kept in the warehouse for the next commands."""

from __future__ import annotations

import dataclasses
import json
from datetime import datetime, timezone
from pathlib import Path

import pytest

import flows.report.publish as publish
from flows.common.config import load_plant_config

EXAMPLE = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"
NOW = datetime(2025, 3, 1, tzinfo=timezone.utc)


def test_a_residual_is_solved_once_and_read_back_exactly(tmp_path, monkeypatch):
    config = load_plant_config(EXAMPLE)
    solved = []
    real = publish.expected_residual
    monkeypatch.setattr(publish, "expected_residual", lambda v, e: solved.append(v.id) or real(v, e))
    first = publish.bounds_frame(config, NOW, tmp_path)
    assert solved and first["eq9_expected"].is_not_null().all()
    assert set(json.loads((tmp_path / publish.RESIDUALS_FILE).read_text()).values()) == set(first["eq9_expected"].to_list())
    n = len(solved)
    assert publish.bounds_frame(config, NOW, tmp_path).equals(first)  # read back: the same floats, nothing solved
    assert len(solved) == n
    assert publish.bounds_frame(config, NOW).equals(first) and len(solved) == 2 * n  # no warehouse: solved as before

    # a valve whose cylinder changed is solved again
    v = config.valves[0]
    wider = dataclasses.replace(config, valves=(dataclasses.replace(v, piston_diameter_m=v.piston_diameter_m * 1.1), *config.valves[1:]))
    publish.bounds_frame(wider, NOW, tmp_path)
    assert solved[-1] == v.id and len(solved) == 2 * n + 1


@pytest.mark.parametrize("content", ["", "{not json", "[1, 2]"])
def test_an_unreadable_record_is_solved_again(tmp_path, content):
    config = load_plant_config(EXAMPLE)
    want = publish.bounds_frame(config, NOW)
    (tmp_path / publish.RESIDUALS_FILE).write_text(content)
    assert publish.bounds_frame(config, NOW, tmp_path).equals(want)

"""docs/configuration.md stays true: every key the parser accepts is named there (a key added
without its documentation fails here; a section with a page of its own, `[notify]` in
docs/notify.md, is named on that page, key for key), and every complete example of
docs/configuration_examples.md
parses; the first is the specification's example, `tests/fixtures/plant_example.toml`, key for key."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

import schemas.plant_config as pc
from schemas.fields import SIGNALS

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "configuration.md").read_text()
EXAMPLES_PAGE = (ROOT / "docs" / "configuration_examples.md").read_text()
EXAMPLES = [block for block in re.findall(r"```toml\n(.*?)```", EXAMPLES_PAGE, re.S) if block.startswith("[plant]")]
OWN_PAGES = {"notify": (ROOT / "docs" / "notify.md").read_text()}
"""Sections documented on a page of their own: section → that page's text."""

KEY_SETS = {
    "top level": pc._TOP_KEYS,
    "plant": pc._PLANT_KEYS,
    "export": pc._EXPORT_KEYS,
    "monitor": pc._MONITOR_KEYS,
    "retention": pc._RETENTION_KEYS,
    "valve_types": pc._DESIGN_KEYS,
    "valves": pc._VALVE_KEYS,
    "bounds": set(pc.BOUND_KEYS),
    "tags": set(SIGNALS),
    "tolerances": set(pc._TOLERANCE_KEYS),
}
OWN_KEY_SETS = {"notify": pc._NOTIFY_KEYS, "notify.mail": pc._MAIL_KEYS}


def _named(key: str, text: str) -> bool:
    return any(form in text for form in (f"`{key}`", f"[{key}]", f"[{key}.", f"\n{key} = "))


@pytest.mark.parametrize("table", KEY_SETS)
def test_every_accepted_key_is_documented(table):
    missing = sorted(k for k in KEY_SETS[table] if not _named(k, DOC) and not (k in OWN_PAGES and _named(k, OWN_PAGES[k])))
    assert not missing, f"docs/configuration.md does not name these keys of {table}: {missing}"


@pytest.mark.parametrize("table", OWN_KEY_SETS)
def test_every_key_of_a_section_with_its_own_page_is_documented_there(table):
    page = OWN_PAGES[table.split(".")[0]]
    missing = sorted(k for k in OWN_KEY_SETS[table] if not _named(k, page))
    assert not missing, f"the page of [{table}] does not name these keys: {missing}"


def test_the_notify_page_examples_parse():
    fixture = tomllib.loads((ROOT / "tests" / "fixtures" / "plant_example.toml").read_text())
    blocks = [block for block in re.findall(r"```toml\n(.*?)```", OWN_PAGES["notify"], re.S) if block.startswith("[notify]")]
    assert len(blocks) >= 2
    for block in blocks:
        assert pc.parse_plant_config(fixture | tomllib.loads(block)).notify is not None


def test_the_page_has_an_example_per_export_shape():
    layouts = [tomllib.loads(block)["export"]["layout"] for block in EXAMPLES]
    assert len(EXAMPLES) >= 3 and {"long", "wide"} <= set(layouts)


@pytest.mark.parametrize("i", range(len(EXAMPLES)))
def test_every_example_parses(i):
    config = pc.parse_plant_config(tomllib.loads(EXAMPLES[i]))
    assert config.valves


def test_the_first_example_is_the_specifications():
    fixture = tomllib.loads((ROOT / "tests" / "fixtures" / "plant_example.toml").read_text())
    assert tomllib.loads(EXAMPLES[0]) == fixture

"""Hand-built warehouses for the view tests (:mod:`tests.report.viewdb`)."""

from __future__ import annotations

import pytest

from tests.report.viewdb import Warehouse


@pytest.fixture
def wh() -> Warehouse:
    w = Warehouse()
    yield w
    w.con.close()

"""The remaining life in words (flows/report/remaining.py): two significant figures, "more than"
rounded down so it stays true, every basis worded."""

import pytest

from flows.report.remaining import remaining_text, two_figures


@pytest.mark.parametrize(("hours", "down", "text"), [
    (1_515_459.3, False, "1,500,000"), (482_678.0, False, "480,000"), (6_462.0, False, "6,500"),
    (6_462.0, True, "6,400"), (2_297.4, False, "2,300"), (99.6, False, "100"), (3.44, False, "3.4"), (0.0, False, "0"),
])  # fmt: skip
def test_two_significant_figures(hours, down, text):
    assert two_figures(hours, down=down) == text


def test_every_basis_in_words():
    forecast = {"remaining_basis": "forecast", "remaining_hours": 2297.4, "remaining_hours_low": 1893.0,
                "remaining_hours_high": 2811.0, "remaining_horizon_hours": 6462.0}
    assert remaining_text(forecast) == "2,300 h (95 %: 1,900–2,800 h)"
    assert remaining_text(forecast | {"remaining_hours_high": None}) == "2,300 h (95 %: 1,900 h to beyond the 6,400 h horizon)"
    beyond = {"remaining_basis": "beyond_horizon", "remaining_hours": None, "remaining_horizon_hours": 6462.0}
    assert remaining_text(beyond) == "> 6,400 h (no wear toward a bound within the horizon)"
    assert remaining_text({"remaining_basis": "faulty", "remaining_hours": 0.0}) == "now (faulty)"
    assert remaining_text({"remaining_basis": "worn", "remaining_hours": 0.0}) == "now (worn)"
    assert remaining_text({"remaining_basis": "no_trend"}) == "no significant wear trend"
    assert remaining_text({"remaining_basis": "too_little_data"}) == "unknown (too little data)"

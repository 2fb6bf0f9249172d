"""Step 4a with the nominal characteristic as carrier (transforms.baseline.fit_characteristic):
the baseline follows Eq. 3's curved shape inside and beyond the commissioning points, where a
chord does not."""

from __future__ import annotations

import numpy as np
import pytest

from transforms.baseline import carrier_fit, fit_characteristic
from transforms.characteristic import scaled_shifted

from .test_accuracy import NOMINAL


@pytest.mark.parametrize("edge", ["s1", "s2"])
def test_carrier_shape_inside_and_beyond_the_points(edge):
    nominal = NOMINAL[edge]
    truth = scaled_shifted(nominal, 1.07, 25e-6)  # a valve 7 % more open in α, 25 µm more underlap
    rng = np.random.default_rng(3)
    u = np.sort(rng.uniform(1.04e-3, 1.40e-3, 2000))  # a narrow commissioning window
    a = truth.evaluate(u)
    alpha, x = carrier_fit(u, a, nominal)
    assert alpha == pytest.approx(1.07, rel=1e-6) and x == pytest.approx(25e-6, abs=1e-9)
    shaped = fit_characteristic(u, a, carrier=nominal, extend_m=1.5e-3, grid_step_m=0.05e-3)
    chord = fit_characteristic(u, a)
    far = np.linspace(1.0e-3, 2.9e-3, 40)  # up to 1.5 mm beyond the points
    rel_shaped = np.abs(shaped.evaluate(far) / truth.evaluate(far) - 1)
    rel_chord = np.abs(chord.evaluate(far) / truth.evaluate(far) - 1)
    assert rel_shaped.max() < 2e-4  # the 0.05 mm sampling of a nearly linear curve
    assert rel_chord.max() > 10 * rel_shaped.max()
    assert shaped.u_range[0] <= u.min() - 1.5e-3 + 1e-12 and shaped.u_range[1] >= u.max() + 1.5e-3 - 1e-12


def test_carrier_factor_keeps_the_datas_own_shape():
    """A shape the carrier does not have (a 3 % bump) is still fitted by the knots of c(u)."""
    nominal = NOMINAL["1r"]
    u = np.linspace(1.04e-3, 3.0e-3, 4000)
    bump = 1 + 0.03 * np.exp(-(((u - 2.0e-3) / 0.3e-3) ** 2))
    a = nominal.evaluate(u) * bump
    shaped = fit_characteristic(u, a, carrier=nominal, max_knots=12, points_per_interval=200)
    err = np.abs(shaped.evaluate(u) / a - 1)
    assert err.max() < 0.006  # piecewise-linear c on 12 knots against a 0.6 mm wide bump
    assert np.abs(nominal.evaluate(u) / a - 1).max() > 0.025

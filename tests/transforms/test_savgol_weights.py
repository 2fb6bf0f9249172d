"""transforms.derivatives computes scipy.signal.savgol_coeffs' weights itself (scipy.signal is slow to import)."""

import numpy as np
import pytest
from scipy.signal import savgol_coeffs

from transforms.derivatives import savgol_weights


@pytest.mark.parametrize("window", [5, 11, 21, 51])
@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("deriv", [0, 1, 2, 5])  # 5 > order: zero weights
def test_weights_are_scipys(window, order, deriv):
    ours = savgol_weights(window, order, deriv)
    theirs = savgol_coeffs(window, order, deriv=deriv, delta=1.0, use="dot")
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-12)


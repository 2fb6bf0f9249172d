"""model.student_t gives scipy's Student's t quantiles (``stdtrit``) without importing scipy.special."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import stdtrit

from model.student_t import EXPANSION_MIN_DOF, t_quantile

DOF = np.concatenate([np.arange(1, 1200), np.geomspace(1200, 1e8, 60).round()])


@pytest.mark.parametrize("p", [0.55, 0.8, 0.95, 0.975, 0.995, 0.9995])
def test_quantiles_are_scipys_over_every_small_dof_and_large_ones(p):
    ours = t_quantile(DOF, p)
    np.testing.assert_allclose(ours, stdtrit(DOF, p), rtol=1e-12, atol=0)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 10**7), st.floats(0.5001, 0.99999))
def test_any_dof_and_level(dof, p):
    assert t_quantile(dof, p) == pytest.approx(stdtrit(dof, p), rel=1e-11, abs=0)


def test_closed_forms_of_one_and_two_dof():
    p = np.array([0.6, 0.9, 0.975])
    np.testing.assert_allclose(t_quantile(1, p), np.tan(np.pi * (p - 0.5)), rtol=1e-14)
    np.testing.assert_allclose(t_quantile(2, p), (2 * p - 1) / np.sqrt(2 * p * (1 - p)), rtol=1e-14)


def test_arrays_broadcast_and_no_dof_is_nan():
    dof = np.array([[0, 1], [EXPANSION_MIN_DOF - 1, EXPANSION_MIN_DOF]])
    got = t_quantile(dof, np.array([0.9, 0.975]))
    assert got.shape == (2, 2) and np.isnan(got[0, 0])
    np.testing.assert_allclose(got[1], stdtrit(dof[1], [0.9, 0.975]), rtol=1e-13)
    with pytest.raises(ValueError, match="p must lie in"):
        t_quantile(5, 0.5)

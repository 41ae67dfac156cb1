"""Inverting a cold-to-hot field (fixed-point iteration)."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.errors import FieldError
from hot2cold.io.field import DisplacementField
from hot2cold.pipeline.invert import invert_field


def test_inverse_of_a_nonlinear_field_round_trips():
    rng = np.random.default_rng(5)
    hot = rng.uniform(0, 50, (4000, 3))

    def cold_to_hot(x):                      # a smooth, non-affine field of up to ~1 mm
        return np.column_stack([0.01 * x[:, 1] + 2e-4 * x[:, 2] ** 2, -0.008 * x[:, 0], 3e-4 * x[:, 0] * x[:, 1]])

    field = DisplacementField(hot, cold_to_hot(hot), source="test")
    inverted, info = invert_field(field, tolerance=1e-10)
    cold = hot + inverted.displacements
    # the cold points go back to the hot points under the cold-to-hot field, up to interpolation error
    interior = np.all((hot > 8) & (hot < 42), axis=1)
    back = cold + cold_to_hot(cold)
    assert np.abs(back - hot)[interior].max() < 2e-3
    assert info.converged and info.residual < 1e-9 and info.iterations < 20
    # and d is not simply -u
    assert np.abs(inverted.displacements + field.displacements).max() > 1e-2


def test_affine_field_is_inverted_exactly():
    rng = np.random.default_rng(6)
    hot = rng.uniform(0, 50, (2000, 3))
    a = np.array([[0.004, 0.001, 0.0], [0.0, 0.004, -0.002], [0.001, 0.0, 0.004]])
    field = DisplacementField(hot, hot @ a.T + [0.1, 0.0, -0.2])
    inverted, info = invert_field(field, tolerance=1e-13)
    cold = hot + inverted.displacements
    assert np.abs(cold + cold @ a.T + [0.1, 0.0, -0.2] - hot).max() < 1e-11


def test_a_field_too_large_to_invert_is_refused():
    rng = np.random.default_rng(7)
    hot = rng.uniform(0, 10, (500, 3))
    field = DisplacementField(hot, 3.0 * hot[:, ::-1])            # gradient 3: no fixed point iteration
    with pytest.raises(FieldError, match="invert"):
        invert_field(field)

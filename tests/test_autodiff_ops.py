"""The dual numbers a force term runs through in the refinement: the NumPy operations they carry
exact sensitivities for, and a named error for any other (not NumPy's 'returned NotImplemented')."""

from __future__ import annotations

import numpy as np
import pytest

from pidyn.autodiff import deriv, seed, supported, value

X = np.array([0.3, -0.7, 1.4])


@pytest.mark.parametrize(
    "fn",
    [
        np.arctan,
        np.sinh,
        np.cosh,
        np.tanh,
        np.sin,
        lambda x: np.clip(x, -0.5, 0.5),
        lambda x: 0.0 < x * x,
        lambda x: (
            np.tanh(x @ np.array([[0.5, -1.0], [2.0, 0.1], [0.3, 0.3]]))
            @ np.array([[1.0, 2.0], [-1.0, 0.5]]).T
        ),
        lambda x: np.array([[1.0, 2.0, 3.0], [0.5, -1.0, 0.0]]) @ x,
    ],
)
def test_each_supported_operation_has_the_finite_differences_derivative(fn):
    dual = fn(seed(X, np.eye(3)))
    h = 1e-7
    fd = np.array([(np.asarray(fn(X + h * e), float) - np.asarray(fn(X), float)) / h for e in np.eye(3)]).T
    assert np.allclose(value(dual), fn(X))
    assert np.allclose(deriv(dual, 3), fd, atol=1e-5)


def test_an_operation_without_a_derivative_is_named_with_what_is_supported():
    x = seed(X, np.eye(3))
    with pytest.raises(TypeError, match=r"np\.arcsin has no exact sensitivity.*np\.arctan"):
        np.arcsin(x)
    with pytest.raises(TypeError, match=r"np\.sum"):
        np.sum(x)
    assert "np.clip" in supported() and "np.where" in supported()

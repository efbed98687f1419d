"""Gradients of gridded fields and the Field container."""

import numpy as np
import pytest

import rimcl
from rimcl.core.errors import RimclError
from rimcl.fields.derivatives import central_difference, gradient, spectral_derivative


def test_spectral_derivative_is_exact_on_trigonometric_fields():
    count = 32
    h = 2 * np.pi / count
    x = h * np.arange(count)
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    values = np.sin(3 * x1) * np.cos(2 * x2) + np.sin(5 * x3)
    grad = gradient(values, (h, h, h), method="spectral", periodic=True)
    np.testing.assert_allclose(grad[..., 0], 3 * np.cos(3 * x1) * np.cos(2 * x2), atol=1e-12)
    np.testing.assert_allclose(grad[..., 1], -2 * np.sin(3 * x1) * np.sin(2 * x2), atol=1e-12)
    np.testing.assert_allclose(grad[..., 2], 5 * np.cos(5 * x3), atol=1e-12)


@pytest.mark.parametrize("order", [2, 4, 6])
@pytest.mark.parametrize("periodic", [False, True])
def test_finite_differences_show_their_order(order, periodic):
    """Halving h divides the max error (edges included) by about 2**order."""
    errors = []
    for count in (40, 80):
        if periodic:
            x = 2 * np.pi * np.arange(count) / count
        else:
            x = np.linspace(0.0, 2.0, count)
        h = x[1] - x[0]
        values = np.sin(x) if periodic else np.exp(np.sin(2 * x))
        exact = np.cos(x) if periodic else 2 * np.cos(2 * x) * values
        found = central_difference(values, h, axis=0, order=order, periodic=periodic)
        errors.append(np.max(np.abs(found - exact)))
    rate = np.log2(errors[0] / errors[1])
    assert order - 0.3 <= rate <= order + 0.7


def test_short_axes_get_the_widest_stencil_that_fits():
    values = np.broadcast_to(np.arange(10.0) * 0.5, (2, 3, 10))
    grad = gradient(values, (1.0, 1.0, 1.0))
    np.testing.assert_allclose(grad[..., 0], 0.5)
    np.testing.assert_allclose(grad[..., 1:], 0.0)


def test_spectral_needs_periodic():
    with pytest.raises(RimclError, match="periodic"):
        gradient(np.zeros((8, 8, 8)), (1, 1, 1), method="spectral")


def test_spectral_derivative_drops_the_nyquist_mode():
    values = np.cos(np.pi * np.arange(8))  # the Nyquist mode alone
    np.testing.assert_allclose(spectral_derivative(values, 1.0, axis=0), 0.0, atol=1e-12)


def test_field_keeps_delta_n_in_float32_and_n_ref_in_float64():
    values = 1e-6 * np.random.default_rng(0).standard_normal((6, 7, 8))
    field = rimcl.Field.from_arrays(values, spacing=(0.1, 0.2, 0.3), n_ref=1.000123456789)
    assert field.delta_n.dtype == np.float32 and field.gradient.dtype == np.float32
    assert field.n_ref == 1.000123456789
    assert field.shape == (6, 7, 8) and field.counts.tolist() == [8, 7, 6]
    np.testing.assert_allclose(field.grid_hi, [0.7, 1.2, 1.5])
    assert field.packed.shape == (6, 7, 8, 4)
    np.testing.assert_array_equal(field.packed[..., 0], field.delta_n)


def test_periodic_field_computes_spectral_gradients_and_has_no_walls():
    count = 16
    h = 2 * np.pi / count
    x = h * np.arange(count)
    values = np.broadcast_to(1e-3 * np.sin(x), (count, count, count))
    field = rimcl.Field.from_arrays(values, spacing=(h, h, h), boundary="periodic")
    expected = np.broadcast_to(1e-3 * np.cos(x), field.shape)
    np.testing.assert_allclose(field.gradient[..., 0], expected, atol=1e-9)
    assert np.all(np.isinf(field.box_hi)) and np.all(np.isinf(field.box_lo))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"delta_n": np.zeros((4, 4))}, "shape"),
        ({"delta_n": np.full((4, 4, 4), np.nan)}, "NaN"),
        ({"spacing": (1.0, 0.0, 1.0)}, "positive"),
        ({"gradient": np.zeros((4, 4, 4, 2))}, "gradient must have shape"),
        ({"gradient": np.full((4, 4, 4, 3), np.inf)}, "gradient holds NaN"),
        ({"boundary": "reflect"}, "boundary"),
        ({"n_ref": -1.0}, "n_ref"),
    ],
)
def test_bad_fields_are_refused(kwargs, message):
    arguments = {"delta_n": np.zeros((4, 4, 4)), "spacing": (1.0, 1.0, 1.0), **kwargs}
    with pytest.raises(RimclError, match=message):
        rimcl.Field.from_arrays(**arguments)

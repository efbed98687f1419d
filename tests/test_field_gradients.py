"""Density gradients: spectral exactness on trigonometric fields, finite-difference order."""

import numpy as np
import pytest

from rimcl.fields.derivatives import gradient
from rimcl.fields.field_loading import load_field
from rimcl.fields.field_writer import write_field


def _periodic_grid(counts, lengths):
    """Coordinates x1, x2, x3 ((n3, n2, n1) arrays) of a periodic box and its spacing."""
    spacing = np.array(lengths) / np.array(counts)
    axes = [spacing[k] * np.arange(counts[k]) for k in range(3)]
    x3, x2, x1 = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return (x1, x2, x3), spacing


def _trigonometric(x1, x2, x3, lengths):
    """A trigonometric polynomial on the box and its exact gradient."""
    a, b, c = (2 * np.pi / length for length in lengths)
    value = np.sin(3 * a * x1) * np.cos(2 * b * x2) + 0.5 * np.cos(a * x1 + 4 * c * x3)
    exact = np.stack(
        [
            3 * a * np.cos(3 * a * x1) * np.cos(2 * b * x2) - 0.5 * a * np.sin(a * x1 + 4 * c * x3),
            -2 * b * np.sin(3 * a * x1) * np.sin(2 * b * x2),
            -2 * c * np.sin(a * x1 + 4 * c * x3),
        ],
        axis=-1,
    )
    return value, exact


def test_spectral_gradient_is_exact_on_a_trigonometric_field():
    counts, lengths = (16, 12, 20), (2 * np.pi, 3.0, 5.0)  # unequal, even and anisotropic
    (x1, x2, x3), spacing = _periodic_grid(counts, lengths)
    value, exact = _trigonometric(x1, x2, x3, lengths)
    computed = gradient(value, spacing, method="spectral", periodic=True)
    assert np.max(np.abs(computed - exact)) < 1e-12 * np.max(np.abs(exact))


@pytest.mark.parametrize(("method", "order"), [("fd2", 2), ("fd4", 4), ("fd6", 6)])
@pytest.mark.parametrize("periodic", [True, False])
def test_finite_differences_show_their_order(method, order, periodic):
    lengths = (2 * np.pi, 2 * np.pi, 2 * np.pi)
    errors = []
    for n in (32, 64):
        (x1, x2, x3), spacing = _periodic_grid((n, n, n), lengths)
        value, exact = _trigonometric(x1, x2, x3, lengths)
        computed = gradient(value, spacing, method=method, periodic=periodic)
        errors.append(np.max(np.abs(computed - exact)))
    measured = np.log2(errors[0] / errors[1])
    # non-periodic ends use one-sided stencils of the same width: same order, larger constant
    assert order - 0.3 < measured < order + 0.8, (errors, measured)


def test_load_field_computes_exact_spectral_gradients_for_periodic_files(tmp_path):
    lengths = (2 * np.pi, 2 * np.pi, 2 * np.pi)
    (x1, x2, x3), spacing = _periodic_grid((16, 16, 16), lengths)
    value, exact = _trigonometric(x1, x2, x3, lengths)
    density = 1.05 + 0.05 * value
    path = write_field(tmp_path / "p.h5", density=[density], times=[0.0], origin=(0, 0, 0),
                       spacing=spacing, boundary="periodic")  # fmt: skip
    field = load_field(path, case="C4")
    # float32 storage of ρ ≈ 1 limits the match to ~1e-7 of ρ per node
    np.testing.assert_allclose(field.gradient, 0.334 * 0.05 * exact, atol=0.334 * 2e-6)
    # without a periodic boundary the reader falls back to 4th-order differences
    clamped = write_field(tmp_path / "c.h5", density=[density], times=[0.0], origin=(0, 0, 0),
                          spacing=spacing)  # fmt: skip
    fd4 = load_field(clamped, case="C4").gradient
    stored = np.float32(density).astype(np.float64)
    expected = 0.334 * gradient(stored - stored.mean(), spacing, method="fd4", periodic=False)
    np.testing.assert_allclose(fd4, expected, rtol=1e-6, atol=1e-9)

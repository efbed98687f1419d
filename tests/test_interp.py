"""Interpolation kinds: the B-spline prefilter, kernels against the float64 reference,
the Luneburg focus, texture against trilinear."""

import types

import numpy as np
import pytest
from tracing_fields import luneburg_field, luneburg_rays, oblique_rays, smooth_field

import rimcl
from rimcl.core.device import is_pocl
from rimcl.core.errors import RimclError
from rimcl.optics.reference import sample_field, trace_rays_reference
from rimcl.optics.trace import _texture_image


def _wave(points):
    """A smooth 2π-periodic test function and its gradient, at points (M, 3)."""
    x1, x2, x3 = points[:, 0], points[:, 1], points[:, 2]
    value = np.sin(x1 + 0.3) * np.cos(2 * x2) + 0.5 * np.sin(x3 - x1)
    gradient = np.column_stack(
        [
            np.cos(x1 + 0.3) * np.cos(2 * x2) - 0.5 * np.cos(x3 - x1),
            -2 * np.sin(x1 + 0.3) * np.sin(2 * x2),
            0.5 * np.cos(x3 - x1),
        ]
    )
    return value, gradient


def _wave_field(nodes, periodic):
    """_wave sampled on nodes³ over one period (periodic) or [0, 2π] (clamped)."""
    spacing = 2 * np.pi / nodes if periodic else 2 * np.pi / (nodes - 1)
    x = spacing * np.arange(nodes)
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    points = np.stack([x1, x2, x3], axis=-1).reshape(-1, 3)
    value, gradient = _wave(points)
    return rimcl.Field.from_arrays(
        1e-2 * value.reshape(x1.shape),
        spacing=(spacing,) * 3,
        gradient=1e-2 * gradient.reshape(*x1.shape, 3),
        boundary="periodic" if periodic else "clamp",
    )


def _sampling_errors(field, interp, points):
    n, gradient = sample_field(field, points, interp)
    value, exact_gradient = _wave(points)
    return (
        float(np.max(np.abs(n - 1.0 - 1e-2 * value))),
        float(np.max(np.abs(gradient - 1e-2 * exact_gradient))),
    )


@pytest.mark.parametrize("periodic", [False, True])
def test_bspline_interpolates_the_nodes(periodic):
    field = smooth_field(1e-3, counts=(9, 7, 6), periodic=periodic)
    n1, n2, n3 = field.counts
    i3, i2, i1 = np.meshgrid(np.arange(n3), np.arange(n2), np.arange(n1), indexing="ij")
    nodes = np.stack([i1, i2, i3], axis=-1).reshape(-1, 3) * field.spacing + field.origin
    n, _ = sample_field(field, nodes, "bspline3")
    np.testing.assert_allclose(n - field.n_ref, field.delta_n.ravel(), rtol=0, atol=2e-9)


@pytest.mark.parametrize("periodic", [False, True])
def test_bspline_converges_faster_than_trilinear(periodic):
    """Values 4th order and gradients 3rd order (trilinear: 2nd order, gradients from
    the exact node gradients); the clamped spline keeps its order up to the edges."""
    points = np.random.default_rng(1).uniform(0, 2 * np.pi, (4000, 3))
    errors = {
        interp: [
            _sampling_errors(_wave_field(nodes, periodic), interp, points) for nodes in (32, 64)
        ]
        for interp in ("trilinear", "bspline3")
    }
    (value_32, gradient_32), (value_64, gradient_64) = errors["bspline3"]
    assert value_32 / value_64 > (12 if periodic else 7)
    assert gradient_32 / gradient_64 > 6
    assert value_64 < errors["trilinear"][1][0] / 100
    assert gradient_64 < errors["trilinear"][1][1] / 3


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("interp", ["trilinear", "texture", "bspline3"])
def test_kernel_matches_the_float64_reference(device, has_fp64, interp, periodic):
    if interp == "texture" and not is_pocl(device):
        pytest.skip("GPU texture units quantise the weights (NVIDIA: to 1/256 of a cell)")
    field = smooth_field(3e-2, periodic=periodic)
    high = 2 * np.pi if periodic else 1.0
    origins, directions = oblique_rays(21, 0.2 * high, 0.8 * high, 0.2, seed=2)
    x_end = 0.9 * high
    reference = trace_rays_reference(field, origins, directions, x_end=x_end, interp=interp)
    # texture coordinates are float32 even in f64: ~1e-8 of a cell
    tolerances = {"f32c": 2e-7, "f64": 1e-8 if interp == "texture" else 1e-12}
    for precision in ["f32c", "f64"] if has_fp64 else ["f32c"]:
        result = rimcl.trace_rays(
            field,
            origins,
            directions,
            x_end=x_end,
            interp=interp,
            precision=precision,
            device=device,
        )
        np.testing.assert_array_equal(result.status, reference.status)
        np.testing.assert_array_equal(result.steps, reference.steps)
        assert result.counts["ok"] == len(origins)
        error = np.max(np.abs(result.image_pos - reference.image_pos)) / high
        assert error <= tolerances[precision], (precision, error)
        assert result.config["interp"] == interp


def test_luneburg_focus_bspline3_beats_trilinear(device):
    """Must hold (issue 6): on a Luneburg lens sampled on 64³, bspline3 (f32c) puts
    parallel rays on the focus within 1e-5, at least 10 times better than trilinear."""
    field = luneburg_field(64)
    origins, directions = luneburg_rays(48)
    miss = {}
    for interp in ("trilinear", "bspline3"):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=1.0, interp=interp, precision="f32c", device=device
        )
        assert result.counts["ok"] == len(origins)
        miss[interp] = np.max(np.linalg.norm(result.end_pos - [1.0, 0.0, 0.0], axis=1))
    assert miss["bspline3"] <= 1e-5
    assert miss["trilinear"] >= 10 * miss["bspline3"]


def test_texture_agrees_with_trilinear_on_pocl(device):
    """PoCL filters images in exact float32 (NVIDIA quantises the weights to 1/256)."""
    if not is_pocl(device):
        pytest.skip("exact agreement is a property of PoCL's image filtering")
    field = smooth_field(3e-2, periodic=True, seed=4)
    origins, directions = oblique_rays(40, 1.0, 5.0, 0.4, seed=5)
    results = [
        rimcl.trace_rays(field, origins, directions, x_end=6.0, interp=interp, device=device)
        for interp in ("trilinear", "texture")
    ]
    np.testing.assert_array_equal(results[0].status, results[1].status)
    assert np.max(np.abs(results[0].image_pos - results[1].image_pos)) <= 1e-7 * 2 * np.pi
    np.testing.assert_allclose(results[0].deflection, results[1].deflection, rtol=1e-5, atol=1e-9)


def test_texture_needs_image_support():
    device = types.SimpleNamespace(image_support=False, name="No Images Device")
    with pytest.raises(RimclError, match="image support"):
        _texture_image(smooth_field(1e-3), context=None, device=device)


def test_unknown_interpolation_is_refused(device):
    with pytest.raises(RimclError, match="interp must be one of"):
        rimcl.trace_rays(
            smooth_field(1e-3),
            [[0, 0.5, 0.5]],
            [[1, 0, 0]],
            x_end=1.0,
            interp="cubic",
            device=device,
        )

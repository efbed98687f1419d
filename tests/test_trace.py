"""The tracer against closed-form rays and against its float64 NumPy twin."""

import numpy as np
import pytest

import rimcl
from rimcl.core.errors import RimclError
from rimcl.fields.field import analytic_field
from rimcl.optics.reference import trace_rays_reference
from rimcl.optics.verify import exact_fisheye, exact_grin, exact_linear


def _fan(count, spread, seed=0):
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-spread, spread, size=(count, 2))
    directions = np.column_stack([np.ones(count), np.tan(angles[:, 0]), np.tan(angles[:, 1])])
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def _precisions(device):
    return ["f32c", "f64"] if rimcl.core.device.has_fp64(device) else ["f32c"]


def test_uniform_medium_images_rays_back_to_their_origin(device):
    """~3e4 steps over L = π: f32c keeps r' = r0 to 1e-6 L (plain float32 does not)."""
    field = analytic_field("uniform", n0=1.33)
    rng = np.random.default_rng(3)
    origins = np.column_stack([np.zeros(8), rng.uniform(0, 3, (8, 2))])
    directions = _fan(8, 0.9)
    result = rimcl.trace_rays(
        field, origins, directions, x_end=np.pi, step=1e-4, precision="f32c", device=device
    )
    assert result.counts["ok"] == 8
    assert result.steps.min() > 2.3e4
    assert np.max(np.abs(result.image_pos - origins)) <= 1e-6 * np.pi
    np.testing.assert_allclose(result.deflection, 0.0, atol=1e-7)
    travel = np.pi / directions[:, 0]
    np.testing.assert_allclose(result.path_length, travel, rtol=1e-6)
    np.testing.assert_allclose(result.optical_path, 1.33 * travel, rtol=1e-6)
    np.testing.assert_allclose(result.end_pos[:, 0], np.pi, atol=1e-9)
    drift = rimcl.trace_rays(
        field, origins, directions, x_end=np.pi, step=1e-4, precision="f32", device=device
    )
    assert np.max(np.abs(drift.image_pos - origins)) > 1e-4  # why f32c is the default


@pytest.mark.parametrize(("alpha", "length", "spread"), [(0.5, np.pi, 0.5), (0.01, 100.0, 0.02)])
def test_grin_rod_matches_the_exact_ray(device, alpha, length, spread):
    field = analytic_field("grin", n0=1.5, alpha=alpha)
    rng = np.random.default_rng(5)
    origins = np.column_stack([np.zeros(6), rng.uniform(-0.5, 0.5, 6), np.zeros(6)])
    directions = _fan(6, spread, seed=1)
    exact = exact_grin(field, origins, directions, length)
    for precision in _precisions(device):
        result = rimcl.trace_rays(
            field,
            origins,
            directions,
            x_end=length,
            step=1e-3,
            precision=precision,
            device=device,
        )
        error = np.max(np.linalg.norm(result.end_pos - exact, axis=1))
        assert error <= (1e-9 if precision == "f64" else 1e-6 * length), precision


def test_fisheye_rays_return_to_the_plane_they_started_from(device):
    """Rays from (0, -1) cross x1 = 0 again, in the -x1 direction, at (0, 1)."""
    field = analytic_field("fisheye", n_max=2.0)
    theta = np.linspace(np.pi / 3, 2 * np.pi / 3, 7)
    origins = np.column_stack([np.zeros(7), -np.ones(7), np.zeros(7)])
    directions = np.column_stack([np.sin(theta), np.cos(theta), np.zeros(7)])
    for precision in _precisions(device):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=0.0, step=1e-3, precision=precision, device=device
        )
        assert result.counts["ok"] == 7
        assert np.all(result.end_dir[:, 0] < 0)
        error = np.max(np.linalg.norm(result.end_pos - exact_fisheye(origins), axis=1))
        assert error <= (1e-9 if precision == "f64" else 2e-6), precision


def test_linear_medium_matches_the_exact_ray(device):
    field = analytic_field("linear", n0=1.33, g=0.05)
    rng = np.random.default_rng(9)
    origins = np.column_stack([np.zeros(6), rng.uniform(-1, 1, (6, 2))])
    directions = _fan(6, 0.6, seed=2)
    exact = exact_linear(field, origins, directions, np.pi)
    result = rimcl.trace_rays(field, origins, directions, x_end=np.pi, step=1e-3, device=device)
    assert np.max(np.linalg.norm(result.end_pos - exact, axis=1)) <= 1e-6 * np.pi


def test_fourth_order_convergence(device, has_fp64):
    if not has_fp64:
        pytest.skip("needs cl_khr_fp64")
    field = analytic_field("grin", n0=1.5, alpha=0.5)
    origins = np.array([[0.0, 0.3, 0.0], [0.0, -0.2, 0.1]])
    directions = _fan(2, 0.4, seed=4)
    exact = exact_grin(field, origins, directions, np.pi)
    errors = []
    for step in (0.08, 0.04, 0.02):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=np.pi, step=step, precision="f64", device=device
        )
        errors.append(np.max(np.linalg.norm(result.end_pos - exact, axis=1)))
    assert errors[0] / errors[1] >= 12
    assert errors[1] / errors[2] >= 12


def test_gridded_fisheye_on_the_lens_only_grid(device):
    """512² grid over [-0.05, 1.05] x [-1.05, 1.05], θ0 in [π/3, π/2]."""
    lens = analytic_field("fisheye", n_max=2.0)
    field = lens.on_grid((512, 512, 1), (-0.05, -1.05, 0.0), (1.05, 1.05, 0.0), n_ref=1.0)
    theta = np.linspace(np.pi / 3, np.pi / 2, 6)
    origins = np.column_stack([np.zeros(6), -np.ones(6), np.zeros(6)])
    directions = np.column_stack([np.sin(theta), np.cos(theta), np.zeros(6)])
    result = rimcl.trace_rays(field, origins, directions, x_end=0.0, device=device)
    assert result.counts["ok"] == 6
    assert np.max(np.linalg.norm(result.end_pos - exact_fisheye(origins), axis=1)) <= 1e-5


def smooth_random_field(delta_n, counts=(24, 20, 18), seed=0, periodic=False):
    """A sum of a few random Fourier modes with peak-to-peak amplitude ~ ``delta_n``."""
    rng = np.random.default_rng(seed)
    n1, n2, n3 = counts
    period = 2 * np.pi
    spacing = (
        np.full(3, period / np.array(counts))
        if periodic
        else (np.full(3, 2.0) / (np.array(counts) - 1))
    )
    axes = [spacing[k] * np.arange(counts[k]) for k in range(3)]
    x3, x2, x1 = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    values = np.zeros((n3, n2, n1))
    for _ in range(6):
        k = rng.integers(1, 3, size=3) * (rng.integers(0, 2, size=3) * 2 - 1)
        if not periodic:
            k = k * np.pi / 2
        values += np.cos(k[0] * x1 + k[1] * x2 + k[2] * x3 + rng.uniform(0, 2 * np.pi))
    values *= delta_n / np.ptp(values)
    return rimcl.Field.from_arrays(
        values, spacing=spacing, n_ref=1.333, boundary="periodic" if periodic else "clamp"
    )


@pytest.mark.parametrize("delta_n", [2e-5, 3e-4, 1e-2])
@pytest.mark.parametrize("periodic", [False, True])
def test_f32c_agrees_with_the_float64_twin_on_random_fields(device, delta_n, periodic):
    field = smooth_random_field(delta_n, periodic=periodic, seed=int(delta_n * 1e6))
    rng = np.random.default_rng(11)
    count = 40
    depth = 2.0 if not periodic else 2 * np.pi
    origins = np.column_stack([np.zeros(count), rng.uniform(0.5, 1.5, (count, 2))])
    directions = _fan(count, 0.2 if not periodic else 0.7, seed=12)
    reference = trace_rays_reference(field, origins, directions, x_end=depth)
    result = rimcl.trace_rays(field, origins, directions, x_end=depth, device=device)
    assert result.counts["ok"] == count == reference.counts["ok"]
    assert np.max(np.abs(result.image_pos - reference.image_pos)) <= 2e-6 * depth
    shift = reference.image_pos - origins
    shift_error = np.linalg.norm(result.image_pos - reference.image_pos, axis=1)
    assert np.max(shift_error / np.linalg.norm(shift, axis=1)) <= 1e-3
    np.testing.assert_array_equal(result.steps, reference.steps)
    np.testing.assert_allclose(result.deflection, reference.deflection, rtol=1e-3)
    np.testing.assert_allclose(result.path_length, reference.path_length, rtol=1e-6)
    np.testing.assert_allclose(result.n_metric, reference.n_metric, rtol=1e-3, atol=1e-9)


def test_f64_kernel_is_the_float64_twin(device, has_fp64):
    if not has_fp64:
        pytest.skip("needs cl_khr_fp64")
    field = smooth_random_field(1e-2, seed=3)
    rng = np.random.default_rng(2)
    origins = np.column_stack([np.zeros(20), rng.uniform(0.5, 1.5, (20, 2))])
    directions = _fan(20, 0.3, seed=5)
    reference = trace_rays_reference(field, origins, directions, x_end=2.0)
    result = rimcl.trace_rays(field, origins, directions, x_end=2.0, precision="f64", device=device)
    np.testing.assert_allclose(result.image_pos, reference.image_pos, atol=1e-12)
    np.testing.assert_allclose(result.end_dir, reference.end_dir, atol=1e-12)


def test_n_metric_explains_the_deflection(device):
    """|Δθ| ≈ |N| S for small deflections."""
    field = smooth_random_field(3e-4, seed=8)
    rng = np.random.default_rng(4)
    origins = np.column_stack([np.zeros(30), rng.uniform(0.5, 1.5, (30, 2))])
    result = rimcl.trace_rays(field, origins, _fan(30, 0.3), x_end=2.0, device=device)
    predicted = np.linalg.norm(result.n_metric, axis=1) * result.path_length
    np.testing.assert_allclose(result.deflection, predicted, rtol=2e-3)


def _stratified_field(gradient):
    """n = 1.5 + gradient * x1 on [0, 1] x [-1, 1] x [-1, 1] (clamped)."""
    x1 = np.linspace(0, 1, 41)
    values = np.broadcast_to(gradient * x1, (9, 9, 41))
    return rimcl.Field.from_arrays(
        values, spacing=(1 / 40, 0.25, 0.25), origin=(0, -1, -1), n_ref=1.5
    )


def test_status_codes_are_reported_not_lost(device):
    field = _stratified_field(-0.45)
    grazing = np.deg2rad(75)  # n sin(θ) = 1.45 > n(x1 = 1) = 1.05: total internal reflection
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.9, 0.0], [0.0, 0.0, 0.0]])
    directions = np.array(
        [
            [1.0, 0.0, 0.0],  # straight through
            [np.cos(grazing), np.sin(grazing) * 0.05, np.sin(grazing)],  # turns back
            [0.3, 1.0, 0.0],  # leaves through the x2 = 1 face
            [1.0, 0.0, 0.0],  # runs out of steps
        ]
    )
    result = rimcl.trace_rays(field, origins[:3], directions[:3], x_end=1.0, device=device)
    assert result.status.tolist() == [0, 2, 1]
    assert np.all(np.isnan(result.image_pos[1:]))
    short = rimcl.trace_rays(
        field, origins[3:], directions[3:], x_end=1.0, max_steps=3, device=device
    )
    assert short.status.tolist() == [3]
    assert short.counts == {
        "ok": 0,
        "exit_side": 0,
        "turned_back": 0,
        "max_steps": 1,
        "non_finite": 0,
    }


def test_non_finite_rays_are_flagged(device):
    """A gradient near the float32 limit overflows the ray state: reported, not lost."""
    values = np.zeros((4, 4, 4))
    gradient = np.full((4, 4, 4, 3), 3e38)
    field = rimcl.Field.from_arrays(values, spacing=(1, 1, 1), n_ref=1.33, gradient=gradient)
    result = rimcl.trace_rays(
        field, [[0.0, 1.0, 1.0]], [[1.0, 0.0, 0.0]], x_end=3.0, precision="f32c", device=device
    )
    assert result.status.tolist() == [4]
    assert result.counts["non_finite"] == 1


def test_periodic_rays_wrap_instead_of_leaving(device):
    field = smooth_random_field(1e-3, periodic=True, seed=21)
    origins = np.array([[0.0, 6.0, 6.0]])
    directions = np.array([[1.0, 0.6, 0.6]])
    result = rimcl.trace_rays(field, origins, directions, x_end=2 * np.pi, device=device)
    reference = trace_rays_reference(field, origins, directions, x_end=2 * np.pi)
    assert result.status.tolist() == [0]
    assert result.end_pos[0, 1] > field.grid_hi[1]  # it left the box and kept going
    np.testing.assert_allclose(result.image_pos, reference.image_pos, atol=1e-5)


def test_batches_give_the_same_answer(device):
    field = smooth_random_field(1e-3, seed=2)
    rng = np.random.default_rng(0)
    origins = np.column_stack([np.zeros(23), rng.uniform(0.5, 1.5, (23, 2))])
    directions = _fan(23, 0.3)
    whole = rimcl.trace_rays(field, origins, directions, x_end=2.0, device=device)
    pieces = rimcl.trace_rays(field, origins, directions, x_end=2.0, batch_size=5, device=device)
    np.testing.assert_array_equal(whole.image_pos, pieces.image_pos)
    np.testing.assert_array_equal(whole.status, pieces.status)


@pytest.mark.parametrize(
    ("origins", "directions", "message"),
    [
        (np.zeros((0, 3)), np.zeros((0, 3)), "empty"),
        (np.zeros((2, 2)), np.zeros((2, 2)), "shape"),
        (np.zeros((1, 3)), np.zeros((1, 3)), "zero vector"),
        ([[0.0, np.nan, 0.0]], [[1.0, 0.0, 0.0]], "NaN"),
    ],
)
def test_bad_rays_are_refused(device, origins, directions, message):
    with pytest.raises(RimclError, match=message):
        rimcl.trace_rays(analytic_field("uniform"), origins, directions, x_end=1.0, device=device)


def test_a_step_larger_than_the_field_is_refused(device):
    field = _stratified_field(0.0)
    with pytest.raises(RimclError, match="larger than the field"):
        rimcl.trace_rays(field, [[0, 0, 0]], [[1, 0, 0]], x_end=1.0, step=5.0, device=device)


@pytest.mark.parametrize("boundary", ["periodic", "clamp"])
def test_straight_rays_are_what_the_integrator_traces_in_a_uniform_field(device, boundary):
    """rimcl.optics.straight.straight_rays (the reference medium's closed form) against the
    float64 trace: the same status for rays that end well inside, well past the side, or
    move away from the exit plane, and the same exit points and image points."""
    from rimcl.optics.straight import straight_rays

    field = rimcl.Field.from_arrays(
        np.zeros((16, 16, 16), dtype=np.float32), spacing=(0.1, 0.1, 0.1), boundary=boundary
    )
    assert field.is_uniform
    rng = np.random.default_rng(7)
    count = 300
    origins = np.column_stack(
        [np.full(count, 0.05), rng.uniform(0.4, 1.1, count), rng.uniform(0.4, 1.1, count)]
    )
    x_end = 1.2
    targets = np.column_stack(
        [np.full(count, x_end), rng.uniform(0.3, 1.2, count), rng.uniform(0.3, 1.2, count)]
    )
    targets[:100, 1] += 3.0  # far past the side of a clamped box, long before the plane
    directions = targets - origins
    directions[-50:, 0] *= -1  # away from the exit plane
    traced = rimcl.trace_rays(
        field, origins, directions, x_end=x_end, precision="f64", device=device
    )
    straight = straight_rays(field, origins, directions, x_end=x_end)
    np.testing.assert_array_equal(straight.status, traced.status)
    expected = {"periodic": [250, 0, 50], "clamp": [150, 100, 50]}[boundary]
    assert [int(np.sum(straight.status == k)) for k in range(3)] == expected
    ok = traced.ok
    np.testing.assert_allclose(straight.end_pos[ok], traced.end_pos[ok], rtol=0, atol=1e-12)
    np.testing.assert_allclose(straight.image_pos[ok], traced.image_pos[ok], rtol=0, atol=1e-12)
    np.testing.assert_allclose(straight.image_pos[ok], origins[ok], rtol=0, atol=1e-15)
    assert np.all(straight.steps == 0) and np.all(straight.n_metric == 0)
    np.testing.assert_allclose(straight.path_length[ok], traced.path_length[ok], rtol=1e-6)


def test_a_straight_ray_whose_exit_overflows_is_non_finite_never_ok():
    from rimcl.optics.straight import straight_rays
    from rimcl.optics.trace import STATUS_NAMES

    field = rimcl.Field.from_arrays(
        np.zeros((4, 4, 4), dtype=np.float32), spacing=(0.1, 0.1, 0.1), boundary="periodic"
    )
    origins = np.array([[0.0, 1.7e308, 0.0], [0.0, 0.0, 0.0]])
    directions = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    result = straight_rays(field, origins, directions, x_end=1e308)
    assert [STATUS_NAMES[s] for s in result.status] == ["non_finite", "ok"]
    assert np.isnan(result.image_pos[0]).all() and np.isfinite(result.image_pos[1]).all()


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("precision", ["f32", "f32c"])
def test_every_kernel_shape_traces_the_same_bits(device, periodic, precision):
    """Rays side by side in vector lanes (the structure-of-arrays sampler of 8 and 16
    lanes on PoCL, the lane-by-lane one otherwise), in work-groups of any size, are traced
    exactly as one ray per work-item: the same operations in the same order (so the
    shape measured per device never changes results). 37 rays leave some lanes empty;
    rays that leave the box through a side finish while their neighbours keep running."""
    from rimcl.core.device import is_pocl
    from rimcl.optics.shapes import KernelShape

    field = smooth_random_field(3e-3, periodic=periodic, seed=5)
    rng = np.random.default_rng(3)
    count = 37
    depth = 2 * np.pi if periodic else 2.0
    origins = np.column_stack([np.zeros(count), rng.uniform(0.3, 1.7, (count, 2))])
    directions = _fan(count, 0.9, seed=4)
    pocl = is_pocl(device)
    shapes = [KernelShape(lanes, pocl) for lanes in (1, 4, 8, 16)] + [KernelShape(8, False)]
    # a work-group size that leaves a surplus work-item (3 of 16 lanes -> a group of 4)
    shapes.append(KernelShape(16, pocl, group=4))
    results = [
        rimcl.trace_rays(
            field,
            origins,
            directions,
            x_end=depth,
            precision=precision,
            device=device,
            kernel_shape=shape,
        )
        for shape in shapes
    ]
    first = results[0]
    if not periodic:
        assert 0 < first.counts["ok"] < count  # some rays leave through the side
    for shape, result in zip(shapes[1:], results[1:], strict=True):
        for name in ("end_pos", "end_dir", "image_pos", "path_length", "n_metric", "steps"):
            np.testing.assert_array_equal(
                getattr(result, name), getattr(first, name), err_msg=f"{shape} {name}"
            )
        np.testing.assert_array_equal(result.status, first.status, err_msg=str(shape))

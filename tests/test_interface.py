"""The wall between fluid and lens: closed forms for the bare interface and the exit index.

- A window of thickness 0 is the bare fluid/air interface: a ray leaving a uniform fluid of
  index n_f at angle θ_f to x1 leaves the interface at sin θ_o = n_f sin θ_f / n_o and its
  backward extension meets the plane the lens is focused on, L n_o / n_f behind the exit
  plane (the paraxial image of the sheet), at ``y_exit - (L n_o / n_f) tan θ_o``.
- Snell at the wall takes the index at the ray's exit point (``|T|`` of the exit state), not
  the camera's fixed mean index: in a medium layered along x1, ``n sin θ`` is invariant, so
  the ray outside leaves at ``sin θ_o = n(x_sheet) sin θ_0 / n_o`` whatever the index at the
  exit.
"""

import numpy as np
import pytest

import rimcl
from rimcl.optics.camera import FlatWindow, LensCamera, Scene
from rimcl.scene.config import CameraConfig

LENGTH_M = 32.5e-6 * 1024 / (2 * np.pi)


def _lens(window, fluid_index, depth=2 * np.pi):
    scene = Scene(0.0, depth, np.zeros(2), np.full(2, 2 * np.pi), False)
    return LensCamera(
        scene,
        LENGTH_M,
        magnification=0.2,
        f_number=8.0,
        pixels=(1024, 1024),
        fluid_index=fluid_index,
        window=window,
        rays=64,
    )


def test_a_zero_thickness_window_is_the_bare_interface():
    n_f, n_o, depth = 1.335, 1.0, 2 * np.pi
    camera = _lens(FlatWindow(0.0, 1.52, n_o), n_f, depth)
    # the focus: the paraxial image of the sheet, 0.251 L beyond it in water
    assert camera.focus_x1 == pytest.approx(depth * (1 - n_o / n_f), rel=1e-15)
    assert camera.focus_x1 / depth == pytest.approx(0.2509, abs=1e-4)
    theta = np.linspace(-0.3, 0.3, 13)  # in the x1-x2 plane
    start = 1.7
    exits = np.column_stack([np.full_like(theta, depth), start + depth * np.tan(theta), 0 * theta])
    directions = np.column_stack([np.cos(theta), np.sin(theta), 0 * theta])
    outside = np.arcsin(n_f * np.sin(theta) / n_o)
    expected = exits[:, 1] - depth * n_o / n_f * np.tan(outside)
    images = camera.image_points(exits, directions)
    np.testing.assert_allclose(images[:, 0], expected, rtol=0, atol=1e-9 * depth)
    np.testing.assert_array_equal(images[:, 1], 0.0)
    # the glass index drops out of a wall of no thickness
    other = _lens(FlatWindow(0.0, 1.9, n_o), n_f, depth).image_points(exits, directions)
    np.testing.assert_allclose(other, images, rtol=0, atol=1e-12 * depth)
    # and the paraxial ray images onto its tracer
    assert images[len(theta) // 2, 0] == pytest.approx(start, abs=1e-12)


def test_the_scene_lens_always_has_the_interface():
    scene = Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), False)
    config = CameraConfig(kind="lens", length_m=LENGTH_M, magnification=0.2, pupil_rays=16)
    camera = config.build(scene, medium_index=1.335)
    assert camera.window is not None and camera.window.thickness_mm == 0.0
    assert camera.fluid_index == 1.335
    assert camera.focus_x1 == pytest.approx(2 * np.pi * (1 - 1 / 1.335))
    # a given fluid index wins over the case's mean index
    fixed = CameraConfig(kind="lens", length_m=LENGTH_M, magnification=0.2, fluid_index=1.2)
    assert fixed.build(scene, medium_index=1.335).fluid_index == 1.2


def _layered(n_sheet, slope, depth=1.0, nodes=9):
    """n = n_sheet + slope x1 on [0, depth]³ (trilinear interpolation is exact)."""
    x1 = np.linspace(0.0, depth, nodes)
    delta = np.broadcast_to(slope * x1, (nodes, nodes, nodes)).copy()
    gradient = np.zeros((nodes, nodes, nodes, 3))
    gradient[..., 0] = slope
    return rimcl.Field.from_arrays(
        delta, spacing=(depth / (nodes - 1),) * 3, n_ref=n_sheet, gradient=gradient
    )


@pytest.mark.parametrize("thickness_mm", [0.0, 2.0])
def test_snell_at_the_wall_takes_the_index_at_the_exit(thickness_mm):
    n_sheet, slope, n_o = 1.30, 0.05, 1.0  # n = 1.30 at the sheet, 1.35 at the exit
    field = _layered(n_sheet, slope)
    theta = np.linspace(-0.25, 0.25, 7)
    origins = np.column_stack([np.zeros_like(theta), np.full_like(theta, 0.5), np.full(7, 0.5)])
    directions = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    result = rimcl.trace_rays(
        field, origins, directions, x_end=1.0, step=1e-3, precision="f64", interp="trilinear"
    )
    assert (result.status == 0).all()
    np.testing.assert_allclose(result.exit_index, n_sheet + slope, rtol=0, atol=1e-9)
    # the camera's mean index (1.325) is not the exit index (1.35)
    camera = _lens(FlatWindow(thickness_mm, 1.52, n_o), n_sheet + slope / 2, depth=1.0)
    _, out = camera.through_window(result.end_pos, result.end_dir, result.exit_index)
    np.testing.assert_allclose(out[:, 1], n_sheet * np.sin(theta) / n_o, rtol=0, atol=1e-9)
    _, fixed = camera.through_window(result.end_pos, result.end_dir)
    assert np.max(np.abs(fixed[:, 1] - n_sheet * np.sin(theta) / n_o)) > 1e-3

"""Scene, tracers and ray fans (plane and pupil cameras)."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.optics.camera import PlaneCamera, PupilCamera, Scene, seed_tracers


def _scene(boundary="clamp"):
    # 9 x 5 x 7 nodes along x1, x2, x3 (array shape (n3, n2, n1))
    return Scene.from_grid((0.5, -1.0, 2.0), (0.25, 0.5, 0.5), (7, 5, 9), boundary)


def test_scene_defaults_of_a_clamped_grid():
    scene = _scene()
    assert scene.x_sheet == 0.5 and scene.x_end == pytest.approx(2.5)
    np.testing.assert_allclose(scene.fov_lo, [-1.0, 2.0])
    np.testing.assert_allclose(scene.fov_hi, [1.0, 5.0])
    assert scene.depth == pytest.approx(2.0)


def test_scene_defaults_of_a_periodic_box_span_full_periods():
    scene = _scene("periodic")
    assert scene.depth == pytest.approx(9 * 0.25)
    np.testing.assert_allclose(scene.fov_hi - scene.fov_lo, [2.5, 3.5])


@pytest.mark.parametrize(
    ("kw", "match"),
    [({"x_sheet": 3.0}, "sheet"), ({"depth": -1.0}, "depth"), ({"depth": 5.0}, "beyond")],
)
def test_bad_scene_rejected(kw, match):
    with pytest.raises(RimclError, match=match):
        Scene.from_grid((0.5, -1.0, 2.0), (0.25, 0.5, 0.5), (7, 5, 9), "clamp", **kw)


def test_tracers_are_seeded_inside_the_margin_and_reproducible():
    scene = _scene()
    first = seed_tracers(500, scene, np.random.default_rng(7), margin=0.1)
    again = seed_tracers(500, scene, np.random.default_rng(7), margin=0.1)
    np.testing.assert_array_equal(first, again)
    lo = scene.fov_lo + 0.1 * scene.fov_size
    hi = scene.fov_hi - 0.1 * scene.fov_size
    assert np.all(first >= lo) and np.all(first <= hi)
    # uniform: each half of the band holds about half the tracers
    assert abs(np.mean(first[:, 0] < scene.fov_centre[0]) - 0.5) < 0.1


@pytest.mark.parametrize(("count", "margin"), [(0, 0.05), (10, 0.5)])
def test_bad_tracer_requests_rejected(count, margin):
    with pytest.raises(RimclError):
        seed_tracers(count, _scene(), np.random.default_rng(0), margin=margin)


def test_plane_fan_aims_at_cell_centres_of_the_exit_plane():
    scene = _scene()
    camera = PlaneCamera(scene, fan=4)
    tracers = np.array([[0.1, 3.3], [-0.8, 4.9]])
    directions = camera.directions(tracers)
    assert directions.shape == (2, 16, 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=-1), 1.0)
    # straight lines from each tracer along its directions reach the aim points at x_end
    starts = scene.in_sheet(tracers)[:, None, :]
    reach = starts + (scene.depth / directions[..., :1]) * directions
    np.testing.assert_allclose(reach, np.broadcast_to(camera.aim_points(), reach.shape))
    aims = camera.aim_points()
    np.testing.assert_allclose(np.unique(aims[:, 1]), [-0.75, -0.25, 0.25, 0.75])
    np.testing.assert_allclose(np.unique(aims[:, 2]), [2.375, 3.125, 3.875, 4.625])
    assert camera.collected(np.zeros((16, 3)), directions[0]).all()


def _pupil(**kw):
    settings = {"diameter": 0.4, "distance": 6.0, "view_angle": 20.0, "rays": 2000, **kw}
    return PupilCamera(_scene(), **settings)


def test_pupil_points_fill_the_aperture_uniformly():
    camera = _pupil()
    points = camera.aim_points()
    offsets = points - camera.centre
    np.testing.assert_allclose(offsets @ camera.axis, 0.0, atol=1e-12)  # in the pupil plane
    radius = np.linalg.norm(offsets, axis=1)
    assert radius.max() < 0.2
    # area-uniform: the inner disk of half the area holds half the points
    assert np.mean(radius < 0.2 / np.sqrt(2)) == pytest.approx(0.5, abs=0.01)
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=2e-3)


def test_pupil_geometry_centre_and_axis():
    camera = _pupil(view_angle=30.0)
    np.testing.assert_allclose(camera.axis, [np.cos(np.pi / 6), 0.5, 0.0])
    expected = np.array([0.5, 0.0, 3.5]) + 6.0 * camera.axis
    np.testing.assert_allclose(camera.centre, expected)


def test_pupil_collects_straight_rays_and_vignettes_tilted_ones():
    camera = _pupil()
    scene = camera.scene
    tracers = np.array([[0.2, 3.1], [-0.6, 4.2]])
    directions = camera.directions(tracers).reshape(-1, 3)
    starts = np.repeat(scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
    exits = starts + (scene.depth / directions[:, :1]) * directions
    assert camera.collected(exits, directions).all()
    # tilted by ~0.2 rad: over the ~4 units from the exit plane, twice the pupil's size
    tilted = directions + np.array([0.0, 0.0, 0.2])
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    assert not camera.collected(exits, tilted).any()
    backwards = camera.collected(exits[:1], -directions[:1])
    failed = camera.collected(np.full((1, 3), np.nan), np.full((1, 3), np.nan))
    assert not backwards[0] and not failed[0]


def test_pupil_from_focal_length_and_f_number():
    camera = PupilCamera.from_optics(_scene(), 6.0, focal_length=0.8, f_number=4.0)
    assert camera.diameter == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"distance": 1.0}, "beyond the exit plane"),
        ({"diameter": 0.0}, "diameter"),
        ({"view_angle": 90.0}, "view angle"),
        ({"rays": 0}, "at least 1 ray"),
    ],
)
def test_bad_pupil_rejected(kw, match):
    with pytest.raises(RimclError, match=match):
        _pupil(**kw)


def test_pupil_optics_need_diameter_or_focal_length_and_f_number():
    with pytest.raises(RimclError, match="focal-length"):
        PupilCamera.from_optics(_scene(), 6.0, focal_length=0.8)
    with pytest.raises(RimclError, match="not both"):
        PupilCamera.from_optics(_scene(), 6.0, diameter=0.3, f_number=2.0)


@pytest.mark.parametrize("kind", ["plane", "pupil"])
def test_uniform_medium_images_every_ray_to_its_tracer(device, kind):
    import rimcl

    scene = _scene()
    # viewed straight on, the pupil's rays stay inside the (clamped) field
    camera = PlaneCamera(scene, fan=8) if kind == "plane" else _pupil(rays=64, view_angle=0.0)
    tracers = seed_tracers(5, scene, np.random.default_rng(2))
    shape = (7, 5, 9)
    field = rimcl.Field.from_arrays(
        np.zeros(shape), spacing=(0.25, 0.5, 0.5), origin=(0.5, -1.0, 2.0), n_ref=1.33
    )
    starts = np.repeat(scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
    result = rimcl.trace_rays(
        field,
        starts,
        camera.directions(tracers).reshape(-1, 3),
        x_end=scene.x_end,
        device=device,
    )
    assert (result.status == 0).all()
    np.testing.assert_allclose(result.image_pos, starts, atol=1e-9)
    assert camera.collected(result.end_pos, result.end_dir).all()


@pytest.mark.parametrize("kind", ["plane", "pupil", "lens", "lens behind a window"])
def test_directions_of_single_rays_equal_the_full_fan_bit_for_bit(kind):
    """camera.directions(tracers, aim_index): the ray sample's directions, made per ray."""
    from rimcl.optics.camera import FlatWindow, LensCamera

    scene = Scene.from_grid((0, 0, 0), (0.1, 0.1, 0.1), (64, 64, 64), "clamp", x_sheet=3.2)
    if kind == "plane":
        camera = PlaneCamera(scene, 9)
    elif kind == "pupil":
        camera = PupilCamera(scene, 2.0, 20.0, view_angle=12.0, rays=70)
    else:
        window = FlatWindow(5.0) if "window" in kind else None
        camera = LensCamera(scene, 0.01, magnification=0.2, window=window, rays=70)
    rng = np.random.default_rng(4)
    tracers = rng.uniform(0.5, 5.9, size=(40, 2))
    aim_index = rng.integers(0, camera.rays_per_tracer, size=40)
    every = camera.directions(tracers)
    np.testing.assert_array_equal(
        camera.directions(tracers, aim_index), every[np.arange(40), aim_index]
    )


def test_lane_order_groups_nearby_aim_points():
    """The device engine's fan kernel gives rays to lanes in lane_order: a permutation of
    the aim points whose aligned groups of 16 are 4 x 4 blocks of a plane camera's grid,
    and compact clusters of a pupil's spiral (whose consecutive points lie far apart)."""
    from rimcl.imaging.engine import lane_order

    plane = PlaneCamera(_scene(), fan=8)
    order = lane_order(plane)
    assert order.dtype == np.int32
    np.testing.assert_array_equal(np.sort(order), np.arange(64))
    for group in order.reshape(-1, 16):
        columns, rows = group % 8, group // 8
        assert np.ptp(columns) == 3 and np.ptp(rows) == 3 and columns.min() % 4 == 0

    pupil = _pupil(rays=2048)
    order = lane_order(pupil)
    np.testing.assert_array_equal(np.sort(order), np.arange(2048))
    points = pupil.aim_points()

    def mean_spread(indices):
        groups = points[indices].reshape(-1, 16, 3)
        return np.mean(np.linalg.norm(np.ptp(groups, axis=1), axis=-1))

    assert mean_spread(order) < 0.25 * mean_spread(np.arange(2048))

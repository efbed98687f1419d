"""The lens camera in physical units (rimcl.optics.camera.LensCamera) against closed forms."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.optics.camera import FlatWindow, LensCamera, PupilCamera, Scene

# a 2π box seen whole by a 2048-px sensor of 6.5 µm pitch at M = 0.2: 66.6 mm on the sheet
LENGTH_M = 2048 * 6.5e-6 / 0.2 / (2 * np.pi)


def _scene():
    return Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), True)


def _camera(**kw):
    settings = {"length_m": LENGTH_M, "magnification": 0.2, "f_number": 8.0, "rays": 256, **kw}
    return LensCamera(_scene(), **settings)


def test_optics_closed_forms():
    camera = _camera()  # 50 mm f/8, 6.5 µm pixels, 532 nm, 10 µm tracers
    assert camera.working_distance_mm == pytest.approx(300.0)  # f (1 + 1/M)
    assert camera.aperture_mm == pytest.approx(6.25)
    assert camera.numerical_aperture == pytest.approx(np.sin(np.arctan(3.125 / 300.0)))
    assert camera.pixel_size * LENGTH_M == pytest.approx(32.5e-6)  # pitch / M, in metres
    np.testing.assert_allclose(camera.sensor_fov, 2 * np.pi)
    assert camera.depth_of_field_mm == pytest.approx(4 * 6.0**2 * 64 * 532e-6)  # 4.90 mm
    assert camera.diffraction_diameter_um == pytest.approx(2.44 * 1.2 * 0.532 * 8)  # 12.46 µm
    assert camera.image_diameter_um == pytest.approx(np.hypot(2.0, 12.461568))
    assert camera.psf_sigma_px == pytest.approx(12.621041 / (4 * 6.5), rel=1e-6)


def test_working_distance_gives_the_magnification():
    by_distance = _camera(magnification=None, working_distance_mm=300.0)
    assert by_distance.magnification == pytest.approx(0.2)
    assert by_distance.pixel_size == pytest.approx(_camera().pixel_size)


def test_without_a_window_it_is_a_pupil_camera():
    camera = _camera()
    pupil = PupilCamera(camera.scene, 6.25e-3 / LENGTH_M, 0.3 / LENGTH_M, view_angle=0.0, rays=256)
    tracers = np.array([[1.0, 2.0], [3.0, 5.5]])
    np.testing.assert_allclose(camera.directions(tracers), pupil.directions(tracers), atol=1e-14)
    directions = camera.directions(tracers).reshape(-1, 3)
    starts = np.repeat(camera.scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
    exits = starts + (camera.scene.depth / directions[:, :1]) * directions
    assert camera.collected(exits, directions).all()
    # the image points are the back-projection onto the sheet, i.e. the tracers
    images = camera.image_points(exits, directions)
    np.testing.assert_allclose(images, starts[:, 1:], atol=1e-12)


def _oblique_rays(angle):
    directions = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    positions = np.zeros((len(angle), 3))
    positions[:, 0] = 2 * np.pi
    return positions, directions


def test_glass_plate_shifts_a_ray_by_the_textbook_displacement():
    # a plate in air (the fluid is air too): the ray leaves parallel, displaced sideways by
    # Δ = t sin θ (1 - cos θ / sqrt(n² - sin² θ))
    window = FlatWindow(thickness_mm=10.0, glass_index=1.5, outside_index=1.0)
    camera = _camera(window=window)
    angle = np.radians([5.0, 20.0, 40.0])
    positions, directions = _oblique_rays(angle)
    out_pos, out_dir = camera.through_window(positions, directions)
    np.testing.assert_allclose(out_dir, directions, atol=1e-15)
    t = 10e-3 / LENGTH_M
    # distance between the incoming line and the outgoing parallel line
    offset = out_pos - positions
    displacement = np.linalg.norm(
        offset - np.sum(offset * directions, axis=1)[:, None] * directions, axis=1
    )
    expected = t * np.sin(angle) * (1 - np.cos(angle) / np.sqrt(1.5**2 - np.sin(angle) ** 2))
    np.testing.assert_allclose(displacement, expected, rtol=1e-12)
    np.testing.assert_allclose(out_pos[:, 0], positions[:, 0] + t)


def test_window_of_equal_indices_leaves_rays_alone():
    window = FlatWindow(thickness_mm=8.0, glass_index=1.33, outside_index=1.33)
    camera = _camera(window=window, fluid_index=1.33)
    assert camera.focus_x1 == pytest.approx(camera.scene.x_sheet, abs=1e-12)
    positions, directions = _oblique_rays(np.radians([0.0, 3.0, 30.0]))
    out_pos, out_dir = camera.through_window(positions, directions)
    np.testing.assert_allclose(out_dir, directions, atol=1e-15)
    np.testing.assert_allclose(
        out_pos, positions + (0.008 / LENGTH_M / directions[:, :1]) * directions
    )
    straight = positions[:, 1:] - (2 * np.pi / directions[:, :1]) * directions[:, 1:]
    np.testing.assert_allclose(camera.image_points(positions, directions), straight, atol=1e-12)


def test_water_to_air_follows_snell_and_reflects_beyond_the_critical_angle():
    window = FlatWindow(thickness_mm=10.0, glass_index=1.52, outside_index=1.0)
    camera = _camera(window=window, fluid_index=1.335)
    angle = np.radians([10.0, 30.0, 60.0])  # critical angle water-air: 48.5°
    positions, directions = _oblique_rays(angle)
    _, out_dir = camera.through_window(positions, directions)
    np.testing.assert_allclose(out_dir[:2, 1], 1.335 * np.sin(angle[:2]), rtol=1e-14)
    assert np.all(np.isnan(out_dir[2])) and not camera.collected(positions, directions)[2]


def _through_uniform_fluid(camera, tracers):
    directions = camera.directions(tracers)
    starts = camera.scene.in_sheet(tracers)[:, None, :]
    exits = starts + (camera.scene.depth / directions[..., :1]) * directions
    return exits.reshape(-1, 3), directions.reshape(-1, 3)


def test_directions_through_a_window_reach_their_pupil_points():
    window = FlatWindow(thickness_mm=10.0, glass_index=1.52, outside_index=1.0)
    camera = _camera(window=window, fluid_index=1.335)
    tracers = np.array([[np.pi, np.pi], [1.0, 5.0]])
    exits, directions = _through_uniform_fluid(camera, tracers)
    positions, outside = camera.through_window(exits, directions)
    run = (camera.pupil.centre[0] - positions[:, 0]) / outside[:, 0]
    hits = (positions + run[:, None] * outside).reshape(2, -1, 3)
    np.testing.assert_allclose(hits, np.broadcast_to(camera.aim_points(), hits.shape), atol=1e-12)
    assert camera.collected(exits, directions).all()


def test_window_aberration_is_symmetric_and_third_order():
    window = FlatWindow(thickness_mm=10.0, glass_index=1.52, outside_index=1.0)
    spread = []
    for f_number in (8.0, 16.0):
        camera = _camera(window=window, fluid_index=1.335, f_number=f_number, rays=1024)
        centre = np.array([[np.pi, np.pi]])  # on the lens axis
        images = camera.image_points(*_through_uniform_fluid(camera, centre))
        # focused on the paraxial image of the sheet: the rays centre on the tracer ...
        np.testing.assert_allclose(images.mean(axis=0), centre[0], atol=1e-8)
        spread.append(np.max(np.linalg.norm(images - centre, axis=1)))
    # ... with a spherical-aberration blur that falls as the cube of the aperture
    assert spread[0] / spread[1] == pytest.approx(8.0, rel=0.05)
    assert spread[0] < 0.01 * _camera().pixel_size


def test_uniform_medium_through_the_tracer(device):
    import rimcl

    window = FlatWindow(thickness_mm=10.0, glass_index=1.52, outside_index=1.0)
    camera = _camera(window=window, fluid_index=1.335, rays=64)
    tracers = np.array([[np.pi, np.pi], [2.0, 4.0]])
    field = rimcl.Field.from_arrays(
        np.zeros((8, 8, 8)),
        spacing=(2 * np.pi / 8,) * 3,
        n_ref=1.335,
        boundary="periodic",
    )
    starts = np.repeat(camera.scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
    directions = camera.directions(tracers).reshape(-1, 3)
    result = rimcl.trace_rays(field, starts, directions, x_end=camera.scene.x_end, device=device)
    assert (result.status == 0).all() and camera.collected(result.end_pos, result.end_dir).all()
    exits, _ = _through_uniform_fluid(camera, tracers)
    expected = camera.image_points(exits, directions)
    traced = camera.image_points(result.end_pos, result.end_dir)
    np.testing.assert_allclose(traced, expected, atol=1e-4 * camera.pixel_size)


def test_describe_names_the_kind_and_the_derived_optics():
    record = _camera(window=FlatWindow(5.0)).describe()
    assert record["camera"] == "lens" and record["window"]["thickness_mm"] == 5.0
    assert record["psf_sigma_px"] == pytest.approx(_camera().psf_sigma_px)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"working_distance_mm": 300.0}, "magnification or a working distance"),
        ({"magnification": None, "working_distance_mm": 40.0}, "exceed the focal length"),
        ({"magnification": 50.0}, "inside the field"),
        ({"f_number": 0.0}, "f_number"),
        ({"length_m": "big"}, "length_m"),
        ({"pixels": (0, 10)}, "1 x 1 pixels"),
        ({"window": FlatWindow(10.0), "magnification": 12.0}, "inside the field or the window"),
    ],
)
def test_bad_lens_camera_rejected(kw, match):
    with pytest.raises(RimclError, match=match):
        _camera(**kw)


def test_aiming_ends_early_with_the_bits_of_every_newton_step():
    """aim_through_layers stops a ray's Newton steps once its iterate repeats (a fixed point
    or a cycle in the last bits): the directions equal, bit for bit, those of all
    NEWTON_STEPS steps run on every ray (the device's fan kernel runs them all)."""
    from rimcl.optics.layers import NEWTON_STEPS, _newton_step, aim_through_layers

    rng = np.random.default_rng(4)
    count = 20000
    lateral = rng.normal(0.0, 3.0, (count, 2))
    lateral[:5] = 0.0  # straight on: reach 0
    depths = np.column_stack([rng.uniform(0, 2, count), np.full(count, 0.1), np.full(count, 40.0)])
    ratios = np.array([1.0, 1.333 / 1.52, 1.333])
    reach = np.linalg.norm(lateral, axis=-1)
    sine = np.minimum(reach / np.sum(depths * ratios, axis=-1), 0.999 / ratios.max())
    history = [sine]
    for _ in range(NEWTON_STEPS):
        history.append(_newton_step(history[-1], reach, depths, ratios))
    # rays still moving in the last bits: the early end must find the cycle's right phase
    assert np.count_nonzero(history[-1] != history[-2]) > count // 10
    unit = np.divide(lateral, reach[:, None], out=np.zeros_like(lateral), where=reach[:, None] > 0)
    expected = np.column_stack([np.sqrt(1.0 - history[-1] ** 2), history[-1][:, None] * unit])
    got = aim_through_layers(lateral, depths, ratios)
    np.testing.assert_array_equal(got, expected)
    # the same rays in a (K, P, 3) layout with shared depths, as a camera's aim gives them
    shaped = aim_through_layers(lateral.reshape(100, 200, 2), depths[0], ratios)
    single = aim_through_layers(lateral, depths[0], ratios)
    np.testing.assert_array_equal(shaped.reshape(-1, 3), single)


def test_ray_aiming_brings_the_bent_chief_ray_to_the_pupil_centre(device):
    """A constant index gradient bends every ray of a tracer by the same angle, more than
    the f/8 pupil's half angle: aimed as through a uniform fluid every ray misses the
    pupil; aimed through the field (rimcl.optics.aiming) the chief ray lands on the pupil
    centre and the whole cone is collected. A uniform field leaves the aim alone."""
    import rimcl
    from rimcl.fields.field import analytic_field
    from rimcl.optics.aiming import aim_origins, chief_misses

    window = FlatWindow(thickness_mm=10.0, glass_index=1.52, outside_index=1.0)
    camera = _camera(window=window, fluid_index=1.335, rays=64)
    tracers = np.array([[np.pi, np.pi], [2.0, 4.0], [5.0, 1.0]])
    box = {"box_lo": (0.0, -40.0, -40.0), "box_hi": (2 * np.pi, 40.0, 40.0)}
    options = {"device": device, "precision": "f64"}
    uniform = rimcl.Field.from_arrays(
        np.zeros((8, 8, 8)), spacing=(2 * np.pi / 8,) * 3, n_ref=1.335, boundary="periodic"
    )
    assert aim_origins(camera, uniform, tracers, options) is tracers
    field = analytic_field("linear", n0=1.335, g=0.02, **box)  # 0.09 rad across the fluid
    radius = 0.5 * camera.pupil.diameter

    def collected(origins):
        starts = np.repeat(camera.scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
        directions = camera.directions(origins).reshape(-1, 3)
        result = rimcl.trace_rays(field, starts, directions, x_end=camera.scene.x_end, **options)
        return camera.collected(result.end_pos, result.end_dir, result.exit_index)

    before = np.hypot(*chief_misses(camera, field, tracers, tracers, options).T)
    assert (before > 3 * radius).all() and not collected(tracers).any()
    origins = aim_origins(camera, field, tracers, options)
    after = np.hypot(*chief_misses(camera, field, tracers, origins, options).T)
    assert (after < 1e-6 * radius).all()
    # the cone fills the pupil but for its rim (the gradient bends its rays a little
    # differently, as the window does)
    share = collected(origins).reshape(len(tracers), -1).mean(axis=1)
    assert (share >= 0.9).all()


def test_aiming_never_loses_a_chief_ray_that_a_scan_of_aims_reaches(device):
    """Through the shipped sample at C4, Newton from the uniform-fluid aim ends pupil radii
    off for some tracers (the field folds the aims: several basins); a brute-force scan of
    aims over ±16 pupil radii (this test's own grid, finer than the aim's) finds a chief
    ray inside the pupil for each. The aim (Newton, scan, Newton) lands at least as near
    the pupil centre as the best of that grid for every tracer, and counts every image."""
    from rimcl.fields.field_reader import FieldFile
    from rimcl.fields.sample import SAMPLE_LENGTH_M, sample_path
    from rimcl.optics.aiming import aim, chief_misses
    from rimcl.scene.config import CameraConfig

    # tracers of the default study (seed 0) where Newton alone failed at C4, frame 0
    tracers = np.array([[0.63466152, 4.94502601], [4.17807813, 4.55977088]])
    with FieldFile(sample_path()) as ff:
        field = ff.field(0, case="C4")
        scene = Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), True)
    config = CameraConfig(kind="lens", length_m=SAMPLE_LENGTH_M, pupil_rays=16)
    camera = config.build(scene, field.n_ref)
    options = {"device": device, "precision": "f64", "interp": "trilinear"}
    radius = 0.5 * camera.pupil.diameter
    newton_only = aim(camera, field, tracers, options, scan=False)
    assert (newton_only.miss > 1.0).all()  # the old aim: both lost
    offsets = radius * np.arange(-16.0, 16.01, 0.5)
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
    rows = np.repeat(tracers, len(grid), axis=0)
    scan = chief_misses(camera, field, rows, rows - np.tile(grid, (len(tracers), 1)), options)
    scan_best = np.nanmin(np.hypot(*scan.T).reshape(len(tracers), -1), axis=1) / radius
    assert (scan_best < 1.0).all()
    aimed = aim(camera, field, tracers, options)
    assert (aimed.miss <= scan_best).all()
    assert (aimed.miss < 1e-3).all()
    landed = np.hypot(*chief_misses(camera, field, tracers, aimed.origins, options).T) / radius
    np.testing.assert_allclose(landed, aimed.miss, rtol=1e-9, atol=1e-12)
    assert (aimed.branches >= 1).all()


def test_aiming_counts_the_separate_aims_that_reach_the_pupil(device):
    """A tracer of the default study at C4 whose chief ray reaches the pupil from separate
    aims (the field images it several times): the aim counts as many images as this
    test's own brute-force scan finds separate regions of aims inside the pupil."""
    from scipy import ndimage

    from rimcl.fields.field_reader import FieldFile
    from rimcl.fields.sample import SAMPLE_LENGTH_M, sample_path
    from rimcl.optics.aiming import aim, chief_misses
    from rimcl.scene.config import CameraConfig

    tracers = np.array([[4.39891037, 1.02442798]])
    with FieldFile(sample_path()) as ff:
        field = ff.field(0, case="C4")
    scene = Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), True)
    # f/8, the lens this tracer was found with: three separate regions of aims reach its
    # pupil (through f/11's smaller pupil the 1-radius scan finds two of three: a region
    # narrower than the scan's spacing can be missed)
    config = CameraConfig(kind="lens", length_m=SAMPLE_LENGTH_M, pupil_rays=16, f_number=8.0)
    camera = config.build(scene, field.n_ref)
    options = {"device": device, "precision": "f64", "interp": "trilinear"}
    radius = 0.5 * camera.pupil.diameter
    offsets = radius * np.arange(-16.0, 16.01, 0.25)
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
    rows = np.repeat(tracers, len(grid), axis=0)
    miss = np.hypot(*chief_misses(camera, field, rows, rows - grid, options).T) / radius
    _, regions = ndimage.label((miss < 1.0).reshape(len(offsets), len(offsets)))
    assert regions >= 2
    assert aim(camera, field, tracers, options).branches[0] == regions

"""PIV frames on the device engine (cl/frame.cl) against the NumPy reference."""

import numpy as np
import pytest

from rimcl.fields.field import Field
from rimcl.imaging.frame_device import DeviceFrames, bin_to_tiles
from rimcl.imaging.mie import MieWeights
from rimcl.imaging.sensor import Sensor
from rimcl.optics.camera import FlatWindow, LensCamera, PupilCamera, Scene
from rimcl.piv.frame_pair import _expose, image_frames
from rimcl.piv.imaging_config import PivImaging, seed_particles, sheet_intensity

TRACE = {"step": None, "interp": "trilinear", "precision": "f32c"}
MIE = MieWeights(
    diameter_um=2.0,
    particle_index=1.59,
    fluid_index=1.33,
    wavelength_nm=532.0,
    sheet_direction=(0.0, 1.0, 0.0),
    polarisation="unpolarised",
)


def _bump_field(x_sheet, depth):
    """A clamped grid with a smooth bump of δn (rays bend and spread)."""
    counts = np.array([6, 10, 10])
    lo, hi = np.array([0.0, -0.1, -0.1]), np.array([x_sheet + depth, 1.1, 1.1])
    spacing = (hi - lo) / (counts - 1)
    x = [lo[a] + spacing[a] * np.arange(counts[a]) for a in range(3)]
    x3, x2, x1 = np.meshgrid(x[2], x[1], x[0], indexing="ij")
    delta_n = 2e-3 * np.exp(-((x2 - 0.5) ** 2 + (x3 - 0.4) ** 2) / 0.05) * x1
    return Field.from_arrays(delta_n, spacing=spacing, origin=lo, n_ref=1.33)


def _lens(scene):
    """A 50 mm f/8 lens at M = 0.5 behind a 5 mm window, 64 x 48 pixels, 16 rays per tracer."""
    return LensCamera(
        scene,
        length_m=0.05,
        focal_length_mm=50.0,
        f_number=8.0,
        magnification=0.5,
        pixel_pitch_um=200.0,
        pixels=(64, 48),
        rays=16,
        fluid_index=1.33,
        window=FlatWindow(thickness_mm=5.0),
    )


@pytest.fixture(scope="module")
def scene_and_tracers():
    scene = Scene(0.05, 1.05, np.zeros(2), np.ones(2), False)
    imaging = PivImaging(pixels=64, sheet_thickness=4 / 64, density=0.04)
    tracers = seed_particles(scene, imaging, np.random.default_rng(5))
    return scene, imaging, tracers, _bump_field(0.05, 1.0)


@pytest.mark.parametrize("mie", [None, MIE], ids=["plain", "mie"])
def test_device_light_matches_numpy_within_ulps(device, scene_and_tracers, mie):
    scene, imaging, tracers, field = scene_and_tracers
    camera = PupilCamera(scene, diameter=0.3, distance=3.0, rays=12)
    renderer = imaging.renderer(scene, camera)
    shape = imaging.frame_shape(scene, camera)
    intensity = sheet_intensity(tracers[:, 0], scene.x_sheet, imaging.thickness(scene))
    options = {**TRACE, "device": device}
    light, optics, collected, totals = _expose(
        field, tracers, intensity, camera, scene, renderer, shape, options, 10**9, mie
    )
    frames = DeviceFrames(camera, scene, renderer, shape, device, mie)
    got, got_optics, got_collected, got_totals = frames.expose(field, tracers, intensity, TRACE)
    again = frames.expose(field, tracers, intensity, TRACE)[0]
    assert np.array_equal(got, again)  # deterministic: the same bits run after run
    assert light.max() > 0 and np.count_nonzero(light) > light.size // 2
    # the same footprints and products in the same order; only ndtr differs (a few ulp
    # of 1), so every pixel within 4 ulp of the frame's brightest
    ulp = np.spacing(light.max())
    assert np.abs(got - light).max() <= 4 * ulp
    assert np.mean(got == light) > 0.1  # many pixels are bit-identical
    assert np.array_equal(got_collected, collected)
    np.testing.assert_allclose(got_optics, optics, rtol=0, atol=1e-14)
    assert np.array_equal(got_totals["status"], totals["status"])
    assert got_totals["vignetted"] == totals["vignetted"] > 0
    assert got_totals["off_frame"] == totals["off_frame"] > 0


def test_lens_behind_a_window_with_noise_gives_the_same_counts(device, scene_and_tracers):
    scene, imaging, tracers, field = scene_and_tracers
    camera = _lens(scene)
    imaging = PivImaging(pixels=64, sheet_thickness=4 * camera.pixel_size, bit_depth=12)
    moved = tracers + np.array([0.0, 0.6, -0.3]) * camera.pixel_size
    positions = np.stack([tracers, moved])
    sensor = Sensor(bit_depth=12, noise=True, background_e=20.0, peak_electrons=2000.0, seed=9)
    made = {
        engine: image_frames(
            (field, field),
            positions,
            scene,
            camera,
            imaging,
            {"device": device},
            engine=engine,
            sensor=sensor,
            mie=MIE,
        )
        for engine in ("numpy", "device")
    }
    numpy_frames, device_frames = made["numpy"], made["device"]
    assert numpy_frames.images.shape == (2, 48, 64)
    assert numpy_frames.images.max() > 100  # tracers above the noise
    # counts differ only where the light is within ulps of a rounding or Poisson boundary
    differ = numpy_frames.images.astype(int) - device_frames.images.astype(int)
    assert np.count_nonzero(differ) <= 2 and np.abs(differ).max() <= 1
    assert numpy_frames.scales == device_frames.scales
    assert numpy_frames.ray_counts == device_frames.ray_counts
    assert numpy_frames.ray_counts["vignetted"] > 0


def test_tracers_are_binned_to_every_tile_their_footprint_reaches():
    # frame 70 x 100 (rows, columns), tiles of 32: 4 x 3 tiles
    boxes = np.array([[0, 0, 0, 0], [30, 40, 35, 40], [-50, -50, -40, -40], [99, 69, 99, 69]])
    start, tracers, tiles_x = bin_to_tiles(boxes, np.array([1, 5, 3, 2]), 2, (70, 100), tile=32)
    assert tiles_x == 4 and len(start) == 4 * 3 + 1
    members = {t: list(tracers[start[t] : start[t + 1]]) for t in range(12)}
    # tracer 0 at pixel (0, 0), footprint [0, 2]²: tile 0 only
    # tracer 1: columns 28-37, rows 38-42: tiles (row 1, columns 0 and 1)
    # tracer 2 lies off the frame; tracer 3 in the last pixel: tile (row 2, column 3)
    assert members[0] == [0] and members[4] == [1] and members[5] == [1]
    assert members[11] == [3]
    assert sum(len(m) for m in members.values()) == 4


def test_lens_rays_are_aimed_through_the_field_in_both_engines(device, scene_and_tracers):
    """A constant index gradient bends every ray by ~0.04 rad, twice the f/8 pupil's half
    angle: aimed as through a uniform fluid no ray of any tracer reaches the lens; aimed
    through the field (rimcl.optics.aiming, tracers at their own depths) every tracer is
    imaged, and both engines make the same frames from the same aim."""
    from rimcl.optics.aiming import aim_origins

    scene, imaging, tracers, _ = scene_and_tracers
    counts = np.array([6, 10, 10])
    lo, hi = np.array([0.0, -0.6, -0.6]), np.array([1.05, 1.6, 1.6])
    spacing = (hi - lo) / (counts - 1)
    x2 = lo[1] + spacing[1] * np.arange(counts[1])
    delta_n = np.broadcast_to(0.05 * x2[None, :, None], (10, 10, 6)).copy()  # (x3, x2, x1)
    field = Field.from_arrays(delta_n, spacing=spacing, origin=lo, n_ref=1.33)
    camera = _lens(scene)
    imaging = PivImaging(pixels=64, sheet_thickness=4 * camera.pixel_size, bit_depth=12)
    inside = tracers[(tracers[:, 1] > 0.2) & (tracers[:, 1] < 0.8)]
    inside = inside[(inside[:, 2] > 0.2) & (inside[:, 2] < 0.8)]
    assert len(inside) >= 20
    renderer = imaging.renderer(scene, camera)
    shape = imaging.frame_shape(scene, camera)
    intensity = sheet_intensity(inside[:, 0], scene.x_sheet, imaging.thickness(scene, camera))
    options = {**TRACE, "device": device}
    unaimed = _expose(
        field, inside, intensity, camera, scene, renderer, shape, options, 10**9, None
    )
    assert unaimed[2].sum() == 0  # every ray misses the pupil
    aim = aim_origins(camera, field, inside, options)
    assert np.abs(aim - inside[:, 1:]).max() > 10 * camera.pixel_size
    aimed = _expose(
        field, inside, intensity, camera, scene, renderer, shape, options, 10**9, None, aim
    )
    assert (aimed[2] >= camera.rays_per_tracer // 2).all()  # most of each cone collected
    made = {
        engine: image_frames(
            (field,), inside[None], scene, camera, imaging, {"device": device}, engine=engine
        )
        for engine in ("numpy", "device")
    }
    assert np.array_equal(made["numpy"].collected, aimed[2][None])
    assert np.array_equal(made["device"].collected, made["numpy"].collected)
    differ = made["numpy"].images.astype(int) - made["device"].images.astype(int)
    assert made["numpy"].images.max() > 100 and np.abs(differ).max() <= 1


def test_uniform_medium_rays_run_straight_in_both_engines(device, scene_and_tracers):
    # the uniform-medium pair: both engines run the rays straight in closed form (no
    # steps), so every collected ray images back onto its own tracer and the frames agree
    scene, imaging, tracers, field = scene_and_tracers
    uniform = Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=field.box_hi - field.box_lo,
        origin=field.box_lo,
        n_ref=1.33,
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
    )
    assert uniform.is_uniform
    camera = PupilCamera(scene, diameter=0.3, distance=3.0, rays=12)
    renderer = imaging.renderer(scene, camera)
    shape = imaging.frame_shape(scene, camera)
    intensity = sheet_intensity(tracers[:, 0], scene.x_sheet, imaging.thickness(scene))
    options = {**TRACE, "device": device}
    light, optics, collected, totals = _expose(
        uniform, tracers, intensity, camera, scene, renderer, shape, options, 10**9, None
    )
    frames = DeviceFrames(camera, scene, renderer, shape, device)
    got, got_optics, got_collected, got_totals = frames.expose(uniform, tracers, intensity, TRACE)
    seen = collected > 0
    assert seen.sum() > len(tracers) // 2
    np.testing.assert_allclose(optics[seen], tracers[seen, 1:], rtol=0, atol=1e-12)
    # the same footprints and products in the same order; ndtr differs by a few ulp of 1
    # (absolute, in the tails too) and a tracer's 12 rays now all land on one point, so
    # those differences add up over its 12 rays (each weighing at most 1) in each pixel
    assert np.abs(got - light).max() <= 4 * camera.rays_per_tracer * np.spacing(1.0)
    assert np.array_equal(got_collected, collected)
    np.testing.assert_allclose(got_optics, optics, rtol=0, atol=1e-14)
    assert np.array_equal(got_totals["status"], totals["status"])

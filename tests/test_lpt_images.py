"""LPT camera images: rendered, digitised and located tracers against closed forms, Mie
weights per camera against miepython at each camera's scattering angle."""

import miepython
import numpy as np
import pytest
from scipy.ndimage import label
from scipy.special import ndtr
from test_lpt import N0, _cameras, _volume

from rimcl.fields.field import Field
from rimcl.imaging.frames import THRESHOLD_VARIANTS
from rimcl.imaging.mie import MieWeights
from rimcl.imaging.sensor import Sensor
from rimcl.lpt.frames import recorded_frame
from rimcl.lpt.images import (
    camera_imaging,
    locate_view,
    ray_light,
    rig_exposure,
)
from rimcl.lpt.views import Tracer, uniform_field, view

SUFFIXES = tuple(suffix for suffix, _ in THRESHOLD_VARIANTS)

ANGLES = (-30.0, -10.0, 10.0, 30.0)


def _uniform():
    base = Field.from_arrays(np.zeros((2, 2, 2), np.float32), spacing=[1.0, 1.0, 1.0], n_ref=N0)
    return uniform_field(base)


def _centre():
    volume = _volume()
    return 0.5 * (volume.seed_lo + volume.seed_hi)


def test_located_centroid_and_frame_equal_the_closed_form():
    """Noiseless 16-bit camera, one ray per tracer: the image is scale × the pixel integrals
    of a Gaussian of the camera's σ, rounded; the centroid is the excess-weighted mean over
    the pixels above threshold. The frame (the TIFF's content) holds the same counts."""
    cameras = _cameras()
    camera = cameras[1]
    field = _uniform()
    points = _centre() + np.array([[0, 0, 0], [0.02, 0.13, -0.07], [-0.05, -0.21, 0.11]])
    sensor = Sensor(bit_depth=16)
    seen = [view(field, c, points, 1, Tracer()) for c in cameras]
    exposure = rig_exposure(cameras, seen, None, sensor, 0.5, 0.05)
    imaging = camera_imaging(camera, 1, exposure, sensor)
    light = ray_light(seen[1])
    found = locate_view(imaging, seen[1], light, exposure.scale, (1, 0, 1))
    whole = recorded_frame(imaging, seen[1], light, exposure.scale, (1, 0, 1), camera.pixels)
    assert whole.shape == (camera.pixels[1], camera.pixels[0]) and whole.dtype == np.uint16
    sigma = camera.psf_sigma_px
    threshold = exposure.thresholds[1]
    # the median tracer (all tracers alike, Mie off) peaks at half full scale when centred
    assert exposure.scale * exposure.unit_peaks[1] == pytest.approx(0.5 * 65535)
    assert threshold == pytest.approx(0.05 * 0.5 * 65535)
    for point, located in zip(seen[1].images[:, 0], found.centroid, strict=True):
        cols = np.arange(int(point[0]) - 8, int(point[0]) + 9)
        rows = np.arange(int(point[1]) - 8, int(point[1]) + 9)
        share_c = ndtr((cols + 0.5 - point[0]) / sigma) - ndtr((cols - 0.5 - point[0]) / sigma)
        share_r = ndtr((rows + 0.5 - point[1]) / sigma) - ndtr((rows - 0.5 - point[1]) / sigma)
        counts = np.clip(np.rint(exposure.scale * np.outer(share_r, share_c)), 0, 65535)
        above = counts > threshold
        assert label(above, structure=np.ones((3, 3)))[1] == 1
        excess = np.where(above, counts - threshold, 0.0)
        expected = [
            np.sum(excess * cols[None, :]) / excess.sum(),
            np.sum(excess * rows[:, None]) / excess.sum(),
        ]
        np.testing.assert_allclose(located, expected, rtol=0, atol=1e-9)
        # pixel locking of the small (σ ≈ 0.6 px) image: the located point is off the ray's
        np.testing.assert_array_less(np.abs(located - point), 0.25)
        frame = whole[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
        np.testing.assert_array_equal(frame, counts.astype(np.uint16))
    np.testing.assert_allclose(found.optics, seen[1].images[:, 0], rtol=0, atol=1e-12)
    assert np.all(found.flags == 0)


def test_recorded_frame_has_noise_everywhere_and_overlaps_add():
    """The frame a noisy sensor records: background and noise on every pixel (mean and
    spread of the empty pixels as the sensor's model gives them), and two tracers at one
    point make an image of twice the light of one."""
    cameras = _cameras()
    camera = cameras[1]
    field = _uniform()
    centre = _centre()
    noisy = Sensor(bit_depth=16, noise=True, read_noise_e=5.0, background_e=400.0)
    seen = [view(field, c, centre[None], 1, Tracer()) for c in cameras]
    exposure = rig_exposure(cameras, seen, None, noisy, 0.5, 0.05)
    imaging = camera_imaging(camera, 1, exposure, noisy)
    one = view(field, camera, centre[None], 1, Tracer())
    frame = recorded_frame(imaging, one, ray_light(one), exposure.scale, (0, 0, 1), camera.pixels)
    point = one.images[0, 0]
    rows, cols = np.mgrid[: frame.shape[0], : frame.shape[1]]
    empty = np.hypot(cols - point[0], rows - point[1]) > 10
    background = frame[empty].astype(float)
    gain = noisy.gain
    # Poisson(400 e-) + 5 e- read noise, in counts of `gain` electrons
    assert background.mean() == pytest.approx(400.0 / gain, rel=0.02)
    assert background.std() == pytest.approx(np.sqrt(400.0 + 25.0) / gain, rel=0.05)
    assert np.all(background > 0)
    # overlapping images add as light does (noiseless sensor: exact up to rounding)
    quiet = camera_imaging(camera, 1, exposure, Sensor(bit_depth=16))
    two = view(field, camera, np.stack([centre, centre]), 1, Tracer())
    single = recorded_frame(quiet, one, ray_light(one), exposure.scale, (0, 0, 1), camera.pixels)
    double = recorded_frame(quiet, two, ray_light(two), exposure.scale, (0, 0, 1), camera.pixels)
    assert double.max() > 1.9 * single.max()
    np.testing.assert_allclose(double.astype(float), 2.0 * single, atol=1.0)


def test_mie_weight_per_camera_is_its_scattering_angle():
    """Light along x2; a camera at angle θ from x1 (in air) sees a tracer at the look-at point
    along the fluid direction (cos θ_f, sin θ_f, 0), n0 sin θ_f = sin θ: the scattering
    cosine is sin θ / n0. Each camera's light is miepython's intensity there."""
    cameras = _cameras()
    mie = MieWeights(10.0, 1.59, N0, 532.0, (0.0, 1.0, 0.0), "unpolarised")
    field = _uniform()
    seen = [view(field, c, _centre()[None], 1, Tracer()) for c in cameras]
    cosines = np.sin(np.radians(ANGLES)) / N0
    parallel, perpendicular = miepython.intensities(
        1.59, 10.0, 0.532, cosines, n_env=N0, norm="wiscombe"
    )
    expected = 0.5 * (parallel + perpendicular)
    light = np.array([ray_light(s, mie)[0, 0] for s in seen])
    np.testing.assert_allclose(light, expected, rtol=1e-6)
    assert len(set(np.round(light / light.max(), 3))) == 4  # the four cameras differ
    sensor = Sensor(bit_depth=16)
    exposure = rig_exposure(cameras, seen, mie, sensor, 0.5, 0.05)
    np.testing.assert_allclose(exposure.median_light, expected, rtol=1e-6)
    # one gain for the rig: the brightest camera's tracer at half scale, the others dimmer;
    # each threshold 5 % of its own camera's tracer peak
    peaks = np.array(exposure.median_light) * np.array(exposure.unit_peaks) * exposure.scale
    assert peaks.max() == pytest.approx(0.5 * 65535)
    np.testing.assert_allclose(exposure.thresholds, 0.05 * peaks)


def test_noise_draws_differ_between_cameras_and_passes():
    cameras = _cameras()
    field = _uniform()
    point = _centre()[None]
    sensor = Sensor(bit_depth=16, noise=True, read_noise_e=20.0, background_e=50.0)
    seen = [view(field, c, point, 1, Tracer()) for c in cameras]
    exposure = rig_exposure(cameras, seen, None, sensor, 0.5, 0.05)
    located = {}
    for key in ((0, 0, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0)):
        imaging = camera_imaging(cameras[0], 0, exposure, sensor)
        found = locate_view(imaging, seen[0], ray_light(seen[0]), exposure.scale, key)
        located[key] = found.centroid[0]
    again = locate_view(
        camera_imaging(cameras[0], 0, exposure, sensor),
        seen[0],
        ray_light(seen[0]),
        exposure.scale,
        (0, 0, 0),
    ).centroid[0]
    np.testing.assert_array_equal(again, located[(0, 0, 0)])  # reproducible
    values = np.array(list(located.values()))
    assert len({tuple(v) for v in values}) == 4  # independent draws
    # shot noise on ~1e4 electrons moves the centroid by a few hundredths of a pixel
    assert np.max(np.abs(values - seen[0].images[0, 0])) < 0.3


def test_ray_count_choice_stops_at_the_first_converged_count():
    """Tracers 12 mm off the focus plane through the uniform fluid: the mirrored pupil
    spiral keeps the rays' mean image point within 0.004 px of the chief ray's (the window
    at 30° makes the blur disc slightly lopsided), so the optics centroid converges at one
    ray; the located centroid changes as the blur disc fills with rays: more are needed."""
    from rimcl.lpt.views import choose_ray_count

    cameras = _cameras()
    field = _uniform()
    points = _centre() + np.array([[0.12, 0.1, 0.05], [-0.12, -0.2, 0.0]])  # ±12 mm deep
    choice = choose_ray_count(field, cameras[0], points, Tracer(), 0.01, 64)
    assert choice["rays"] == 1 and choice["converged"] and len(choice["changes_px"]) == 1
    sensor = Sensor(bit_depth=16)
    seen = [view(field, c, points, 1, Tracer()) for c in cameras]
    exposure = rig_exposure(cameras, seen, None, sensor, 0.5, 0.05)
    imaging = camera_imaging(cameras[0], 0, exposure, sensor)

    def located(v):
        return locate_view(imaging, v, ray_light(v), exposure.scale, (1, 0, 0)).centroid

    choice = choose_ray_count(field, cameras[0], points, Tracer(), 0.01, 64, centroid=located)
    assert choice["rays"] > 1 and choice["changes_px"][0] > 0.01
    assert len(choice["changes_px"]) == choice["counts"].index(choice["rays"]) + 1


def _measured(scene, run, device, engine):
    """One case of ``scene`` on ``engine``: its result and every camera frame."""
    import dataclasses

    from rimcl.lpt.config import LptScene
    from rimcl.lpt.run import run_case

    study = scene.study
    shared = dataclasses.replace(
        study.shared, run=dataclasses.replace(study.shared.run, engine=engine)
    )
    scene = LptScene(dataclasses.replace(study, shared=shared))
    frames = {}

    def keep(case, kind, camera, frame, counts):
        frames[kind, camera.name, frame] = counts.copy()

    return run_case(run, scene, "C3", device, frame_sink=keep), frames


def test_device_and_numpy_engines_measure_alike(lpt_flow, device, tmp_path):
    """run.engine = "device" (the image kernel on the rays' image points) against "numpy":
    C3 through the tiny flow, Mie weights, a noisy sensor, both passes. As for PTV: the
    same ray choice, flags and areas; where a camera's frame is the same on both engines
    the located centroids are the same to the last bit, elsewhere within 1e-3 px (also
    those located at the threshold ×½ and ×2, whose flags are the same); the optics
    centroids within 1e-9 px, the peaks within 1e-12."""
    from rimcl.lpt.config import parse_lpt_scene
    from rimcl.lpt.run import prepare

    scene = parse_lpt_scene(
        {
            "field": {"path": str(lpt_flow)},
            "tracers": {"count": 30},
            "time": {"frames": 5},
            "sensor": {"noise": True},
            "mie": {"enabled": True},
            "rig": {"preset": "stereo"},
            "lpt": {"max_rays": 8, "calibration_grid": [6, 5], "self_calibration": False},
        }
    )
    run = prepare(scene, tmp_path, {})
    try:
        on_device, device_frames = _measured(scene, run, device, "device")
        in_numpy, numpy_frames = _measured(scene, run, device, "numpy")
    finally:
        run.source.close()
    assert on_device["rays"] == in_numpy["rays"]
    assert on_device["rays"][0]["rays"] > 1  # a bundle of rays: blurred, split windows
    same = 0
    for kind in ("meas", "ref"):
        for c, camera in enumerate(on_device["cameras"]):
            for k in range(run.times.size):
                identical = np.array_equal(
                    device_frames[kind, camera.name, k], numpy_frames[kind, camera.name, k]
                )
                same += identical
                for name in (f"centroid_{kind}", *(f"centroid_{kind}_{s}" for s in SUFFIXES)):
                    got, expected = (r[name][k, c] for r in (on_device, in_numpy))
                    if identical:
                        np.testing.assert_array_equal(got, expected, err_msg=name)
                    else:
                        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-3, err_msg=name)
        for name, check in (
            (f"image_flags_{kind}", {"rtol": 0, "atol": 0}),
            *((f"image_flags_{kind}_{s}", {"rtol": 0, "atol": 0}) for s in SUFFIXES),
            (f"optics_{kind}", {"rtol": 0, "atol": 1e-9}),
            (f"peak_{kind}", {"rtol": 1e-12, "atol": 0}),
        ):
            np.testing.assert_allclose(on_device[name], in_numpy[name], **check, err_msg=name)
    assert same > 0
    assert np.isfinite(on_device["centroid_meas"]).any()
    # the noise floor's second exposure of the reference (independent draws, no frames kept):
    # the same flags on both engines, centroids within the tolerance of the frames that differ
    np.testing.assert_array_equal(on_device["image_flags_floor"], in_numpy["image_flags_floor"])
    np.testing.assert_allclose(
        on_device["centroid_floor"], in_numpy["centroid_floor"], rtol=0, atol=1e-3
    )
    found = np.isfinite(in_numpy["centroid_floor"]) & np.isfinite(in_numpy["centroid_ref"])
    assert found.any()
    assert np.any(in_numpy["centroid_floor"][found] != in_numpy["centroid_ref"][found])

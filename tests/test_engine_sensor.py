"""The device engine's sensor noise and per-image scaling against the NumPy engine.

The device draws each pixel's noise with the host's Philox counters and the host's order
of float64 operations (rimcl/imaging/sensor.py). Its exp, log and cos differ from NumPy's in the
last bit for about 1 value in 10 on PoCL, but a count changes only where a value lies
within that bit of a rounding boundary (about 1e-13 per pixel): no count differed in 8.7
million lit pixels (1600 tracers, both passes, both renderers, 10/12/16 bits). So the synthetic
images must be identical (images, flags, areas, centroids); the measurements keep the
fallback of tests/test_engine.py (centroids within 1e-3 px where the frame images differ).
"""

import dataclasses

import numpy as np
import pytest
from test_engine import PIXEL, SAMPLE, _assert_same, _clouds, assert_engines_agree

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import TracerFlag
from rimcl.imaging.device import image_points
from rimcl.imaging.frames import Imaging, image_batch
from rimcl.imaging.render import FrameImage, Renderer
from rimcl.imaging.sensor import FLOOR_PASS, REFERENCE_PASS, Sensor
from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig, SensorConfig

FRAME = 3
FIRST_ID = 1000  # global id of the first tracer (a shard's offset)


def _noisy_imaging(kind, bits, weights="excess", scaling="reference", adc_clips=False):
    renderer = Renderer(kind, PIXEL, (0.0, 0.0), 1.5, 48, bits)
    full_well = 16_000.0
    sensor = Sensor(
        bit_depth=bits,
        noise=True,
        peak_electrons=8000.0,
        read_noise_e=3.0,
        background_e=6.0,  # means <= 16: Poisson inversion; brighter: the rounded normal
        full_well_e=full_well,
        # the ADC clips at half the full well, or the full well fills the ADC range
        gain_e_per_count=full_well / 2 / renderer.full_scale if adc_clips else None,
        seed=(5 << 32) + 77,
    )
    threshold = 40.0 * (2**bits - 1) / 1023 // 1
    return Imaging(renderer, threshold, weights, scaling, sensor)


def _both(imaging, points, usable, flags, scales, device, pass_id):
    """Both engines on the same rays and noise keys: columns and the frame images."""
    noise = (pass_id, FRAME, FIRST_ID + np.arange(len(points)))
    columns, images = [], []
    for engine in (image_batch, image_points):
        canvas = FrameImage(512, 512, imaging.renderer.full_scale)
        extra = {} if engine is image_batch else {"device": device}
        columns.append(
            engine(imaging, points, usable, 1.0, flags, scales, canvas=canvas, noise=noise, **extra)
        )
        images.append(canvas.counts)
    return columns, images


def _squeezed(points):
    """Dimmer (spread x4, below the threshold) and brighter (squeezed, saturating) images."""
    centre = np.nanmean(points, axis=1, keepdims=True)
    squeezed = centre + 0.4 * (points - centre)
    squeezed[1::2] = centre[1::2] + 4.0 * (points[1::2] - centre[1::2])
    return squeezed


@pytest.mark.parametrize("kind", ["exact", "paper"])
@pytest.mark.parametrize(
    ("bits", "weights", "adc_clips"),
    [(10, "excess", False), (12, "grey", True), (16, "excess", False)],
)
def test_noisy_images_match_the_numpy_engine(device, kind, bits, weights, adc_clips):
    points, usable = _clouds(np.random.default_rng(11))
    imaging = _noisy_imaging(kind, bits, weights, adc_clips=adc_clips)
    flags = np.zeros(len(points), dtype=np.int64)
    seen = 0
    scales = None
    for pass_id, pass_points in ((REFERENCE_PASS, points), (FLOOR_PASS, _squeezed(points))):
        (expected, got), images = _both(
            imaging, pass_points, usable, flags, scales, device, pass_id
        )
        differing = np.count_nonzero(images[0] != images[1])
        assert differing == 0, f"{differing} pixels differ"
        _assert_same(expected, got, same_images=True)
        if scales is None:
            # Sensor.scale_for: the reference peak at peak_electrons; the measured pass's
            # scales
            found = np.isfinite(expected["scale"])
            np.testing.assert_allclose(expected["peak"][found], 8000.0, rtol=1e-12)
            scales = expected["scale"]
        seen |= np.bitwise_or.reduce(expected["flags"])
    for flag in ("SATURATED", "BELOW_THRESHOLD", "SPLIT", "NO_RAYS", "RAYS_OUTSIDE_WINDOW"):
        assert seen & TracerFlag[flag], flag


def test_per_image_scaling_matches_the_numpy_engine(device):
    """Every image scaled to its own peak, noiseless and noisy: the measured pass ignores
    the reference's scales and reports its own."""
    points, usable = _clouds(np.random.default_rng(12))
    flags = np.zeros(len(points), dtype=np.int64)
    squeezed = _squeezed(points)
    # (not the twins 4 x apart: their capped window between them holds no light, and the
    # NumPy engine cannot add the NaN counts of an unscalable image to the frame image)
    squeezed[3] = points[3]
    noiseless = Imaging(Renderer("exact", PIXEL, (0.0, 0.0), 1.5, 48, 12), 160.0, "excess")
    for imaging in (
        dataclasses.replace(noiseless, scaling="per_image"),
        _noisy_imaging("paper", 12, scaling="per_image"),
    ):
        scales = np.full(len(points), 123.0)  # ignored
        (expected, got), images = _both(
            imaging, squeezed, usable, flags, scales, device, FLOOR_PASS
        )
        assert np.array_equal(*images)
        _assert_same(expected, got, same_images=True)
        found = np.isfinite(got["peak"])
        target = imaging.sensor.peak_electrons if imaging.sensor.noise else 4095
        np.testing.assert_allclose(got["peak"][found], target, rtol=1e-12)
        assert not np.any(got["scale"] == 123.0)
        # no image is too dim with per-image scaling
        assert not np.any(got["flags"][1::2] & TracerFlag.BELOW_THRESHOLD)


def test_noise_draws_differ_between_passes_and_repeat(device):
    points, usable = _clouds(np.random.default_rng(13))
    imaging = _noisy_imaging("exact", 16)
    flags = np.zeros(len(points), dtype=np.int64)
    ids = FIRST_ID + np.arange(len(points))

    def image(pass_id, frame=FRAME, tracer_ids=ids):
        canvas = FrameImage(512, 512, imaging.renderer.full_scale)
        columns = image_points(
            imaging,
            points,
            usable,
            1.0,
            flags,
            np.full(len(points), 8000.0),
            device=device,
            canvas=canvas,
            noise=(pass_id, frame, tracer_ids),
        )
        return columns, canvas.counts

    measured, measured_image = image(FLOOR_PASS)
    again, again_image = image(FLOOR_PASS)
    np.testing.assert_array_equal(again_image, measured_image)
    for name, values in measured.items():
        np.testing.assert_array_equal(again[name], values, err_msg=name)
    found = (measured["flags"] & int(TracerFlag.NO_RAYS | TracerFlag.BELOW_THRESHOLD)) == 0
    for other in (image(REFERENCE_PASS), image(FLOOR_PASS, FRAME + 1), image(1, 3, ids + 1)):
        columns, counts = other
        lit = (measured_image > 0) | (counts > 0)
        assert np.mean(counts[lit] != measured_image[lit]) > 0.5  # independent draws
        assert np.all(columns["x2"][found] != measured["x2"][found])
    with pytest.raises(RimclError, match="consecutive"):
        image(FLOOR_PASS, tracer_ids=ids[::-1])
    with pytest.raises(RimclError, match="NoiseKey"):
        image_points(imaging, points, usable, 1.0, flags, device=device)


def _sensor_render(engine, case, sensor, k_rho=None, **options):
    config = MeasureConfig.from_options(engine=engine, frame_image=True, **options)
    config = dataclasses.replace(config, sensor=sensor)
    return run_render(None, case=case, k_rho=k_rho, config=config)


NOISY = SensorConfig(
    noise=True, peak_electrons=12_000.0, read_noise_e=3.0, background_e=8.0, seed=(3 << 32) + 5
)


@pytest.mark.parametrize(
    ("case", "sensor", "options"),
    [
        ("C1", NOISY, {"camera": "pupil", "renderer": "paper", "bit_depth": 16}),
        ("C4", NOISY, {"camera": "plane", "renderer": "exact", "bit_depth": 12}),
        (
            "C4",
            dataclasses.replace(NOISY, full_well_e=14_000.0),
            {"camera": "pupil", "renderer": "exact", "scaling": "per_image", "max_window": 24},
        ),
        ("C1", SensorConfig(), {"camera": "plane", "renderer": "paper", "scaling": "per_image"}),
    ],
)
def test_measurement_matches_the_numpy_engine(device, case, sensor, options):
    """The shipped sample through both engines with noise and with per-image scaling."""
    options = {**SAMPLE, "device": device, "frames": 2, **options}
    numpy_result = _sensor_render("numpy", case, sensor, **options)
    device_result = _sensor_render("device", case, sensor, **options)
    assert device_result.config["render"] == numpy_result.config["render"]
    assert_engines_agree(numpy_result, device_result)
    expected = numpy_result.tracers
    # noise: the floor's second exposure of the reference draws independently of the first
    # (both engines alike: assert_engines_agree compares the floor's columns too)
    assert "x2_floor" in device_result.tracers
    both = np.isfinite(expected["x2_ref"]) & np.isfinite(expected["x2_floor"])
    assert both.any()
    moved = expected["x2_ref"][both] != expected["x2_floor"][both]
    assert np.any(moved) if sensor.noise else not np.any(moved)


def test_device_noise_repeats_run_to_run(device):
    options = {**SAMPLE, "device": device, "camera": "plane", "tracers": 6}
    first = _sensor_render("device", None, NOISY, k_rho=0.0, **options)
    again = _sensor_render("device", None, NOISY, k_rho=0.0, **options)
    for name, values in first.tracers.items():
        np.testing.assert_array_equal(again.tracers[name], values, err_msg=name)
    np.testing.assert_array_equal(again.frame_image, first.frame_image)
    # G = 0, a uniform medium: the measured image is the reference exposure (common random
    # numbers), to the bit; the floor's second exposure differs by the sensor's noise alone
    rows = first.tracers
    for kind in ("meas", "floor"):
        found = np.isfinite(rows["x2_ref"]) & np.isfinite(rows[f"x2_{kind}"])
        assert found.any()
        moved = rows["x2_ref"][found] != rows[f"x2_{kind}"][found]
        assert np.all(moved) if kind == "floor" else not np.any(moved)
    np.testing.assert_array_equal(rows["x3_meas"], rows["x3_ref"])
    other = _sensor_render("device", None, dataclasses.replace(NOISY, seed=6), k_rho=0.0, **options)
    assert not np.array_equal(other.frame_image, first.frame_image)

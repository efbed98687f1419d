"""The camera sensor (rimcl.imaging.sensor): counter-based draws, Poisson draws, noise."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import poisson

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import locate
from rimcl.imaging.render import Renderer, quantize, scale_for
from rimcl.imaging.sensor import (
    FLOOR_PASS,
    POISSON_INVERSION_MAX,
    REFERENCE_PASS,
    NoiseKey,
    Sensor,
    philox4x32,
    pixel_uniforms,
    poisson_from_uniforms,
)


@pytest.mark.parametrize(
    ("counter", "key", "expected"),
    # Random123 known-answer vectors (kat_vectors, philox4x32 10 rounds)
    [
        ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
        ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
        (
            (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
            (0xA4093822, 0x299F31D0),
            (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
        ),
    ],
)
def test_philox_known_answers(counter, key, expected):
    assert tuple(int(w) for w in philox4x32(counter, key)) == expected


def test_philox_header_matches_the_host_on_the_opencl_device(device, has_fp64):
    """cl/rimcl_philox.h (the sensor noise of cl/image.cl) draws the host's words."""
    import pyopencl as cl
    import pyopencl.array as cl_array

    from rimcl.core.program import kernel_dir

    source = r"""
    #if HAS_FP64
    #pragma OPENCL EXTENSION cl_khr_fp64 : enable
    #endif
    #include "rimcl_philox.h"
    __kernel void draw(__global uint *out, __global double *uniform, uint column0, uint row,
                       uint tracer, uint stream, uint k0, uint k1) {
        const uint i = get_global_id(0);
        const uint4 words =
            rimcl_philox4x32_10((uint4)(column0 + i, row, tracer, stream), (uint2)(k0, k1));
        vstore4(words, i, out);
    #if HAS_FP64
        const double4 u = (double4)(rimcl_philox_uniform(words.x), rimcl_philox_uniform(words.y),
                                    rimcl_philox_uniform(words.z), rimcl_philox_uniform(words.w));
        vstore4(u, i, uniform);
    #endif
    }"""
    context = cl.Context([device])
    queue = cl.CommandQueue(context)
    options = [f"-I{kernel_dir()}", f"-DHAS_FP64={int(has_fp64)}"]
    kernel = cl.Program(context, source).build(options=options).draw
    width = 257
    out = cl_array.empty(queue, 4 * width, np.uint32)
    uniform = cl_array.zeros(queue, 4 * width, np.float64)

    def draw(count, column0, row, tracer, stream, seed):
        words = (column0, row, tracer, stream, seed & 0xFFFFFFFF, seed >> 32)
        args = [np.uint32(w) for w in words]
        kernel(queue, (count,), None, out.data, uniform.data, *args)
        shape = (count, 4)
        return out.get()[: 4 * count].reshape(shape).T, uniform.get()[: 4 * count].reshape(shape).T

    # Random123's known answers (kat_vectors, philox4x32 10 rounds)
    words, _ = draw(1, 0, 0, 0, 0, 0)
    assert tuple(int(w) for w in words[:, 0]) == (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)
    words, _ = draw(1, *(4 * [0xFFFFFFFF]), (1 << 64) - 1)
    assert tuple(int(w) for w in words[:, 0]) == (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)
    # the sensor's counters: pixels of a row (wrapping at 2^32), tracer, 2 frame + pass
    row, tracer, seed = 9, 42, (7 << 32) + 123
    words, uniforms_on_device = draw(width, 2**32 - 100, row, tracer, 2 * 5 + 1, seed)
    columns = np.arange(-100, width - 100)
    uniforms = pixel_uniforms(seed, NoiseKey(FLOOR_PASS, 5, tracer), row, columns)
    np.testing.assert_array_equal((words + 0.5) * 2.0**-32, uniforms)
    if has_fp64:
        np.testing.assert_array_equal(uniforms_on_device, uniforms)


def test_inversion_is_the_exact_poisson_quantile():
    rng = np.random.default_rng(5)
    mean = rng.uniform(0.0, POISSON_INVERSION_MAX, 5000)
    u0 = rng.random(5000)
    draws = poisson_from_uniforms(mean, u0, rng.random(5000))
    np.testing.assert_array_equal(draws, poisson.ppf(u0, mean))


@pytest.mark.parametrize("mean", [0.3, 4.0, 16.0, 16.5, 300.0])
def test_poisson_mean_and_variance(mean):
    count = 200_000
    u = pixel_uniforms(11, NoiseKey(REFERENCE_PASS, 0, 0), 0, np.arange(count))
    draws = poisson_from_uniforms(np.full(count, mean), u[0], u[1])
    variance = mean + (1 / 12 if mean > POISSON_INVERSION_MAX else 0.0)  # rounded normal
    assert abs(draws.mean() - mean) < 5 * np.sqrt(variance / count)
    assert abs(draws.var() - variance) < 5 * variance * np.sqrt(2 / count) + 5 * np.sqrt(
        mean / count
    )
    assert np.all(draws == np.rint(draws)) and draws.min() >= 0


def _tracer_image(bit_depth=16):
    renderer = Renderer("exact", 1.0, (0.0, 0.0), psf_sigma=2.0, bit_depth=bit_depth)
    pixels = np.array([[40.3, 37.7]])
    window = renderer.window_for(pixels)
    raw, _ = renderer.render(pixels, np.ones(1), window)
    return raw, window


def test_noise_off_is_todays_camera():
    raw, _ = _tracer_image()
    raw = raw * np.random.default_rng(2).uniform(0.5, 1.5, raw.shape)
    for bits in (10, 12, 16):
        sensor = Sensor(bit_depth=bits)  # noise off: the noise settings are unused
        scale = sensor.scale_for(raw)
        assert scale == scale_for(raw, 2**bits - 1)
        counts, saturated = sensor.digitize(raw, 1.3 * scale, 5, -7, NoiseKey(1, 0, 0))
        expected, expected_saturated = quantize(raw, 1.3 * scale, 2**bits - 1)
        assert counts.dtype == expected.dtype and np.array_equal(counts, expected)
        assert saturated == expected_saturated


def test_draws_follow_the_global_pixel_grid():
    sensor = Sensor(bit_depth=12, noise=True, peak_electrons=500.0, background_e=3.0)
    raw, window = _tracer_image()
    scale = sensor.scale_for(raw)
    key = NoiseKey(FLOOR_PASS, 2, 17)
    whole, _ = sensor.digitize(raw, scale, window.row0, window.col0, key)
    again, _ = sensor.digitize(raw, scale, window.row0, window.col0, key)
    np.testing.assert_array_equal(whole, again)  # same key: same image
    part, _ = sensor.digitize(raw[2:, 3:], scale, window.row0 + 2, window.col0 + 3, key)
    np.testing.assert_array_equal(part, whole[2:, 3:])  # same global pixel: same draw


@pytest.mark.parametrize(
    "other",
    [NoiseKey(REFERENCE_PASS, 2, 17), NoiseKey(FLOOR_PASS, 3, 17), NoiseKey(1, 2, 18), None],
)
def test_different_keys_draw_independently(other):
    sensor = Sensor(bit_depth=16, noise=True, peak_electrons=2000.0, full_well_e=1e5, seed=1)
    raw = np.full((64, 64), 1.0)
    scale = 1000.0  # 1000 e⁻ per pixel: residuals are shot noise
    key = NoiseKey(FLOOR_PASS, 2, 17)
    first, _ = sensor.digitize(raw, scale, 0, 0, key)
    if other is None:  # another seed
        second, _ = dataclasses.replace(sensor, seed=2).digitize(raw, scale, 0, 0, key)
    else:
        second, _ = sensor.digitize(raw, scale, 0, 0, other)
    a, b = (first - first.mean()).ravel(), (second - second.mean()).ravel()
    correlation = a @ b / np.sqrt((a @ a) * (b @ b))
    assert abs(correlation) < 4 / np.sqrt(a.size)
    assert first.std() * sensor.gain == pytest.approx(np.sqrt(1000 + 4), rel=0.05)


def test_centroid_scatter_falls_as_one_over_root_electrons():
    raw, window = _tracer_image(bit_depth=16)
    peaks = np.array([100.0, 1000.0, 10_000.0])
    scatter = []
    for peak in peaks:
        # the reference peak at 50000 of 65535 counts: the ADC step stays far below the noise
        sensor = Sensor(
            bit_depth=16,
            noise=True,
            peak_electrons=peak,
            read_noise_e=0.0,
            full_well_e=1e9,
            gain_e_per_count=peak / 50_000,
            seed=3,
        )
        scale = sensor.scale_for(raw)
        positions = []
        for tracer in range(200):
            key = NoiseKey(FLOOR_PASS, 0, tracer)
            counts, saturated = sensor.digitize(raw, scale, window.row0, window.col0, key)
            assert not saturated
            blob = locate(counts, 10_000.0)
            positions.append((blob.col, blob.row))
        scatter.append(np.mean(np.std(positions, axis=0)))
    slope = np.polyfit(np.log10(peaks), np.log10(scatter), 1)[0]
    assert -0.6 < slope < -0.4
    noiseless = Sensor(bit_depth=16)
    counts, _ = noiseless.digitize(raw, noiseless.scale_for(raw), 0, 0, None)
    assert scatter[-1] > 0 and np.max(counts) == 2**16 - 1  # today's camera has no scatter


def test_noisy_sensor_needs_a_key():
    with pytest.raises(RimclError, match="NoiseKey"):
        Sensor(noise=True).digitize(np.ones((2, 2)), 1.0, 0, 0, None)


def test_full_well_and_gain():
    sensor = Sensor(bit_depth=12, noise=True, peak_electrons=30_000.0, read_noise_e=0.0)
    assert sensor.gain == pytest.approx(30_000.0 / 4095)
    raw = np.array([[0.0, 0.5, 1.0, 2.0]])
    counts, saturated = sensor.digitize(raw, 30_000.0, 0, 0, NoiseKey(FLOOR_PASS, 0, 0))
    assert saturated and counts[0, 3] == 4095 and counts[0, 0] == 0
    assert abs(counts[0, 1] - 2048) < 5 * np.sqrt(15_000) / sensor.gain


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"bit_depth": 20}, "8 to 16"),
        ({"peak_electrons": 0.0}, "peak_electrons"),
        ({"read_noise_e": -1.0}, "read_noise_e"),
        ({"gain_e_per_count": 0.0}, "gain_e_per_count"),
        ({"seed": -1}, "seed"),
    ],
)
def test_bad_settings_are_one_clear_error(options, message):
    with pytest.raises(RimclError, match=message):
        Sensor(**options)

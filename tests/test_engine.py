"""The device engine against the NumPy engine: same flags, same centroids.

Where the digitised images of the two engines are identical (compared through the frame
image of all windows), centroids must be identical to the last bit (the device returns
exact integer moments and the host divides as the NumPy engine does); elsewhere within
1e-3 px. Image points cover every path of the imaging: compact and wide clouds, windows
capped around the median with rays lost outside, split images with an exact tie in light,
saturation, images below the threshold, tracers without rays.
"""

import dataclasses

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import TracerFlag
from rimcl.imaging.device import image_points
from rimcl.imaging.frames import THRESHOLD_VARIANTS, Imaging, image_batch
from rimcl.imaging.render import FrameImage, Renderer
from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig, MieConfig

PIXEL = 1 / 512  # pixel size of the synthetic clouds (a unit field of view)
RAYS = 96


def _clouds(rng):
    """Image points ``(B, K, 2)`` (sheet units) and usable masks of one tracer per path."""
    centre = lambda: rng.uniform(0.2, 0.8, size=2)  # noqa: E731
    gauss = lambda width: centre() + width * PIXEL * rng.normal(size=(RAYS, 2))  # noqa: E731
    # two identical clusters 24 px apart on dyadic positions: an exact tie in light
    jitter = rng.integers(-2, 3, size=(RAYS // 2, 2)) * PIXEL / 4
    twin = np.array([200.25, 150.5]) * PIXEL + np.concatenate([jitter, jitter])
    twin[RAYS // 2 :, 0] += 24 * PIXEL
    clouds = [
        gauss(0.3),
        np.repeat(centre()[None], RAYS, axis=0),  # every ray on one point
        gauss(3.0),
        twin,
        gauss(40.0),  # wider than the largest window: capped, rays outside
        centre() + 30 * PIXEL * rng.uniform(-1, 1, size=(RAYS, 2)),
        gauss(1.0),  # no usable ray
        gauss(1.0),  # a third of the rays unusable
        np.floor(gauss(2.0) / PIXEL) * PIXEL,  # on pixel corners (binning at edges)
        gauss(0.05),
    ]
    points = np.stack(clouds)
    usable = np.ones(points.shape[:2], dtype=bool)
    usable[4, 0] = False  # an odd count: the median is a ray's (even counts: the mean of two)
    usable[6] = False
    usable[7, ::3] = False
    return points, usable


def _imaging(kind, bits, weights):
    renderer = Renderer(kind, PIXEL, (0.0, 0.0), 1.5, 48, bits)
    return Imaging(renderer, 40.0 * (2**bits - 1) / 1023 // 1, weights)


def _both(imaging, points, usable, weights, flags, scales, device):
    images = []
    columns = []
    for engine in (image_batch, image_points):
        canvas = FrameImage(512, 512, imaging.renderer.full_scale)
        extra = {} if engine is image_batch else {"device": device}
        columns.append(
            engine(imaging, points, usable, weights, flags, scales, canvas=canvas, **extra)
        )
        images.append(canvas.counts)
    return columns, np.array_equal(*images)


def _assert_same(numpy_columns, device_columns, same_images):
    variants = [suffix for suffix, _ in THRESHOLD_VARIANTS]
    for name in ("flags", *(f"flags_{suffix}" for suffix in variants)):
        assert np.array_equal(numpy_columns[name], device_columns[name]), name
    for name in ("area", "n_rays_ok"):
        assert np.array_equal(numpy_columns[name], device_columns[name]), name
    for name in ("x2", "x3", *(f"{x}_{suffix}" for x in ("x2", "x3") for suffix in variants)):
        expected, got = numpy_columns[name], device_columns[name]
        if same_images:
            np.testing.assert_array_equal(got, expected, err_msg=name)
        else:
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-3 * PIXEL, err_msg=name)
    for name in ("perimeter", "circularity", "peak", "scale"):
        np.testing.assert_allclose(
            device_columns[name], numpy_columns[name], rtol=1e-12, err_msg=name
        )
    for name in ("x2_opt", "x3_opt"):
        np.testing.assert_allclose(
            device_columns[name], numpy_columns[name], rtol=0, atol=1e-9 * PIXEL, err_msg=name
        )


@pytest.mark.parametrize(
    ("kind", "bits", "weights"),
    [
        ("exact", 10, "excess"),
        ("exact", 16, "grey"),
        ("paper", 10, "grey"),
        ("paper", 16, "excess"),
    ],
)
def test_image_points_match_the_numpy_engine(device, kind, bits, weights):
    rng = np.random.default_rng(7)
    points, usable = _clouds(rng)
    imaging = _imaging(kind, bits, weights)
    flags = np.zeros(len(points), dtype=np.int64)
    flags[3] = int(TracerFlag.RAYS_FAILED)  # flags known before imaging are kept
    light = np.tile(rng.uniform(0.5, 1.5, size=RAYS // 2), 2)  # uneven, the same per twin
    (reference, device_reference), same = _both(imaging, points, usable, light, flags, None, device)
    _assert_same(reference, device_reference, same)
    seen = np.bitwise_or.reduce(reference["flags"])
    for flag in ("NO_RAYS", "SPLIT", "TOUCHES_EDGE", "RAYS_OUTSIDE_WINDOW", "RAYS_FAILED"):
        assert seen & TracerFlag[flag], flag
    # the variant thresholds locate the same images again: a found tracer's centroid moves
    # (excess weights) and the doubled threshold loses the faint one only where its peak
    # lies between the two thresholds
    found = np.isfinite(reference["x2"])
    assert np.isfinite(reference["x2_threshold_half"][found]).all()
    peak = reference["peak"]
    doubled = 2 * imaging.threshold
    assert (np.isnan(reference["x2_threshold_double"]) == ~(found & (peak > doubled))).all()
    # the twins tie: the first component in raster order is the tracer's
    assert reference["flags"][3] & TracerFlag.SPLIT
    assert abs(reference["x2"][3] / PIXEL - 200.25) < 1

    # the measured pass: the reference's scales; brighter (saturated) and dimmer images
    centre = np.nanmean(points, axis=1, keepdims=True)
    squeezed = centre + 0.6 * (points - centre)
    squeezed[1::2] = centre[1::2] + 4.0 * (points[1::2] - centre[1::2])
    (measured, device_measured), same = _both(
        imaging, squeezed, usable, light, flags, reference["scale"], device
    )
    _assert_same(measured, device_measured, same)
    seen = np.bitwise_or.reduce(measured["flags"])
    assert seen & TracerFlag.SATURATED
    assert seen & TracerFlag.BELOW_THRESHOLD


def test_image_points_are_deterministic(device):
    points, usable = _clouds(np.random.default_rng(3))
    imaging = _imaging("exact", 12, "excess")
    flags = np.zeros(len(points), dtype=np.int64)
    first = image_points(imaging, points, usable, 1.0, flags, device=device)
    again = image_points(imaging, points, usable, 1.0, flags, device=device)
    for name, values in first.items():
        np.testing.assert_array_equal(again[name], values, err_msg=name)


def test_ray_weights_of_the_wrong_shape_are_refused(device):
    points, usable = _clouds(np.random.default_rng(3))
    imaging = _imaging("exact", 10, "excess")
    with pytest.raises(RimclError, match="ray weights of shape"):
        image_points(imaging, points, usable, np.ones((2, 3)), np.zeros(len(points)), device=device)


def _render(engine, case, mie=None, **options):
    config = MeasureConfig.from_options(engine=engine, frame_image=True, **options)
    if mie is not None:
        config = dataclasses.replace(config, mie=mie)
    return run_render(None, case=case, config=config)


SAMPLE = {"tracers": 10, "fan": 8, "pupil_rays": 64, "pixels": 1024, "psf_sigma": 2.5}


@pytest.mark.parametrize(
    ("case", "options"),
    [
        ("C0", {"camera": "plane", "renderer": "exact", "bit_depth": 10}),
        ("C1", {"camera": "pupil", "renderer": "paper", "bit_depth": 16}),
        ("C2", {"camera": "plane", "renderer": "paper", "centroid_weights": "grey"}),
        ("C2", {"camera": "pupil", "renderer": "exact", "threshold": 33.3, "bit_depth": 12}),
        ("C3", {"camera": "pupil", "renderer": "exact", "bit_depth": 16, "view_angle": 20.0}),
        ("C4", {"camera": "plane", "renderer": "exact", "max_window": 24, "bit_depth": 12}),
        ("C4", {"camera": "pupil", "renderer": "paper", "aperture_diameter": 1.0}),
    ],
)
def test_measurement_matches_the_numpy_engine(device, case, options):
    """The shipped sample through both engines: trace, collection, images, rows, sample."""
    options = {**SAMPLE, "device": device, **options}
    assert_engines_agree(_render("numpy", case, **options), _render("device", case, **options))


@pytest.mark.parametrize(
    ("polarisation", "camera"),
    [
        ("unpolarised", "plane"),
        ("perpendicular", "pupil"),
        ("parallel", "plane"),
        ("linear", "pupil"),
    ],
)
def test_mie_weights_are_made_on_the_device_as_on_the_host(device, polarisation, camera):
    """Mie weights from the fan kernel: the same light, optics means and images."""
    mie = MieConfig(
        enabled=True,
        diameter_um=2.0,
        polarisation=polarisation,
        polarisation_direction=(0.6, 0.0, 0.8),
        sheet_direction=(0.0, 1.0, 0.0),
    )
    options = {**SAMPLE, "device": device, "camera": camera, "bit_depth": 16}
    numpy_result = _render("numpy", "C2", mie=mie, **options)
    device_result = _render("device", "C2", mie=mie, **options)
    assert numpy_result.config["mie"]["polarisation"] == device_result.config["mie"]["polarisation"]
    # the weights matter: the same scene without them images differently
    plain = _render("numpy", "C2", **options)
    assert not np.array_equal(plain.tracers["x2_opt"], numpy_result.tracers["x2_opt"])
    assert_engines_agree(numpy_result, device_result)


def assert_engines_agree(numpy_result, device_result):
    """Same flags, areas and ray samples; centroids identical where the frame images are
    (else within 1e-3 px); every other column within 1e-9 px."""
    pixel = numpy_result.attrs["pixel_size"]
    same_images = np.array_equal(numpy_result.frame_image, device_result.frame_image)
    expected, got = numpy_result.tracers, device_result.tracers
    for name, values in expected.items():
        if name.startswith(("flags", "notes", "area", "n_rays", "id", "frame")):
            np.testing.assert_array_equal(got[name], values, err_msg=name)
        elif name.startswith(("x2_", "x3_")) and "opt" not in name and "true" not in name:
            if same_images:
                np.testing.assert_array_equal(got[name], values, err_msg=name)
            else:
                np.testing.assert_allclose(got[name], values, rtol=0, atol=1e-3 * pixel)
        else:
            np.testing.assert_allclose(got[name], values, rtol=1e-12, atol=1e-9 * pixel)
    for name, values in numpy_result.rays.items():
        np.testing.assert_array_equal(device_result.rays[name], values, err_msg=name)
    assert device_result.ray_attrs == numpy_result.ray_attrs
    assert device_result.config["engine"] == "device"


def test_device_engine_reuses_the_reference_of_another_case(device):
    options = {**SAMPLE, "device": device, "frames": 2}
    first = _render("device", "C1", **options)
    config = MeasureConfig.from_options(engine="device", **options)
    again = run_render(None, case="C2", config=config, reference=first.reference)
    fresh = run_render(None, case="C2", config=config)
    for name, values in fresh.tracers.items():
        np.testing.assert_array_equal(again.tracers[name], values, err_msg=name)


def test_straight_reference_with_side_exits_matches_the_numpy_engine(device):
    """The reference through a uniform clamped box (straight rays, no steps on either
    engine) with rays that leave the box sideways, and a G = 0 case imaged the same way."""
    options = {
        **SAMPLE,
        "device": device,
        "camera": "pupil",
        "view_angle": 40.0,
        "aperture_diameter": 3.0,
    }
    results = {}
    for engine in ("numpy", "device"):
        config = MeasureConfig.from_options(engine=engine, frame_image=True, **options)
        config = dataclasses.replace(config, box=((0.0, 3.2), (0.0, 6.2), (0.0, 6.2)))
        results[engine] = run_render(None, case="G=0", config=config)
    assert_engines_agree(results["numpy"], results["device"])
    for result in results.values():
        assert result.reference.ray_counts["exit_side"] > 0
        assert result.reference.ray_steps == 0 and result.ray_attrs["ray_steps"] == 0
        # G = 0 images through the same straight rays: no refraction error at all
        tracers = result.tracers
        np.testing.assert_array_equal(tracers["x2_meas"], tracers["x2_ref"])
        np.testing.assert_array_equal(tracers["x3_opt"], tracers["x3_opt_ref"])


@pytest.mark.parametrize("kind", ["exact", "paper"])
def test_blocks_of_sources_add_the_same_light_as_one_source_at_a_time(device, kind, monkeypatch):
    """The image kernel adds RIMCL_SPLAT_BLOCK sources per pass over a window: every
    pixel's sum keeps the source order, so the raw images (their peaks and light) are
    those of one source at a time to the last bit."""
    import rimcl.imaging.device

    points, usable = _clouds(np.random.default_rng(11))
    weights = np.random.default_rng(12).uniform(0.5, 1.5, size=usable.shape)
    imaging = _imaging(kind, 16, "grey")
    flags = np.zeros(len(points), dtype=np.int64)
    columns = {}
    for block in (1, 3, rimcl.imaging.device.SPLAT_BLOCK):
        monkeypatch.setattr(rimcl.imaging.device, "SPLAT_BLOCK", block)
        columns[block] = image_points(
            imaging,
            points,
            usable,
            weights,
            flags,
            scales=np.full(len(points), 1000.0),
            device=device,
        )
    assert np.count_nonzero(np.isfinite(columns[1]["x2"])) >= 5  # 5 clouds have one image
    for block in columns:
        # peak: the raw image's brightest pixel times the scale given
        for name in ("peak", "x2_opt", "x2", "x3", "area", "flags"):
            np.testing.assert_array_equal(columns[block][name], columns[1][name], err_msg=name)


def test_normal_cdf_of_the_image_kernel_matches_scipy(device, has_fp64):
    """cl/rimcl_ndtr.h (the exact renderer's pixel integrals): ndtr within 2 ulp of 1 of
    scipy's over the renderer's range of edges, and in the tails within 1.5e-15 of
    erfcx(z) exp(-z^2) / 2 for the same exponential (scipy's erfcx as the reference)."""
    import pyopencl as cl
    from scipy.special import erfcx, ndtr

    from rimcl.core.program import kernel_dir

    if not has_fp64:
        pytest.skip("the image kernel needs cl_khr_fp64")
    source = r"""
    #pragma OPENCL EXTENSION cl_khr_fp64 : enable
    #include "rimcl_ndtr.h"
    __kernel void normal_cdf(__global const double *a, __global const double *gauss,
                             __global double *out) {
        const size_t i = 8 * get_global_id(0);
        vstore8(ndtr8(vload8(0, a + i), vload8(0, gauss + i)), 0, out + i);
    }"""
    context = cl.Context([device])
    queue = cl.CommandQueue(context)
    kernel = cl.Program(context, source).build(options=[f"-I{kernel_dir()}"]).normal_cdf
    # edges up to 9 sigma from a ray (EXACT_SIGMAS = 8, plus a pixel), the middle densely
    a = np.concatenate([np.linspace(-9.0, 9.0, 40000), np.linspace(-1.1, 1.1, 4000)])
    gauss = np.exp(-0.5 * a * a)
    flags = cl.mem_flags
    inputs = [
        cl.Buffer(context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=x) for x in (a, gauss)
    ]
    out = np.empty_like(a)
    result = cl.Buffer(context, flags.WRITE_ONLY, out.nbytes)
    kernel(queue, (len(a) // 8,), None, *inputs, result)
    cl.enqueue_copy(queue, out, result)
    assert np.max(np.abs(out - ndtr(a))) <= 2 * 2.0**-52
    z = -a / np.sqrt(2.0)
    lower_tail = z >= np.sqrt(0.5)  # where ndtr8 takes erfcx
    expected = 0.5 * erfcx(z[lower_tail]) * gauss[lower_tail]
    np.testing.assert_allclose(out[lower_tail], expected, rtol=1.5e-15, atol=0)


def test_no_ray_sample_gives_empty_ray_tables_on_both_engines(device):
    """run.ray_sample = 0: the device engine never hands its sampler a batch."""
    options = {**SAMPLE, "device": device, "frames": 1, "ray_sample": 0}
    tables = [_render(engine, "C1", **options).rays for engine in ("numpy", "device")]
    for numpy_column, device_column in zip(tables[0].values(), tables[1].values(), strict=True):
        assert len(device_column) == 0 and device_column.dtype == numpy_column.dtype
    assert tables[0].keys() == tables[1].keys()


def test_several_batches_per_frame_match_the_numpy_engine(device, monkeypatch):
    """Batches double-buffered within a frame (the ray sample, noise keys and rows of
    each batch at their tracers): the same result as one batch and as NumPy."""
    import rimcl.imaging.device

    options = {**SAMPLE, "device": device, "frames": 2, "ray_sample": 300, "camera": "pupil"}
    one_batch = _render("device", "C3", **options)
    monkeypatch.setattr(rimcl.imaging.device, "MIN_BATCH_RAYS", 0)
    monkeypatch.setattr(rimcl.imaging.device, "CPU_SLOTS_PER_CORE", 1)
    monkeypatch.setattr(rimcl.imaging.device, "GPU_SLOTS_PER_UNIT", 1)
    split = MeasureConfig.from_options(
        engine="device", frame_image=True, rays_per_batch=64, **options
    )
    several = run_render(None, case="C3", config=split)
    assert several.config["engine"] == "device"
    assert_engines_agree(_render("numpy", "C3", **options), several)
    for name, values in one_batch.tracers.items():
        np.testing.assert_array_equal(several.tracers[name], values, err_msg=name)

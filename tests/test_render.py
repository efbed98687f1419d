"""Renderers: render → quantize → centroid round trips at known sub-pixel positions."""

import numpy as np
import pytest
from scipy.special import ndtr

from rimcl.core.errors import RimclError
from rimcl.imaging.centroid import locate
from rimcl.imaging.render import FULL_SCALE, FrameImage, Renderer, Window, quantize, scale_for

SIGMA = 2.3
THRESHOLD = 100


def _renderer(kind, **kw):
    return Renderer(kind, pixel_size=1.0, origin=(0.0, 0.0), psf_sigma=SIGMA, **kw)


def _round_trip(renderer, point, window, rays=16):
    """Centroid (pixels) of a tracer whose rays all image to ``point``."""
    pixels = np.repeat(np.asarray(point, dtype=float)[None], rays, axis=0)
    raw, outside = renderer.render(pixels, np.ones(rays), window)
    assert outside == 0
    counts, saturated = quantize(raw, scale_for(raw))
    assert not saturated
    blob = locate(counts, THRESHOLD)
    return np.array([window.col0 + blob.col, window.row0 + blob.row])


# sub-pixel offsets on both axes, on windows of different widths and heights
OFFSETS = np.linspace(0.0, 1.0, 9, endpoint=False)
WINDOWS = [Window(-7, 3, 41, 23), Window(-20, -2, 30, 57)]


@pytest.mark.parametrize("window", WINDOWS, ids=["wide", "tall"])
def test_exact_renderer_bias_below_a_hundredth_pixel(window):
    centre = np.array([window.col0 + window.width // 2, window.row0 + window.height // 2])
    worst = 0.0
    for dx in OFFSETS:
        for dy in OFFSETS:
            point = centre + np.array([dx, dy + 0.05])
            worst = max(
                worst, np.max(np.abs(_round_trip(_renderer("exact"), point, window) - point))
            )
    assert worst <= 0.01


def test_exact_renderer_with_paper_weights_shows_threshold_bias():
    # the paper's plain grey weights jump when a pixel crosses the threshold
    window = WINDOWS[0]
    errors = []
    for dx in OFFSETS:
        point = np.array([13.0 + dx, 14.3])
        pixels = np.repeat(point[None], 4, axis=0)
        raw, _ = _renderer("exact").render(pixels, np.ones(4), window)
        counts, _ = quantize(raw, scale_for(raw))
        blob = locate(counts, THRESHOLD, weights="grey")
        errors.append(window.col0 + blob.col - point[0])
    assert 0.02 < np.max(np.abs(errors)) < 0.1


def test_paper_renderer_locks_a_point_image_to_the_pixel_centre():
    window = WINDOWS[1]
    errors = []
    for dx in OFFSETS:
        for dy in OFFSETS:
            point = np.array([-5.0 + dx, 20.0 + dy])
            found = _round_trip(_renderer("paper"), point, window)
            np.testing.assert_allclose(found, np.floor(point) + 0.5, atol=1e-12)
            errors.append(found - point)
    # uniform sub-pixel positions: the locking error is uniform in [-0.5, 0.5) px
    assert np.sqrt(np.mean(np.square(errors))) == pytest.approx(np.sqrt(1 / 12), rel=0.1)


def test_paper_renderer_unlocks_a_spread_image():
    # rays spread over several pixels (a distorted tracer) average the binning out
    rng = np.random.default_rng(3)
    spread = rng.normal(scale=2.0, size=(4000, 2))
    spread -= spread.mean(axis=0)
    window = Window(0, 0, 40, 40)
    renderer = _renderer("paper")
    for dx in (0.1, 0.3, 0.5, 0.7):
        point = np.array([20.0 + dx, 19.6])
        raw, _ = renderer.render(point + spread, np.ones(len(spread)), window)
        counts, _ = quantize(raw, scale_for(raw))
        blob = locate(counts, THRESHOLD)
        assert blob.col == pytest.approx(point[0], abs=0.05)


@pytest.mark.parametrize("kind", ["exact", "paper"])
def test_light_is_conserved_in_the_window(kind):
    renderer = _renderer(kind)
    pixels = np.array([[3.2, 4.7], [6.9, 2.1], [5.0, 5.0]])
    weights = np.array([1.0, 2.0, 0.5])
    window = renderer.window_for(pixels)
    raw, outside = renderer.render(pixels, weights, window)
    assert outside == 0
    # the window is padded to the PSF's 4 σ cut: only the Gaussian tails beyond are lost
    assert raw.sum() == pytest.approx(weights.sum(), rel=2e-4)


def test_window_holds_every_point_and_its_psf():
    renderer = _renderer("exact")
    pixels = np.array([[10.2, -3.7], [25.9, 4.4]])
    window = renderer.window_for(pixels)
    assert window.col0 <= 10.2 - 4 * SIGMA and window.col0 + window.width >= 25.9 + 4 * SIGMA
    assert window.row0 <= -3.7 - 4 * SIGMA and window.row0 + window.height >= 4.4 + 4 * SIGMA


def test_capped_window_counts_the_rays_left_outside():
    renderer = _renderer("exact", max_window=64)
    pixels = np.array([[0.0, 0.0]] * 8 + [[500.0, 0.0]] * 2)
    window = renderer.window_for(pixels)
    assert window.width == 64
    _, outside = renderer.render(pixels, np.ones(len(pixels)), window)
    assert outside == 2


def test_quantize_scales_rounds_and_clips():
    raw = np.array([[0.0, 1.0], [2.0, 0.26]])
    counts, saturated = quantize(raw, scale_for(raw))
    np.testing.assert_array_equal(counts, [[0, 512], [1023, 133]])
    assert not saturated
    counts, saturated = quantize(2 * raw, scale_for(raw))
    assert saturated and counts.max() == FULL_SCALE


def test_frame_image_adds_and_clips_windows_at_the_frame_edge():
    frame = FrameImage(width=6, height=4)
    counts = np.full((3, 3), 600.0)
    frame.add(Window(-1, 2, 3, 3), counts)
    frame.add(Window(0, 3, 3, 3), counts)
    expected = np.zeros((4, 6), dtype=np.uint16)
    expected[2:4, 0:2] = 600
    expected[3, 0:2] = 1023
    expected[3, 2] = 600
    np.testing.assert_array_equal(frame.counts, expected)


def test_pixel_coordinates_round_trip():
    renderer = Renderer("exact", pixel_size=0.25, origin=(1.0, -2.0))
    points = np.array([[1.0, -2.0], [1.3, 0.55]])
    np.testing.assert_allclose(renderer.to_pixels(points), [[0, 0], [1.2, 10.2]])
    np.testing.assert_allclose(renderer.to_sheet(renderer.to_pixels(points)), points)


def test_exact_pixel_integrals_match_erf_differences():
    renderer = _renderer("exact")
    point = np.array([[2.4, 1.6]])
    raw, _ = renderer.render(point, np.ones(1), Window(0, 0, 5, 4))
    cols = ndtr((np.arange(1, 6) - 2.4) / SIGMA) - ndtr((np.arange(0, 5) - 2.4) / SIGMA)
    rows = ndtr((np.arange(1, 5) - 1.6) / SIGMA) - ndtr((np.arange(0, 4) - 1.6) / SIGMA)
    np.testing.assert_allclose(raw, np.outer(rows, cols), rtol=1e-13)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"kind": "blur"}, "unknown renderer"),
        ({"pixel_size": 0.0}, "pixel size"),
        ({"psf_sigma": -1.0}, "PSF sigma"),
        ({"max_window": 8}, "largest window"),
    ],
)
def test_bad_renderer_settings_rejected(kw, match):
    settings = {"kind": "exact", "pixel_size": 1.0, "origin": (0.0, 0.0), **kw}
    with pytest.raises(RimclError, match=match):
        Renderer(**settings)


def test_a_deeper_camera_lowers_the_rounding_noise_of_centroids():
    """The shift that rounding to counts gives a centroid shrinks with the bit depth
    (about 2**-6 from 10 to 16 bits); a 7-bit camera is refused."""
    window = WINDOWS[0]
    rounding = {}
    for bits in (10, 16):
        renderer = _renderer("exact", bit_depth=bits)
        full = renderer.full_scale
        threshold = THRESHOLD * full / FULL_SCALE
        worst = 0.0
        for dx in OFFSETS:
            pixels = np.repeat(np.array([[13.0 + dx, 14.37]]), 4, axis=0)
            raw, _ = renderer.render(pixels, np.ones(4), window)
            scale = scale_for(raw, full)
            counts, _ = quantize(raw, scale, full)
            assert counts.max() == full
            rounded = locate(counts, threshold)
            exact = locate(raw * scale, threshold)
            worst = max(worst, abs(rounded.col - exact.col), abs(rounded.row - exact.row))
        rounding[bits] = worst
    assert 1e-5 < rounding[10] < 0.01
    assert rounding[16] < rounding[10] / 10
    with pytest.raises(RimclError, match="bit depth"):
        _renderer("exact", bit_depth=7)

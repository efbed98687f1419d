"""PIV never calls noise a vector, and a background offset moves no vector (issue 20, 1)."""

import warnings

import numpy as np
import pytest
from click.testing import CliRunner
from piv_particles import particle_pair, render_particles, uniform

from rimcl.cli.main import cli
from rimcl.piv.analysis import (
    PivSettings,
    WindowGrid,
    analyze_pair,
    write_tiff,
)


def _quietly(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return analyze_pair(*args, **kwargs)


@pytest.mark.parametrize("passes", [1, 3])
@pytest.mark.parametrize("level", [0.0, 1000.0])
def test_empty_and_constant_frames_give_no_valid_vector(passes, level):
    frame = np.full((64, 64), level)
    result = _quietly(frame, frame, PivSettings(window=16, passes=passes))
    assert not result.valid.any() and not result.replaced.any()
    assert np.isnan(result.dx).all() and np.isnan(result.peak_ratio).all()


@pytest.mark.parametrize("passes", [1, 2, 3])
def test_one_particle_is_valid_only_where_its_image_is(passes):
    def frame(x, y):
        image = render_particles(np.array([x]), np.array([y]), (64, 64), 0.75) * 30000
        return np.rint(image).astype(np.uint16)

    settings = PivSettings(window=16, passes=passes)
    # pixel centres at integer coordinates (piv_particles): the particle at (29.7, 32.6)
    # in A and (30.5, 33.1) in B
    result = _quietly(frame(29.7, 32.6), frame(30.5, 33.1), settings)
    # the particle's peak pixel is (row 33, column 30) in A and (33, 31) in B: only the
    # windows holding both are vectors; the deformation's spline spreads light into all 49
    grid = WindowGrid.for_image((64, 64), 16, 0.5)
    rows = (grid.rows <= 33) & (33 < grid.rows + 16)
    cols = (grid.cols <= 30) & (31 < grid.cols + 16)
    np.testing.assert_array_equal(result.valid, rows[:, None] & cols[None, :])
    assert result.valid.sum() == 4
    # one pass: the windows' edges cut the particle image (0.71 px at 2 of them)
    np.testing.assert_allclose(result.dx[result.valid], 0.8, atol=0.1)
    np.testing.assert_allclose(result.dy[result.valid], 0.5, atol=0.1)


@pytest.mark.parametrize("passes, tolerance", [(1, 0.15), (3, 0.04)])
def test_half_blank_noisy_frames_are_invalid_there(passes, tolerance):
    rng = np.random.default_rng(3)
    image_a, image_b = particle_pair(uniform(1.3, -0.4), (128, 128), seed=7)
    frames = []
    for image in (image_a, image_b):
        image = image.astype(np.float64)
        image[:, 64:] = 0  # no particle in the right half: 100 counts of background, noise
        frames.append(np.rint(image + 100 + rng.normal(0, 20, image.shape)).astype(np.uint16))
    from rimcl.piv.validity import noise_sigma

    assert noise_sigma(frames[0][:, 64:]) == pytest.approx(20, rel=0.1)
    result = _quietly(*frames, PivSettings(window=32, passes=passes))
    grid = WindowGrid.for_image((128, 128), 32, 0.5)
    blank = grid.cols >= 64
    assert not result.valid[:, blank].any()
    assert result.valid[:, grid.cols + 32 <= 64].all()
    assert result.replaced[:, blank].all()  # from the valid half, not from noise
    # one pass without deformation loses pairs at 1.3 px in 32 px windows (down to 1.17 px)
    full = result.dx[:, grid.cols + 32 <= 64]
    np.testing.assert_allclose(full, 1.3, atol=tolerance)


@pytest.mark.parametrize("shift", [0.3, 0.5, 0.8])
@pytest.mark.parametrize("offset", [1000, 5000])
def test_a_background_offset_moves_no_vector(shift, offset):
    # the README's synthetic pairs (d = 3 px, 0.03 particles per pixel, 32 px windows)
    image_a, image_b = particle_pair(uniform(shift, -0.6 * shift), (256, 256), seed=11)
    plain = analyze_pair(image_a, image_b, PivSettings(window=32))
    raised = analyze_pair(image_a + float(offset), image_b + float(offset), PivSettings(window=32))
    assert np.max(np.abs(raised.dx - plain.dx)) <= 0.0025
    assert np.max(np.abs(raised.dy - plain.dy)) <= 0.0025
    np.testing.assert_array_equal(raised.valid, plain.valid)


def test_cli_all_zero_frames_say_n_a(tmp_path):
    path = tmp_path / "zero.tif"
    write_tiff(path, np.zeros((64, 64)))
    args = ["piv", "analyze", str(path), str(path), "-o", str(tmp_path / "v.h5"), "--window", "16"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "49 invalid, 0 of them replaced" in result.output
    assert "mean displacement n/a" in result.output and "nan" not in result.output


def test_piv_memory_is_estimated_before_it_is_spent(monkeypatch):
    from rimcl.core import memory
    from rimcl.core.errors import RimclError
    from rimcl.piv.analysis import check_piv_memory

    monkeypatch.setattr(memory, "host_available", lambda: 1 << 30)
    check_piv_memory((1024, 1024), PivSettings())  # about 0.4 GiB: fits
    # --overlap 0.999: a window at every pixel, 986049 windows of 32 x 32 px
    with pytest.raises(RimclError, match=r"needs about 6\d\.\d GiB .*--overlap.*--window"):
        analyze_pair(np.zeros((1024, 1024)), np.zeros((1024, 1024)), PivSettings(overlap=0.999))


def test_a_tiff_that_expands_beyond_memory_is_refused_from_its_header(tmp_path, monkeypatch):
    import tifffile

    from rimcl.core import memory
    from rimcl.piv import analysis

    path = tmp_path / "big.tif"
    tifffile.imwrite(path, np.zeros((8000, 8000), np.uint16), compression="zlib")
    assert path.stat().st_size < 1 << 20  # 122 MiB of pixels in a small file
    monkeypatch.setattr(memory, "host_available", lambda: 1 << 30)

    def never(path):
        raise AssertionError("the pixels were read")

    monkeypatch.setattr(analysis, "read_tiff", never)
    args = ["piv", "analyze", str(path), str(path), "-o", str(tmp_path / "v.h5")]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "8000 x 8000 px frames" in lines[0], result.output
    assert "--window" in lines[0] and "tracers" not in lines[0]

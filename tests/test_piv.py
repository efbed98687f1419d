"""PIV correlation (rimcl.piv.analysis) on synthetic pairs of known displacement."""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from piv_particles import particle_pair, uniform

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.piv.analysis import (
    PivSettings,
    WindowGrid,
    analyze_pair,
    correlate_windows,
    interpolate_grid,
    normalized_median_test,
    read_tiff,
    replace_outliers,
    write_tiff,
)

SHAPE = (256, 256)


def _errors(result, shift_x, shift_y):
    return result.dx - shift_x, result.dy - shift_y


@pytest.mark.parametrize("shift", np.linspace(0.0, 1.0, 9))
def test_subpixel_shifts_bias_and_rms(shift):
    # d = 3 px, 0.03 ppp, 32 px windows; the two components get different sub-pixel parts
    image_a, image_b = particle_pair(uniform(shift, -0.6 * shift), SHAPE, seed=11)
    result = analyze_pair(image_a, image_b, PivSettings(window=32))
    for error in _errors(result, shift, -0.6 * shift):
        assert abs(error.mean()) < 0.02
        assert np.sqrt(np.mean(error**2)) < 0.05
    assert result.valid.all() and not result.replaced.any()


@pytest.mark.parametrize("shift", [(1, 0), (0, -1), (2, -1), (-3, 2)])
def test_integer_shifts(shift):
    image_a, image_b = particle_pair(uniform(*shift), SHAPE, seed=5)
    result = analyze_pair(image_a, image_b)
    for error in _errors(result, *shift):
        assert abs(error.mean()) < 0.005
        assert np.sqrt(np.mean(error**2)) < 0.005


def test_linear_shear_recovered_after_deformation():
    rate = 0.02  # dx = rate (y - 256): ±5 px over the frame

    def shear(x, y):
        return rate * (y - 256.0), np.zeros_like(y)

    image_a, image_b = particle_pair(shear, (512, 512), seed=4)
    single = analyze_pair(image_a, image_b, PivSettings(passes=1))
    deformed = analyze_pair(image_a, image_b, PivSettings(passes=3))
    truth = rate * (deformed.y - 256.0)
    # the displacement is the particles' (taken at their first position; a shear moves
    # them along x only, so it is also the displacement at the midpoint)
    assert np.max(np.abs(deformed.dx - truth)) < 0.1
    assert np.max(np.abs(deformed.dy)) < 0.1
    assert deformed.valid.all()
    # one pass without deformation is much worse at the same windows
    assert np.max(np.abs(single.dx - truth)) > 2 * np.max(np.abs(deformed.dx - truth))


def test_window_grid_convention():
    grid = WindowGrid.for_image((100, 130), 32, 0.5)
    # 16 px spacing, centred: columns 130 - 32 = 98 -> corners 0..96 offset by 1
    assert grid.spacing == 16
    assert grid.cols.tolist() == [1, 17, 33, 49, 65, 81, 97]
    assert grid.rows.tolist() == [2, 18, 34, 50, 66]
    # pixel centres at integer coordinates: the centre of pixels 1..32 is 16.5
    assert grid.x[0] == 16.5 and grid.y[0] == 17.5
    image = np.arange(100 * 130, dtype=float).reshape(100, 130)
    windows = grid.extract(image)
    assert windows.shape == (5, 7, 32, 32)
    assert windows[1, 2, 0, 0] == image[18, 33]


def test_correlation_peak_of_a_circular_shift_is_exact():
    rng = np.random.default_rng(0)
    window = rng.random((32, 32))
    moved = np.roll(window, (3, -5), axis=(0, 1))  # B(p) = A(p - d), d = (dx -5, dy 3)
    dx, dy, ratio, found = correlate_windows(window[None], moved[None])
    assert found[0] and ratio[0] > 1
    assert dx[0] == pytest.approx(-5, abs=1e-9) and dy[0] == pytest.approx(3, abs=1e-9)


def test_empty_window_is_not_a_vector():
    *_, ratio, found = correlate_windows(np.zeros((1, 16, 16)), np.zeros((1, 16, 16)))
    assert not found[0] and np.isnan(ratio[0])


def test_blank_pair_gives_no_vectors():
    result = analyze_pair(np.zeros((64, 64)), np.zeros((64, 64)))
    assert np.all(np.isnan(result.dx)) and not result.valid.any() and not result.replaced.any()


def test_median_test_flags_an_outlier_and_keeps_linear_fields():
    rows, cols = np.mgrid[0:9, 0:11].astype(float)
    dx, dy = 0.3 * rows - 0.1 * cols, 0.05 * cols
    assert not normalized_median_test(dx, dy).any()  # edges included
    spoiled = dx.copy()
    spoiled[4, 5] += 1.0
    spoiled[0, 0] -= 1.0
    outliers = normalized_median_test(spoiled, dy)
    assert outliers[4, 5] and outliers[0, 0] and outliers.sum() == 2
    fixed_x, fixed_y = replace_outliers(spoiled, dy, outliers)
    # the median of the neighbours of a linear field is its centre value (edges too)
    assert fixed_x[4, 5] == pytest.approx(dx[4, 5])
    assert fixed_x[0, 0] == pytest.approx(dx[0, 0])
    np.testing.assert_array_equal(fixed_y, dy)


def test_outliers_in_images_are_flagged_and_replaced():
    image_a, image_b = particle_pair(uniform(2.0, 1.0), SHAPE, seed=2)
    image_b = image_b.copy()
    image_b[100:140, 100:140] = 0  # no particles: the vectors there are noise
    result = analyze_pair(image_a, image_b, PivSettings(passes=1))
    assert result.replaced.any()
    assert np.array_equal(result.replaced, ~result.valid)
    fixed = result.replaced
    assert np.all(np.abs(result.dx[fixed] - 2.0) < 0.2)


def test_displacement_interpolation_is_exact_for_linear_fields_beyond_the_centres():
    grid = WindowGrid.for_image((64, 96), 16, 0.5)
    values = 0.1 * grid.x[None, :] - 0.3 * grid.y[:, None] + 2.0
    x, y = np.arange(96) + 0.5, np.arange(64) + 0.5
    np.testing.assert_allclose(
        interpolate_grid(grid, values, x, y), 0.1 * x[None, :] - 0.3 * y[:, None] + 2.0, atol=1e-12
    )


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"window": 31}, "even"),
        ({"window": 4}, ">= 8"),
        ({"overlap": 1.0}, "overlap"),
        ({"passes": 0}, "passes"),
        ({"first_window": 16}, "first window"),
        ({"outlier_eps": 0.0}, "eps"),
    ],
)
def test_bad_settings_rejected(kw, match):
    with pytest.raises(RimclError, match=match):
        PivSettings(**kw)


def test_bad_pairs_rejected():
    with pytest.raises(RimclError, match="differ in shape"):
        analyze_pair(np.zeros((64, 64)), np.zeros((64, 32)))
    with pytest.raises(RimclError, match="does not fit"):
        analyze_pair(np.zeros((20, 64)), np.zeros((20, 64)))


def test_cli_analyze_round_trip(tmp_path):
    image_a, image_b = particle_pair(uniform(0.7, -0.3), (128, 192), seed=3)
    path_a, path_b, out = tmp_path / "a.tif", tmp_path / "b.tif", tmp_path / "v.h5"
    write_tiff(path_a, image_a, {"what": "test"})
    write_tiff(path_b, image_b)
    np.testing.assert_array_equal(read_tiff(path_a), image_a)
    args = ["piv", "analyze", str(path_a), str(path_b), "-o", str(out), "--passes", "2"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "seconds per pass" in result.output
    with h5py.File(out) as h5:
        assert h5.attrs["rimcl_schema"] == "piv"
        assert "config" in h5.attrs and "versions" in h5.attrs and "settings" in h5.attrs
        assert h5["valid"].dtype == bool and h5["replaced"].dtype == bool
        assert h5["x"].shape == h5["dx"].shape == (7, 11)
        assert h5["x"][0, 0] == 15.5 and h5["y"][0, 0] == 15.5
        assert abs(np.mean(h5["dx"][()]) - 0.7) < 0.02
        assert abs(np.mean(h5["dy"][()]) + 0.3) < 0.02
        dx, valid = h5["dx"][()], h5["valid"][()]
    import xarray as xr

    vectors = xr.open_dataset(out, engine="h5netcdf")  # one line: named dimensions, units
    assert vectors["dx"].dims == ("row", "column") and vectors["dx"].attrs["units"] == "px"
    np.testing.assert_array_equal(vectors["dx"].values, dx)
    np.testing.assert_array_equal(vectors["valid"].values, valid)
    assert vectors["column"].values[0] == 15.5 and vectors["peak_ratio"].attrs["units"] == "1"
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 1 and "exists" in again.output


def test_cli_analyze_bad_image_is_one_line(tmp_path):
    bad = tmp_path / "bad.tif"
    bad.write_text("not a tiff")
    out = tmp_path / "v.h5"
    result = CliRunner().invoke(cli, ["piv", "analyze", str(bad), str(bad), "-o", str(out)])
    assert result.exit_code == 1
    assert "not a readable TIFF" in result.output and "Traceback" not in result.output
    colour = tmp_path / "rgb.tif"
    import tifffile

    tifffile.imwrite(colour, np.zeros((8, 8, 3), dtype=np.uint8))
    result = CliRunner().invoke(cli, ["piv", "analyze", str(colour), str(colour), "-o", str(out)])
    assert result.exit_code == 1 and "one grey image" in result.output

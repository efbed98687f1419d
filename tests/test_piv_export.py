"""PIV vectors exported for other tools (rimcl.piv.export): netCDF, OpenPIV text, PIVlab .mat."""

import json

import h5netcdf
import numpy as np
import pytest
import tifffile
from click.testing import CliRunner
from piv_particles import particle_pair, uniform
from scipy.io import loadmat

from rimcl.cli.main import cli
from rimcl.piv.analysis import PivSettings, analyze_pair
from rimcl.piv.export import export_vectors, light_mask

SETTINGS = PivSettings(window=16, passes=3)


@pytest.fixture(scope="module")
def dark_right_pair():
    """A pair moved by (0.7, -0.4) px whose right quarter has no light."""
    image_a, image_b = particle_pair(uniform(0.7, -0.4), shape=(64, 96), seed=3)
    for image in (image_a, image_b):
        image[:, 72:] = 0
    return image_a, image_b


def test_light_mask_marks_the_windows_without_light(dark_right_pair):
    result = analyze_pair(*dark_right_pair, SETTINGS)
    mask = light_mask(*dark_right_pair, result)
    grid_cols = result.x[0]
    # windows of 16 px reaching no column below 72 are dark; the others hold particles
    assert np.all(mask[:, grid_cols - 8 >= 72] == 1)
    assert np.all(mask[:, grid_cols + 8 <= 72] == 0)


def test_every_format_holds_the_vectors_units_and_flags(tmp_path, dark_right_pair):
    result = analyze_pair(*dark_right_pair, SETTINGS)
    mask = light_mask(*dark_right_pair, result)
    result.valid[0, 0] = False  # one flagged vector, to find in every format
    pixel, dt = 2e-5, 1e-3
    paths = {s: tmp_path / f"v{s}" for s in (".nc", ".txt", ".mat")}
    for path in paths.values():
        export_vectors(path, result, mask, pixel_size_m=pixel, dt_s=dt, config={"case": "t"})
    lit = (mask == 0) & (result.x + 16 <= 72)  # windows wholly left of the dark quarter
    with h5netcdf.File(paths[".nc"], "r") as nc:
        assert nc.variables["u"].dimensions == ("y", "x")
        assert nc.variables["u"].attrs["units"] == "pixel"
        assert nc.variables["u_ms"].attrs["units"] == "m s-1"
        np.testing.assert_array_equal(nc.variables["x"][:], result.x[0])
        np.testing.assert_array_equal(nc.variables["v"][:], result.dy)
        np.testing.assert_allclose(nc.variables["u_ms"][:], result.dx * pixel / dt)
        assert nc.variables["flags"][0, 0] == 1 and nc.variables["flags"][1, 1] == 0
        np.testing.assert_array_equal(nc.variables["mask"][:], mask)
    assert np.median(result.dx[lit]) == pytest.approx(0.7, abs=0.02)
    assert np.median(result.dy[lit]) == pytest.approx(-0.4, abs=0.02)
    table = np.loadtxt(paths[".txt"])
    assert table.shape == (result.dx.size, 6)
    header = paths[".txt"].read_text().splitlines()[:3]
    assert header[0] == "# x\ty\tu\tv\tflags\tmask" and "m/s" in header[1]
    assert header[2].startswith("# orientation y-up")
    record = json.loads(paths[".txt"].read_text().splitlines()[3].removeprefix("# rimcl_record "))
    assert (
        record["config"] == {"case": "t"} and record["dt_s"] == dt and "rimcl" in record["versions"]
    )
    # OpenPIV's centres (window 0..15 at 8) and its transform_coordinates: y reversed, v up
    np.testing.assert_allclose(table[:, 0], (result.x.ravel() + 0.5) * pixel, rtol=1e-8)
    np.testing.assert_allclose(table[:, 1], (result.y[::-1] + 0.5).ravel() * pixel, rtol=1e-8)
    np.testing.assert_allclose(table[:, 3], -result.dy.ravel() * pixel / dt, rtol=1e-8)
    np.testing.assert_array_equal(table[:, 4], (~result.valid).ravel())
    np.testing.assert_array_equal(table[:, 5], mask.ravel())
    mat = loadmat(paths[".mat"])
    # PIVlab's calibrated values: x = calxy x_px (MATLAB's 1-based pixels), u = calu dx
    np.testing.assert_allclose(mat["x"][0, 0], (result.x + 1) * pixel)
    np.testing.assert_allclose(mat["u_original"][0, 0], result.dx * pixel / dt)
    kinds = mat["typevector_original"][0, 0]
    assert kinds[0, 0] == 2 and np.all(kinds[mask == 1] == 0) and kinds[1, 1] == 1
    assert np.all(np.isnan(mat["u_filtered"][0, 0][mask == 1]))
    assert mat["calu"][0, 0] == pytest.approx(pixel / dt)
    assert mat["calv"][0, 0] == pytest.approx(-pixel / dt)  # y-up
    assert json.loads(mat["rimcl_config"][0])["config"] == {"case": "t"}


def test_cli_exports_and_refuses_an_unknown_suffix(tmp_path, dark_right_pair):
    for name, image in zip("AB", dark_right_pair, strict=True):
        tifffile.imwrite(tmp_path / f"{name}.tif", image)
    base = ["piv", "analyze", str(tmp_path / "A.tif"), str(tmp_path / "B.tif")]
    runner = CliRunner()
    bad = runner.invoke(cli, [*base, "-o", str(tmp_path / "v.h5"), "--export", "v.csv"])
    assert bad.exit_code != 0 and "cannot export vectors to v.csv" in bad.output
    assert not (tmp_path / "v.h5").exists()  # refused before any work
    ok = runner.invoke(
        cli,
        [
            *base,
            "-o",
            str(tmp_path / "v.h5"),
            "--window",
            "16",
            "--export",
            str(tmp_path / "v.txt"),
        ],
    )
    assert ok.exit_code == 0, ok.output
    assert np.loadtxt(tmp_path / "v.txt").shape[1] == 6
    down = runner.invoke(
        cli,
        [
            *base,
            "-o",
            str(tmp_path / "d.h5"),
            "--window",
            "16",
            "--export",
            str(tmp_path / "d.txt"),
            "--orientation",
            "y-down",
        ],
    )
    assert down.exit_code == 0, down.output
    up, image = np.loadtxt(tmp_path / "v.txt"), np.loadtxt(tmp_path / "d.txt")
    np.testing.assert_allclose(up[:, 3], -image[:, 3])
    bad_way = runner.invoke(cli, [*base, "-o", str(tmp_path / "e.h5"), "--orientation", "up"])
    assert bad_way.exit_code != 0 and "'up' is not one of" in bad_way.output
    half = runner.invoke(cli, [*base, "-o", str(tmp_path / "w.h5"), "--pixel-size-m", "1e-5"])
    assert half.exit_code != 0 and "give both" in half.output

"""``rimcl lpt render`` end to end on a tiny flow with full velocity: files and errors."""

import json

import h5py
import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.lpt.calibration import SoloffModel, triangulate

CAMERA = """
[[rig.cameras]]
name = "{name}"
position_mm = [700.0, {x2}, 50.0]
look_at_mm = [50.0, 50.0, 50.0]
focal_length_mm = 16.0
f_number = 8.0
sensor_pixels = [320, 200]
"""


def test_render_writes_dataset(tmp_path, lpt_flow):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'[field]\npath = "{lpt_flow}"\ntime_s = 0.25\n[cases]\nnames = ["C3"]\n'
        "[tracers]\ncount = 6\n"
        "[time]\nframes = 5\n[lpt]\ncalibration_grid = [6, 5]\n"
        + CAMERA.format(name="left", x2=-300.0)
        + CAMERA.format(name="right", x2=400.0)
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["lpt", "render", str(scene), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "C3: n_ref" in result.output
    stats = json.loads((out / "lpt_stats.json").read_text())
    case = stats["cases"]["C3"]
    assert case["tracers"] == 6 and len(case["rays"]) == 2
    # with field.time_s: every rms also in mm/s and m/s², physical = normalised × scale
    length_m, time_s = stats["length_m"], 0.25
    assert stats["time_s"] == time_s
    scales = case["units"]["scales"]
    assert scales["mm_s_per_velocity"] == length_m / time_s * 1e3
    assert scales["m_s2_per_acceleration"] == length_m / time_s**2
    assert scales["dt_ms"] == case["fit"]["dt"] * time_s * 1e3
    groups = (("velocity", "mm_s", scales["mm_s_per_velocity"]),
              ("acceleration", "m_s2", scales["m_s2_per_acceleration"]))  # fmt: skip
    for group, physical, factor in groups:
        for axis in ("x1", "x2", "x3"):
            entry = case["units"][group][axis]
            assert entry["rms_truth"]["field"] == case[group][axis]["truth_rms"]
            refraction = case[group][axis]["absolute"]["refraction"]["rms"]
            assert refraction > 0 and entry["rms_refraction"]["field"] == refraction
            for name in ("rms_truth", "rms_refraction", "rms_baseline"):
                assert entry[name][physical] == entry[name]["field"] * factor
    units = case["units"]["position"]["x2"]["rms_refraction"]
    assert scales["um_per_length"] == length_m * 1e6
    assert units["um"] == case["position"]["x2"]["refraction"]["rms"] * scales["um_per_length"]
    assert "refraction rms x1/x2/x3" in result.output and "mm/s" in result.output
    with h5py.File(out / "lpt_case_C3.h5", "r") as h5:
        assert h5.attrs["rimcl_schema"] == "lpt_case"
        truth = h5["tracks/x2_true"][()]
        assert truth.shape == (6, 5)  # (id, frame)
        # a tracer whose image is lost in a camera (sensor noise, Mie's dark angles) is
        # flagged and has no measured position; every kept one has one in every frame
        kept = h5["tracks/flags"][()] == 0
        assert kept.sum() >= 4
        np.testing.assert_array_equal(np.isfinite(h5["tracks/x2_meas"][()]).all(axis=1), kept)
        assert set(h5["cameras"]) == {"left", "right"}
        assert "focal_length_mm" in json.loads(h5["cameras/left"].attrs["parameters"])
        centroids = h5["cameras/left/centroid_meas"][()]
        # the threshold variants: each kind's positions are its centroids triangulated on
        # the case's models (refitted here from the file's calibration target)
        target, pixels = h5["calibration/target"][()], h5["calibration/pixels"][()]
        models = [SoloffModel.fit(target, p) for p in pixels]
        for suffix in ("threshold_half", "threshold_double"):
            for kind in ("meas", "ref"):
                points = np.stack(
                    [h5[f"cameras/{n}/centroid_{kind}_{suffix}"][()] for n in ("left", "right")]
                )
                assert not np.array_equal(points[0], h5[f"cameras/left/centroid_{kind}"][()])
                expected, _ = triangulate(models, points.reshape(2, -1, 2))
                for axis, name in enumerate(("x1", "x2", "x3")):
                    variant = h5[f"tracks/{name}_{kind}_{suffix}"]
                    assert variant.attrs["units"] == "L0"
                    np.testing.assert_allclose(
                        variant[()].ravel(), expected[:, axis], rtol=0, atol=1e-9
                    )
    # every group opens in xarray with named dimensions and units, holding the same numbers
    import xarray as xr

    path = out / "lpt_case_C3.h5"
    tracks = xr.open_dataset(path, group="tracks", engine="h5netcdf")
    assert tracks["x2_true"].dims == ("id", "frame") and tracks["time"].dims == ("frame",)
    np.testing.assert_array_equal(tracks["x2_true"].values, truth)
    assert tracks["x2_meas"].attrs["units"] == "L0"
    assert tracks["x2_meas"].attrs["si_per_unit"] == stats["length_m"]
    assert tracks["u3_true"].attrs["units"] == "L0/T0" and tracks["flags"].dims == ("id",)
    assert tracks["u3_true"].attrs["si_per_unit"] == length_m / time_s
    assert tracks["a3_true"].attrs["si_per_unit"] == length_m / time_s**2
    assert tracks["time"].attrs["si_per_unit"] == time_s
    with h5py.File(path) as h5:
        assert h5.attrs["time_s"] == time_s
        assert "m/s each" in json.loads(h5.attrs["units"])["velocity"]
    left = xr.open_dataset(path, group="cameras/left", engine="h5netcdf")
    assert left["centroid_meas"].dims == ("id", "frame", "pixel_axis")
    assert list(left["pixel_axis"].values) == ["column", "row"]
    np.testing.assert_array_equal(left["centroid_meas"].values, centroids)
    assert left["disparity_meas"].dims == ("id", "frame")
    assert left["disparity_meas"].attrs["units"] == "px"
    calibration = xr.open_dataset(path, group="calibration", engine="h5netcdf")
    assert calibration["pixels"].dims == ("camera", "point", "pixel_axis")
    assert list(calibration["camera"].values) == ["left", "right"]
    folder = out / "dataset" / "C3"
    image = tifffile.imread(folder / "images" / "field" / "left_frame0000.tif")
    assert image.dtype == np.uint16 and image.shape == (200, 320) and image.max() > 0
    points = np.loadtxt(folder / "calibration_points.txt")
    assert points.shape == (5 * 6 * 5, 3 + 2 * 2)
    rows = np.loadtxt(folder / "truth_tracks.csv", delimiter=",")
    assert rows.shape == (30, 12)
    # the CSV's X (mm) is the field's x2 of the case file, scaled by length_m
    np.testing.assert_allclose(
        rows[:6, 3], truth[:, 0] * stats["length_m"] * 1e3, rtol=1e-8, atol=1e-9
    )
    truth_file = xr.open_dataset(folder / "truth_tracks.h5", engine="h5netcdf")
    assert truth_file["position_mm"].dims == ("id", "frame", "axis")
    assert truth_file["position_mm"].attrs["units"] == "mm"
    np.testing.assert_allclose(
        truth_file["position_mm"].sel(axis="X").values, truth * stats["length_m"] * 1e3, rtol=1e-12
    )
    # truth velocity in m/s and acceleration in m/s²: the case file's (L0/T0) × si_per_unit
    assert truth_file["velocity"].attrs["units"] == "m/s"
    assert truth_file["acceleration"].attrs["units"] == "m/s^2"
    for column, symbol, name in ((6, "u", "velocity"), (9, "a", "acceleration")):
        true = tracks[f"{symbol}2_true"]  # X = x2
        np.testing.assert_array_equal(
            truth_file[name].sel(axis="X").values, true.values * true.attrs["si_per_unit"]
        )
        np.testing.assert_allclose(
            rows[:6, column], true.values[:, 0] * true.attrs["si_per_unit"], rtol=1e-8
        )
    assert "velocity in m/s" in (folder / "truth_tracks.csv").read_text().splitlines()[1]
    pinhole = json.loads((folder / "left_pinhole.json").read_text())
    matrix = np.asarray(pinhole["dlt_matrix_mm_to_px"])
    homog = np.hstack([points[:, :3], np.ones((len(points), 1))]) @ matrix.T
    projected = homog[:, :2] / homog[:, 2:]
    assert np.sqrt(np.mean(np.sum((projected - points[:, 3:5]) ** 2, axis=1))) == pytest.approx(
        pinhole["residual_px"],
        rel=1e-4,  # the file holds 6 decimals
    )


def test_bad_scene_is_one_line(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text('[rig]\npreset = "lpt"\n')
    result = CliRunner().invoke(cli, ["lpt", "run", str(scene), "-o", str(tmp_path / "o")])
    assert result.exit_code != 0
    assert result.output.startswith("Error: rig.preset in") and "must be one of" in result.output
    assert "Traceback" not in result.output

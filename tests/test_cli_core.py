"""The thin CLI: --help without OpenCL, devices, verify, trace; errors are one line."""

import json
import subprocess
import sys

import h5py
import numpy as np
from click.testing import CliRunner

from rimcl.cli.main import cli


def test_help_needs_no_opencl():
    code = (
        "import sys; from click.testing import CliRunner; from rimcl.cli.main import cli;"
        "r = CliRunner().invoke(cli, ['--help']); assert r.exit_code == 0, r.output;"
        "assert 'trace' in r.output and 'study' in r.output;"
        "assert 'pyopencl' not in sys.modules, 'pyopencl imported by --help'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_devices_lists_the_usable_device(device):
    result = CliRunner().invoke(cli, ["devices", "--json"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.output)
    assert any(entry["device"] == device.name.strip() and entry["usable"] for entry in found)
    table = CliRunner().invoke(cli, ["devices"])
    assert table.exit_code == 0 and "fp64" in table.output
    # the PoCL version decides the default device: shown, not hidden in the platform string
    pocl = [entry for entry in found if "PoCL" in entry["platform_version"]]
    for entry in pocl:
        version = entry["platform_version"].split("PoCL ", 1)[1].split()[0]
        assert f"PoCL {version}, LLVM " in table.output


def test_verify_passes_and_reports_convergence(device):
    result = CliRunner().invoke(cli, ["verify", "--rays", "4", "--device", "pocl", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["passed"] is True
    assert {row["case"] for row in report["rows"]} >= {"uniform", "fisheye", "grin a=0.5 L=pi"}
    assert {row["interpolation"] for row in report["rows"]} == {"analytic", "trilinear"}
    assert min(report["convergence"]["ratios"]) >= 12 or report["convergence"]["precision"] != "f64"
    assert report["f32_drift"]["f32"] > 100 * report["f32_drift"]["f32c"]


def test_trace_writes_the_fan_with_status_counts_and_config(device, tmp_path):
    out = tmp_path / "grin.h5"
    args = [
        "trace",
        "--analytic",
        "grin",
        "--length",
        "10",
        "--tracers",
        "3",
        "--fan",
        "4",
        "--step",
        "0.01",
        "--seed",
        "7",
        "-o",
        str(out),
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        assert f.attrs["rimcl_schema"] == "trace"
        counts = json.loads(f.attrs["status_counts"])
        assert counts["ok"] == 48 and sum(counts.values()) == 48
        config = json.loads(f.attrs["config"])
        assert config["rays"] == {"tracers": 3, "fan": 4, "seed": 7}
        assert config["trace"]["step"] == np.float32(0.01)
        assert "numpy" in json.loads(f.attrs["versions"])
        assert f["rays/image_pos"].shape == (48, 3)
        np.testing.assert_array_equal(f["rays/tracer_id"][()], np.repeat(np.arange(3), 16))
        origins = f["rays/origin"][()]
        assert np.all(origins[:, 0] == 0.0)
    import xarray as xr

    rays = xr.open_dataset(out, group="rays", engine="h5netcdf")  # named dimensions, units
    assert rays["origin"].dims == ("ray", "axis") and rays["deflection"].dims == ("ray",)
    np.testing.assert_array_equal(rays["origin"].values, origins)
    assert rays["n_metric"].attrs["units"] == "1/L0" and rays["end_pos"].attrs["units"] == "L0"
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 1
    assert "exists" in again.output and "--overwrite" in again.output


def test_trace_reads_rays_from_a_file(device, tmp_path):
    rays = tmp_path / "rays.csv"
    np.savetxt(rays, [[0, 0.1, 0, 1, 0, 0], [0, -0.1, 0.2, 1, 0.1, 0]], delimiter=",")
    out = tmp_path / "out.h5"
    result = CliRunner().invoke(
        cli, ["trace", "--analytic", "uniform", "--rays", str(rays), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        np.testing.assert_allclose(f["rays/image_pos"][:, 1:], [[0.1, 0], [-0.1, 0.2]], atol=1e-9)


def test_bad_input_is_one_clear_line(device, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2,3\n")
    result = CliRunner().invoke(
        cli, ["trace", "--analytic", "uniform", "--rays", str(bad), "-o", str(tmp_path / "o.h5")]
    )
    assert result.exit_code == 1
    assert (
        result.output.strip().startswith("Error:") and len(result.output.strip().splitlines()) == 1
    )
    assert not (tmp_path / "o.h5").exists()
    missing_dir = CliRunner().invoke(
        cli, ["trace", "--analytic", "uniform", "-o", str(tmp_path / "nowhere" / "o.h5")]
    )
    assert missing_dir.exit_code == 1 and "does not exist" in missing_dir.output
    step = CliRunner().invoke(cli, ["trace", "--analytic", "uniform", "--step", "-1"])
    assert step.exit_code == 2 and "positive" in step.output


def test_trace_auto_reports_its_choice(device, tmp_path):
    out = tmp_path / "auto.h5"
    args = [
        "trace",
        "--analytic",
        "linear",
        "--tracers",
        "2",
        "--fan",
        "3",
        "--interp",
        "auto",
        "--step",
        "auto",
        "--tolerance",
        "1e-6",
        "-o",
        str(out),
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "auto: interp trilinear" in result.output and "tolerance 1.00e-06" in result.output
    with h5py.File(out) as f:
        auto = json.loads(f.attrs["config"])["trace"]["auto"]
    assert auto["tolerance"] == 1e-6 and auto["estimated_error"] <= 1e-6

"""``rimcl render`` through click's test runner: outputs, one-line errors, nothing lost."""

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.fields.field_writer import write_field

QUICK = ["--tracers", "4", "--fan", "4", "--pixels", "1024", "--frames", "3"]


def _periodic_box(path, with_velocity=True):
    count = 12
    h = 2 * np.pi / count
    x = np.arange(count) * h
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    density = [1 + 0.05 * np.sin(x1 + t) * np.cos(x2) for t in (0.0, 0.1, 0.2)]
    velocity = [np.stack([0 * x1, np.sin(x3), np.cos(x2)], axis=-1)] * 3
    write_field(
        path,
        density=density,
        times=(0.0, 0.005, 0.01),
        origin=(0, 0, 0),
        spacing=(h, h, h),
        velocity=velocity if with_velocity else None,
        boundary="periodic",
    )
    return str(path)


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return _periodic_box(tmp_path_factory.mktemp("cli") / "box.h5")


def _run(args):
    return CliRunner().invoke(cli, ["render", *args])


def test_render_writes_the_tables_and_a_frame_image(box, device, tmp_path):
    out, picture = tmp_path / "air.h5", tmp_path / "air.png"
    result = _run(
        ["--field", box, "--case", "C2", *QUICK, "-o", str(out), "--frame-image", str(picture)]
    )
    assert result.exit_code == 0, result.output
    assert "wrote" in result.output and "time per stage" in result.output
    with h5py.File(out) as h5:
        assert h5.attrs["rimcl_schema"] == "render" and h5.attrs["case"] == "C2"
        # (id, frame) datasets: 4 tracers at 3 frames, accelerations at the middle frame
        assert h5["tracers/x2_meas"].shape == (4, 3) and h5["acceleration/a3_meas"].shape == (4, 1)
        assert np.all(np.isfinite(h5["tracers/x2_meas"][()]))
    assert picture.stat().st_size > 0


def test_render_defaults_to_the_shipped_sample(device, tmp_path):
    out = tmp_path / "sample.h5"
    result = _run([*QUICK, "--frames", "1", "-o", str(out)])
    assert result.exit_code == 0, result.output
    with h5py.File(out) as h5:
        assert h5.attrs["case"] == "C1"
        assert h5.attrs["length_L"] == pytest.approx(2 * np.pi)


def test_existing_output_is_kept_without_overwrite(box, device, tmp_path):
    out = tmp_path / "kept.h5"
    out.write_bytes(b"precious")
    result = _run(["--field", box, *QUICK, "-o", str(out)])
    assert result.exit_code == 1
    assert "exists" in result.output and "--overwrite" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert out.read_bytes() == b"precious"
    again = _run(["--field", box, *QUICK, "--frames", "1", "-o", str(out), "--overwrite"])
    assert again.exit_code == 0, again.output
    assert h5py.is_hdf5(out)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (
            [
                "--camera",
                "pupil",
                "--view-angle",
                "85",
                "--camera-distance",
                "100",
                "--aperture-diameter",
                "1",
            ],
            "no ray",
        ),
        (["--camera", "pupil", "--focal-length", "50"], "--f-number"),
        (["--camera", "pupil", "--camera-distance", "3"], "beyond the exit plane"),
        (["--k-rho", "1e-3", "--case", "C1"], "not both"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(box, device, tmp_path, extra, message):
    out = tmp_path / "none.h5"
    quick = QUICK
    if "pupil" in extra:  # the fan sets the plane camera only: refused with a pupil
        quick = [*QUICK[:2], "--pupil-rays", "16", *QUICK[4:]]
    args = ["--field", box, *quick, "--frames", "1", *extra, "-o", str(out)]
    result = _run(args)
    assert result.exit_code == 1
    # one error line (after the progress bar, if the work had started)
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and message in errors[0]
    assert list(tmp_path.iterdir()) == []


def test_field_without_velocity_is_refused_for_tracking(device, tmp_path):
    still = _periodic_box(tmp_path / "still.h5", with_velocity=False)
    out = tmp_path / "none.h5"
    result = _run(["--field", still, *QUICK, "-o", str(out)])
    assert result.exit_code == 1
    assert "holds no velocity" in result.output and "--frames 1" in result.output
    assert not out.exists()


def test_missing_output_directory_is_refused_before_any_work(box, tmp_path):
    out = tmp_path / "no" / "such" / "dir.h5"
    result = _run(["--field", box, *QUICK, "-o", str(out)])
    assert result.exit_code == 1
    assert "does not exist" in result.output


def test_unwritable_output_directory_is_refused(box, tmp_path, monkeypatch):
    import os

    # root may write anywhere: stand in for a read-only directory
    readable = os.access
    monkeypatch.setattr(
        os, "access", lambda path, mode, **kw: mode != os.W_OK and readable(path, mode, **kw)
    )
    result = _run(["--field", box, *QUICK, "-o", str(tmp_path / "out.h5")])
    assert result.exit_code == 1
    assert "not writable" in result.output
    assert list(tmp_path.iterdir()) == []


def test_frame_image_must_be_png_or_tiff(box, tmp_path):
    result = _run(
        [
            "--field",
            box,
            *QUICK,
            "-o",
            str(tmp_path / "o.h5"),
            "--frame-image",
            str(tmp_path / "frame.jpg"),
        ]
    )
    assert result.exit_code == 1
    assert ".png, .tif or .tiff" in result.output
    assert list(tmp_path.iterdir()) == []


def test_help_lists_the_options():
    result = CliRunner().invoke(cli, ["render", "--help"])
    assert result.exit_code == 0
    for option in (
        "--camera",
        "--fan",
        "--pupil-rays",
        "--renderer",
        "--psf-sigma",
        "--threshold",
        "--frame-image",
        "--f-number",
        "--view-angle",
    ):
        assert option in result.output


def test_render_auto_interp_is_chosen_once_and_recorded(device, tmp_path):
    out = tmp_path / "auto.h5"
    args = [
        "render",
        "--tracers",
        "3",
        "--fan",
        "4",
        "--pixels",
        "1024",
        "--interp",
        "auto",
        "--frames",
        "1",
        "-o",
        str(out),
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "auto: interp" in result.output
    with h5py.File(out) as f:
        config = json.loads(f.attrs["config"])
    assert config["auto"]["interp"] in ("trilinear", "bspline3", "texture")
    assert config["trace"]["interp"] == config["auto"]["interp"]
    assert config["auto"]["tolerance"] == pytest.approx(0.01 * 2 * np.pi / 1024)

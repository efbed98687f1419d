"""One scene for every command: ``rimcl render``, ``rimcl piv render``, ``rimcl trace`` and
``rimcl study`` read the same scene file, start from the same defaults and let options
override its keys."""

import json

import h5py
import numpy as np
import pytest
import tifffile
from click.testing import CliRunner
from test_cli_render import _periodic_box

from rimcl.cli.main import cli
from rimcl.scene.config import DEFAULT_PSF_SIGMA
from rimcl.scene.keys import default_scene
from rimcl.scene.load import default_scene_text

# a plane camera named: the tests check the other keys' defaults, whatever the camera's is
SCENE = """
[field]
path = "box.h5"
length_m = 0.05
time_s = 2.0
[cases]
names = ["C0", "C2"]
[tracers]
count = 3
[camera]
kind = "plane"
fan = 4
[time]
frames = 3
[piv]
pixels = 96
window = 16
rays = 16
dt = 0.005
"""


@pytest.fixture
def scene(tmp_path):
    _periodic_box(tmp_path / "box.h5")
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


def _run(*args):
    return CliRunner().invoke(cli, [str(arg) for arg in args])


@pytest.mark.parametrize("command", [["study"], ["render"], ["piv", "render"], ["trace"]])
def test_every_command_prints_the_one_default_scene(command):
    result = _run(*command, "--print-default-scene")
    assert result.exit_code == 0, result.output
    assert result.output == default_scene_text()


def test_render_runs_a_scene_file_in_its_units_and_defaults(scene, device, tmp_path):
    out = tmp_path / "r.h5"
    result = _run("render", scene, "-o", out)
    assert result.exit_code == 0, result.output
    defaults = default_scene()["renderer"]
    with h5py.File(out) as h5:
        attrs = dict(h5.attrs)
    # the scene's keys: its first case other than C0, its tracers, fan and scales
    assert attrs["case"] == "C2" and attrs["n_tracers"] == 3 and attrs["rays_per_tracer"] == 16
    assert attrs["length_m"] == 0.05 and attrs["time_s"] == 2.0
    assert " µm)" in result.output  # the position error in physical units too
    # the keys it leaves out: the defaults every command shares (those of a study)
    assert attrs["pixel_size"] == pytest.approx(2 * np.pi / defaults["pixels"])
    assert attrs["threshold"] == defaults["threshold"]
    assert attrs["psf_sigma_px"] == (defaults["psf_sigma"] or DEFAULT_PSF_SIGMA)
    # options override the scene's keys
    again = _run("render", "--scene", scene, "--tracers", 2, "--threshold", 55, "-o", out)
    assert again.exit_code == 1 and "exists" in again.output
    again = _run("render", scene, "--tracers", 2, "--threshold", 55, "--overwrite", "-o", out)
    assert again.exit_code == 0, again.output
    with h5py.File(out) as h5:
        assert h5.attrs["n_tracers"] == 2 and h5.attrs["threshold"] == 55.0


def test_two_scene_files_are_refused(scene, tmp_path):
    other = tmp_path / "other.toml"
    other.write_text("")
    result = _run("render", scene, "--scene", other, "-o", tmp_path / "x.h5")
    assert result.exit_code == 2 and "one scene file" in result.output


def test_piv_render_runs_a_scene_file(scene, device, tmp_path):
    prefix = tmp_path / "p"
    result = _run("piv", "render", scene, "--overlap", 0.25, "-o", prefix)
    assert result.exit_code == 0, result.output
    assert "case C2" in result.output and "× 16 rays" in result.output
    assert tifffile.imread(f"{prefix}_field_A.tif").shape == (96, 96)
    with h5py.File(f"{prefix}_truth.h5") as h5:
        assert h5.attrs["case"] == "C2" and h5.attrs["dt"] == pytest.approx(0.005)
        assert h5.attrs["pixel_size"] == pytest.approx(2 * np.pi / 96)
        config = json.loads(h5.attrs["config"])
    assert config["truth_windows"] == {"window": 16, "overlap": 0.25}
    # with the field's scales the truth is in m/s too, in the file and on the terminal
    scaled = tmp_path / "s"
    result = _run("piv", "render", scene, "--length-m", 0.01, "--time-s", 0.5, "-o", scaled)
    assert result.exit_code == 0, result.output
    with h5py.File(f"{scaled}_truth.h5") as h5:
        per_px = h5.attrs["pixel_size"] * 0.01 / (h5.attrs["dt"] * 0.5)
        assert h5.attrs["m_s_per_px"] == pytest.approx(per_px, rel=1e-12)
        dx, u_ms = h5["truth/dx"][()], h5["truth/u_ms"][()]
    np.testing.assert_allclose(u_ms, dx * per_px, rtol=1e-12)
    rms = np.sqrt(np.nanmean(dx**2)) * per_px * 1e3
    assert f"({rms:.3g} and " in result.output and " mm/s)" in result.output


def test_trace_runs_a_scene_file(scene, device, tmp_path):
    out = tmp_path / "t.h5"
    text = scene.read_text().replace("[field]", "[field]\nx_sheet = 1.0")
    scene.write_text(text)
    result = _run("trace", scene, "--fan", 2, "-o", out)
    assert result.exit_code == 0, result.output
    with h5py.File(out) as h5:
        origins = h5["rays/origin"][()]
        config = json.loads(h5.attrs["config"])
    assert config["rays"] == {"tracers": 3, "fan": 2, "seed": 0}  # the scene's, --fan's
    assert config["source"]["case"] == "C2"
    assert len(origins) == 3 * 2 * 2 and np.all(origins[:, 0] == 1.0)  # the scene's sheet

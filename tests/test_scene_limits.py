"""Physically impossible scenes are refused, not measured (issue 20, item 3)."""

import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.piv.analysis import PivSettings
from rimcl.piv.render import check_piv_scene
from rimcl.piv.study import configs_from_study
from rimcl.scene.load import load_scene
from rimcl.scene.study_config import StudyConfig


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"camera.window_index": 0.9}, "camera.window_index .* at least 1.0"),
        ({"camera.outside_index": 0.5}, "camera.outside_index .* at least 1.0"),
        ({"mie.particle_index": 0.8}, "mie.particle_index .* at least 1.0"),
        ({"mie.fluid_index": 0.99}, "mie.fluid_index .* at least 1.0"),
        ({"camera.f_number": 0.3}, "camera.f_number .* at least 0.5"),
        ({"camera.sensor_pixels": [2048]}, r"sensor_pixels .* two numbers .*got \[2048\]"),
        ({"sensor.peak_electrons": 40000.0}, "above the full well"),
        ({"time.frames": 1}, "time.frames .* at least 3"),
        ({"time.frames": 2}, "time.frames .* at least 3"),
        ({"time.frames": 3, "time.fit_window": 5}, "fit_window = 5 .* needs at least 5 frames"),
        ({"time.fit_window": 4}, "must be odd"),
        ({"time.fit_order": 5}, "fit_order = 5"),
        ({"time.dt_multiples": [1, 5]}, r"dt_multiples \[5\] .* at most 4"),
        ({"cases.names": ["dT=3", "dT=3.0"], "fluid.kind": "water"}, "case dT=3, dT=3.0 more"),
    ],
)
def test_impossible_scenes_are_refused(overrides, message):
    with pytest.raises(RimclError, match=message):
        load_scene(None, overrides)


def test_the_default_fit_follows_fewer_frames_instead_of_being_dropped():
    assert load_scene(None, {"time.frames": 3})["time"]["fit_window"] == 3
    assert load_scene(None, {"time.frames": 4})["time"]["fit_window"] == 3
    assert load_scene(None, {"time.frames": 7})["time"]["fit_window"] == 5


def test_a_sheet_thicker_than_the_field_is_refused(tmp_path):
    # the sample is a 2π-periodic box: tracers seeded ± thickness must fit in it
    thin = StudyConfig.from_scene(load_scene(None, {"piv.sheet_thickness": 3.0}))
    check_piv_scene(None, configs_from_study(thin)[0])
    scene = load_scene(None, {"piv.sheet_thickness": 10.0})
    with pytest.raises(RimclError, match=r"thicker than the field along x1 \(6.28319\).* 3.14"):
        check_piv_scene(None, configs_from_study(StudyConfig.from_scene(scene))[0])
    out = str(tmp_path / "x")
    result = CliRunner().invoke(cli, ["piv", "render", "--sheet-thickness", "10", "-o", out])
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "thicker" in result.output


def test_a_first_window_with_one_pass_is_refused(tmp_path):
    with pytest.raises(RimclError, match="needs 2 or more passes"):
        PivSettings(window=32, first_window=64, passes=1)
    assert PivSettings(window=32, first_window=64, passes=2).window_sizes() == [64, 32]
    from rimcl.piv.analysis import write_tiff

    path = tmp_path / "a.tif"
    write_tiff(path, np.zeros((64, 64)))
    args = ["piv", "analyze", str(path), str(path), "-o", str(tmp_path / "v.h5")]
    result = CliRunner().invoke(cli, [*args, "--passes", "1", "--first-window", "48"])
    assert result.exit_code == 1 and "needs 2 or more passes" in result.output


def test_ptv_options_in_piv_mode_are_named(tmp_path):
    args = ["study", "--out", str(tmp_path / "s"), "--mode", "piv", "--pixels", "256"]
    result = CliRunner().invoke(cli, [*args, "--fan", "4", "--scheduler", "local:0"])
    lines = result.output.strip().splitlines()
    assert lines[0].startswith("note: --fan, --pixels set the PTV cases"), result.output
    assert result.exit_code == 1 and len(lines) == 2


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("piv.bit_depth", 3, r"piv\.bit_depth .* at least 8"),
        ("piv.diameter", 0.1, r"piv\.diameter .* at least 1"),
    ],
)
def test_piv_frames_that_no_camera_records_are_refused(key, value, message):
    with pytest.raises(RimclError, match=message):
        load_scene(None, {key: value})


def test_piv_bit_depth_above_sixteen_is_refused():
    from rimcl.piv.imaging_config import PivImaging

    with pytest.raises(RimclError, match="bit depth must be 8 to 16, got 20"):
        PivImaging(bit_depth=20)
    with pytest.raises(RimclError, match="at least 1 pixel"):
        PivImaging(diameter=0.5)

"""LPT scenes that cannot give an answer are refused before any work, in one line: one
camera, coincident or near-coincident cameras, a calibration target the cameras do not
see; and ``rig.preset = ""`` with camera tables is the documented way to give them."""

import numpy as np
import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.lpt.config import parse_lpt_scene
from rimcl.scene.lpt_config import MIN_BASELINE_DEG, baseline_angles


def _camera(name, x2, sensor=(320, 200), x1=700.0):
    return {"name": name, "position_mm": [x1, x2, 50.0], "look_at_mm": [50.0, 50.0, 50.0],
            "focal_length_mm": 16.0, "f_number": 8.0, "sensor_pixels": list(sensor)}  # fmt: skip


def _scene(*cameras, **rig):
    return parse_lpt_scene({"rig": {"cameras": list(cameras), **rig}})


def test_an_empty_preset_with_camera_tables_is_accepted():
    scene = _scene(_camera("left", -300.0), _camera("right", 400.0), preset="")
    assert scene.rig.preset == "" and [c.name for c in scene.rig.cameras] == ["left", "right"]
    with pytest.raises(RimclError, match=r'rig.preset = "" needs \[\[rig.cameras\]\]'):
        parse_lpt_scene({"rig": {"preset": ""}})


def test_one_camera_is_refused_up_front():
    with pytest.raises(RimclError, match="LPT triangulates from two cameras at least, got one"):
        _scene(_camera("only", 0.0))


def test_coincident_and_near_coincident_cameras_are_refused_naming_the_angle():
    with pytest.raises(RimclError, match=r"0° apart at most \(a–b"):
        _scene(_camera("a", 50.0), _camera("b", 50.0))
    # 20 mm apart at 650 mm: 1.76° (atan(20/650)), under the 5° floor
    near = (_camera("a", 40.0), _camera("b", 60.0))
    angle = np.degrees(np.arctan2(10.0, 650.0)) * 2
    with pytest.raises(RimclError, match=rf"{angle:.3g}° apart at most .* {MIN_BASELINE_DEG:g}°"):
        _scene(*near)
    # the widest pair counts: a third camera far enough makes the rig usable
    scene = _scene(*near, _camera("c", 400.0))
    angles = baseline_angles(scene.rig.cameras)
    assert angles["a", "b"] == pytest.approx(angle, rel=1e-12)
    assert max(angles.values()) > MIN_BASELINE_DEG


def test_the_cli_refuses_before_writing_anything(tmp_path):
    scene = tmp_path / "one.toml"
    scene.write_text(
        '[[rig.cameras]]\nname = "only"\nposition_mm = [700.0, 0.0, 50.0]\n'
        "look_at_mm = [50.0, 50.0, 50.0]\n"
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["lpt", "run", str(scene), "-o", str(out)])
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1 and "two cameras" in result.output
    assert not out.exists()


def test_calibration_uses_only_the_points_every_camera_sees():
    """A small sensor images part of the target: the fit and the export take those points
    only (130 of 150 off the sensor were fitted); a 1 × 1 sensor sees too few: refused."""
    from rimcl.lpt.flow import Volume
    from rimcl.lpt.run import calibrate_rig, rig_cameras

    volume = Volume(np.zeros(3), np.ones(3), 1.0, np.array([0.35, 0.1, 0.25]),
                    np.array([0.65, 0.9, 0.75]), False)  # fmt: skip

    def calibrated(sensor):
        scene = _scene(_camera("left", -300.0), _camera("right", 400.0, sensor=sensor))
        cameras = rig_cameras(scene.rig, volume, 0.1, 1.333)
        return cameras, calibrate_rig(cameras, volume, scene.lpt)

    cameras, (full, _) = calibrated((320, 200))
    cameras, (target, fitted) = calibrated((120, 80))
    assert 40 <= len(target) < len(full)
    for camera, fit in zip(cameras, fitted, strict=True):
        np.testing.assert_array_equal(fit["pixels"], camera.project(target))
        columns, rows = fit["pixels"][:, 0], fit["pixels"][:, 1]
        assert np.all((columns >= -0.5) & (columns <= camera.pixels[0] - 0.5))
        assert np.all((rows >= -0.5) & (rows <= camera.pixels[1] - 0.5))
    with pytest.raises(RimclError, match=r"camera right images 1 of the 585 calibration points"):
        calibrated((1, 1))


def test_finite_rms_is_none_where_nothing_was_measured():
    """The pinhole baseline of a case that kept no tracer: None (was NaN, which JSON
    cannot hold)."""
    from rimcl.lpt.checks import finite_rms

    assert finite_rms(np.zeros((5, 0))) is None
    assert finite_rms(np.array([np.nan, 3.0, -4.0, np.nan])) == np.sqrt(12.5)


def test_a_dim_two_tracer_run_is_an_n_a_answer(tmp_path, lpt_flow):
    """Two tracers under cameras too dim for their threshold (100 peak electrons): no
    candidate pair to match, too few particles to self-calibrate, no tracer kept. It used
    to crash in matching (after the whole case) or on NaN in the JSON, leaving a case file
    without lpt_stats.json; now it exits 0 with every number n/a and says why."""
    import json

    cameras = "".join(
        f'[[rig.cameras]]\nname = "{name}"\nposition_mm = [700.0, {x2}, 50.0]\n'
        "look_at_mm = [50.0, 50.0, 50.0]\nfocal_length_mm = 16.0\nf_number = 8.0\n"
        "sensor_pixels = [320, 200]\n"
        for name, x2 in (("left", -300.0), ("right", 400.0))
    )
    scene = tmp_path / "dim.toml"
    scene.write_text(
        f'[field]\npath = "{lpt_flow}"\n[cases]\nnames = ["C3"]\n[tracers]\ncount = 2\n'
        '[time]\nframes = 5\n[sensor]\npeak_electrons = 100.0\n[run]\nengine = "numpy"\n'
        "[lpt]\ncalibration_grid = [6, 5]\nmax_rays = 4\n" + cameras
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["lpt", "run", str(scene), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "n/a: no tracer kept of 2" in result.output and "nan" not in result.output.lower()
    case = json.loads((out / "lpt_stats.json").read_text(), parse_constant=_no_nan)["cases"]["C3"]
    assert case["tracers_kept"] == 0 and case["no_tracer"].startswith("no tracer kept of 2")
    assert case["position"]["x2"]["refraction"]["rms"] is None
    assert "n/a" in case["self_calibration"]
    # the run's files and the output set's manifest (rimcl.core.outputs), nothing else
    assert sorted(p.name for p in out.iterdir()) == [
        ".rimcl-outputs.json",
        "lpt_case_C3.h5",
        "lpt_stats.json",
    ]
    # a study draws its figures from it: empty panels, no warning (errors under pytest)
    from rimcl.lpt.figures import write_lpt_figures

    document = json.loads((out / "lpt_stats.json").read_text())
    write_lpt_figures(document, tmp_path / "figures")
    assert any((tmp_path / "figures").iterdir())


def _no_nan(constant):
    raise AssertionError(f"{constant} in lpt_stats.json")


def test_calibration_lines_give_each_cameras_fit_residual():
    from rimcl.lpt.checks import calibration_lines

    case = {
        "calibration_residual_px": {
            "minus30": {"pinhole": 0.3104, "soloff": 0.00612},
            "plus30": {"pinhole": 0.2981, "soloff": None},
        }
    }
    assert calibration_lines(case) == [
        "  calibration fit residual per camera (px): minus30 pinhole 0.31, Soloff 0.00612; "
        "plus30 pinhole 0.298, Soloff n/a"
    ]
    assert calibration_lines({}) == []

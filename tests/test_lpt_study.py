"""``rimcl study`` with run.mode = "lpt": the scene table lists the LPT sections, the study
runs the LPT chain, writes its statistics, figures and summary, and keeps them on a rerun."""

import dataclasses
import json

import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.lpt.config import CameraSpec, IlluminationConfig, LptSettings, RigConfig
from rimcl.lpt.figures import FIGURE_NAMES
from rimcl.lpt.sensitivity import HEADLINES
from rimcl.scene.keys import SCENE_KEYS
from rimcl.scene.keys_lpt import camera_keys
from rimcl.scene.load import default_scene_text, load_scene
from rimcl.scene.study_config import StudyConfig


def test_scene_table_lists_the_lpt_keys_with_the_stage_defaults():
    text = default_scene_text()
    for section in ("[rig]", "[illumination]", "[lpt]"):
        assert section in text
    configs = {"rig": RigConfig(), "illumination": IlluminationConfig(), "lpt": LptSettings()}
    listed = {(k.section, k.name) for k in SCENE_KEYS if k.section in configs}
    for section, config in configs.items():
        fields = {f.name for f in dataclasses.fields(config)}
        assert {name for s, name in listed if s == section} == fields
        for key in (k for k in SCENE_KEYS if k.section == section):
            default = getattr(config, key.name)
            if key.default is not None and key.name != "cameras":
                expected = list(default) if isinstance(default, tuple) else default
                assert key.default == expected, key.dotted
    camera_fields = {f.name for f in dataclasses.fields(CameraSpec)}
    assert camera_fields == {key.name for key in camera_keys()}
    lpt = StudyConfig.from_scene(load_scene()).lpt
    assert lpt.rig == RigConfig() and lpt.settings == LptSettings()
    assert lpt.illumination == IlluminationConfig()


def test_unknown_and_bad_lpt_keys_are_refused(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("[lpt]\nself_calibraton = true\n")
    with pytest.raises(RimclError, match="did you mean 'self_calibration'"):
        load_scene(path)
    path.write_text('[run]\nmode = "lpt"\n[rig]\npreset = "stero"\n')
    with pytest.raises(RimclError, match=r"rig\.preset"):
        load_scene(path)
    path.write_text("[illumination]\nextent = [0.5, true]\n")
    with pytest.raises(RimclError, match=r"illumination\.extent"):
        load_scene(path)
    path.write_text('[rig]\ncameras = [{ name = "a" }]\n')
    with pytest.raises(RimclError, match="needs position_mm"):
        StudyConfig.from_scene(load_scene(path))
    # camera tables without a preset: the study runs them (as rimcl lpt does); with one,
    # the scene is refused
    table = "[[rig.cameras]]\nposition_mm = [700, 50, 50]\nlook_at_mm = [50, 50, 50]\n"
    path.write_text(table + table.replace("[700, 50, 50]", "[700, 400, 50]"))  # two: LPT's least
    rig = StudyConfig.from_scene(load_scene(path)).lpt.rig
    assert rig.preset == "" and [c.name for c in rig.cameras] == ["cam1", "cam2"]
    assert rig.cameras[0].position_mm == (700.0, 50.0, 50.0)
    assert rig.cameras[0].sensor_pixels == (1920, 1200)
    path.write_text('[rig]\npreset = "stereo"\n' + table)
    with pytest.raises(RimclError, match="not both"):
        StudyConfig.from_scene(load_scene(path), str(path))
    path.write_text(table.replace("[50, 50, 50]", "[50, 50, inf]"))
    with pytest.raises(RimclError, match=r"rig\.cameras\[0\]\.look_at_mm in .* three numbers"):
        StudyConfig.from_scene(load_scene(path))
    path.write_text(table + "sensor_pixel = [2, 2]\n")
    with pytest.raises(RimclError, match="did you mean 'sensor_pixels'"):
        StudyConfig.from_scene(load_scene(path))


def test_study_runs_lpt(tmp_path, lpt_flow):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'[field]\npath = "{lpt_flow}"\n[cases]\nnames = ["C1", "C3"]\n[tracers]\ncount = 20\n'
        '[time]\nframes = 5\n[run]\nmode = "lpt"\n'
        "[lpt]\ncalibration_grid = [6, 5]\nmax_rays = 4\nself_calibration_cells = [1, 2, 2]\n"
        "[illumination]\nextent = [0.5, 0.5]\n"
        '[rig]\npreset = "stereo"\n'
    )
    out = tmp_path / "study"
    result = CliRunner().invoke(cli, ["study", str(scene), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "C3: n_ref" in result.output
    stats = json.loads((out / "stats.json").read_text())
    cases = stats["lpt"]["cases"]
    assert set(cases) == {"C1", "C3"}
    # a stronger case refracts more: its position error grows with G
    for axis in ("x1", "x2", "x3"):
        c1, c3 = (cases[c]["position"][axis]["refraction"]["rms"] for c in ("C1", "C3"))
        assert c3 > 5 * c1
    assert cases["C3"]["abscissa"]["name"] == "G"
    assert cases["C3"]["self_calibration"]["cells_used"] >= 1
    for name in FIGURE_NAMES:
        for extension in ("png", "pdf", "json"):
            assert (out / "figures" / f"{name}.{extension}").is_file()
    summary = (out / "summary.md").read_text()
    # Markdown, as the PTV summary: a heading and a table per case, not a terminal dump
    assert summary.startswith("# LPT study") and "```" not in summary
    assert "## C3" in summary and "| position refraction rms (px) |" in summary
    # each case's calibration fit residual of each camera's models, as in stats.json
    lines = [s for s in summary.splitlines() if "calibration fit residual per camera" in s]
    assert len(lines) == 2
    for line, case in zip(lines, cases.values(), strict=True):
        assert len(case["calibration_residual_px"]) == 2
        for name, fits in case["calibration_residual_px"].items():
            assert f"{name} pinhole {fits['pinhole']:.3g}, Soloff {fits['soloff']:.3g}" in line
            assert 0 < fits["soloff"] < fits["pinhole"]  # the window: a pinhole misses it
    # every headline number has its threshold band and verdict, in the file and the summary
    for case in cases.values():
        assert set(case["sensitivity"]["bands"]) == set(HEADLINES)
    for group in ("position", "velocity", "acceleration"):
        assert summary.count(f"threshold ×½/×2 band, {group}**: x1 ") == 2
    assert (out / "lpt" / "lpt_case_C3.h5").is_file()
    again = CliRunner().invoke(cli, ["study", str(scene), "--out", str(out)])
    assert again.exit_code == 0, again.output
    assert "finished earlier, kept" in again.output
    assert "0 cases measured, 2 kept" in again.output  # was "0 cases measured, 0 kept"


@pytest.mark.parametrize("mode", ["lpt", "piv"])
def test_sensitivity_where_no_ptv_case_runs_is_refused(tmp_path, mode):
    """The sensitivity variants re-measure PTV cases: asked for in a mode without any, the
    study refuses in one line before writing, instead of silently measuring none."""
    from rimcl.study.run import run_study

    scene = load_scene(None, {"run.mode": mode, "run.sensitivity": True})
    with pytest.raises(RimclError, match=f'run.mode = "{mode}" has none'):
        run_study(scene, tmp_path / "out")
    assert not (tmp_path / "out").exists()

"""One rule for scene keys a command does not use (:mod:`rimcl.scene.usage`): refused across
the planar and LPT kinds, named in a note within the planar kind, options a camera ignores
refused; the same scene file behaves the same in every command. Every refusal comes before
any work (no output is written)."""

import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.scene.keys import SCENE_KEYS
from rimcl.scene.load import default_scene_text, load_scene, scene_text
from rimcl.scene.usage import COMMANDS, check_use, users

#: keys ``rimcl lpt run`` silently ignored (bit-identical outputs) before the rule
LPT_IGNORED = """
[field]
box = [[0.0, 3.0], [0.0, 3.0], [0.0, 3.0]]
depth = 1.0
x_sheet = 1.0
[cases]
names = ["C1"]
thresholds = { C1 = 50.0 }
[tracers]
margin = 0.2
[time]
frames = 5
dt_multiples = [1, 2]
[run]
sensitivity = true
scheduler = "local:2"
numerics = false
ray_sample = 100
"""
LPT_SECTIONS = '[rig]\npreset = "stereo"\n[lpt]\nmax_rays = 4\n[illumination]\nthickness = 0.5\n'


def _run(tmp_path, *args):
    result = CliRunner().invoke(cli, [str(arg) for arg in args])
    return result, sorted(p.name for p in tmp_path.iterdir())


def _names(text):
    return [name for name in (k.dotted for k in SCENE_KEYS) if name in text]


@pytest.mark.parametrize("command", [["lpt", "run"], ["lpt", "render"]])
def test_lpt_refuses_every_key_it_used_to_ignore(tmp_path, command):
    scene = tmp_path / "lpt.toml"
    scene.write_text(LPT_IGNORED)
    result, files = _run(tmp_path, *command, scene, "-o", tmp_path / "out")
    assert result.exit_code == 1 and "Traceback" not in result.output
    line = result.output.strip().splitlines()[-1]
    listed = line.split(" does not use ")[1]
    for name in ("field.box", "field.depth", "field.x_sheet", "cases.thresholds"):
        assert name in listed
    assert "and 2 more" in listed  # ten keys, one line
    assert files == ["lpt.toml"]
    one = tmp_path / "one.toml"
    one.write_text("[tracers]\nmargin = 0.2\n")
    result, _ = _run(tmp_path, *command, one, "-o", tmp_path / "out")
    assert "rimcl lpt does not use tracers.margin (set in" in result.output
    assert "remove it" in result.output


@pytest.mark.parametrize("command", [["render"], ["piv", "render"], ["trace"]])
def test_planar_commands_refuse_the_lpt_sections(tmp_path, command):
    scene = tmp_path / "rig.toml"
    scene.write_text(LPT_SECTIONS)
    result, files = _run(tmp_path, *command, scene, "-o", tmp_path / "out")
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert _names(result.output) == ["rig.preset", "illumination.thickness", "lpt.max_rays"]
    assert "used by rimcl lpt run/render, rimcl study --mode lpt" in result.output
    assert files == ["rig.toml"]


def test_study_and_lpt_run_refuse_the_same_key_alike(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[run]\nsensitivity = true\n")
    lpt, _ = _run(tmp_path, "lpt", "run", scene, "-o", tmp_path / "out")
    study, files = _run(tmp_path, "study", scene, "--mode", "lpt", "--out", tmp_path / "st")
    for result in (lpt, study):
        assert result.exit_code == 1
        assert "does not use run.sensitivity" in result.output
    assert "rimcl study --mode lpt does not use" in study.output
    # an option is held to the same rule, and named as the options
    fan, _ = _run(tmp_path, "study", "--mode", "lpt", "--fan", 8, "--out", tmp_path / "st")
    assert "does not use camera.fan (set in the options" in fan.output
    assert files == ["s.toml"]


@pytest.mark.parametrize(
    ("command", "key"),
    [(["piv", "render"], "piv.pixels"), (["render"], "renderer.pixels")],
)
def test_pixels_under_the_lens_camera_are_refused(tmp_path, command, key):
    # the lens camera's frames are its sensor's (2048² by default): --pixels was ignored
    result, files = _run(tmp_path, *command, "--pixels", 512, "-o", tmp_path / "out")
    assert result.exit_code == 1
    assert f"the lens camera (camera.kind) does not use {key}" in result.output
    assert "camera.sensor_pixels" in result.output
    assert files == []


def test_a_file_key_the_command_ignores_is_noted():
    scene = load_scene()
    scene["piv"]["pixels"] = 256
    given = {"piv.pixels": "scene.toml"}
    note = check_use(scene, given, "render")
    assert note.startswith("note: rimcl render does not use piv.pixels (set in scene.toml")
    lens = "note: the lens camera (camera.kind) does not use piv.pixels (set in scene.toml)"
    assert check_use(scene, given, "piv") == lens
    assert check_use(scene, given, "study") == lens
    scene["camera"]["kind"] = "plane"
    assert check_use(scene, given, "piv") is None
    assert check_use(scene, given, "study") is None  # the study measures PIV in a mode


@pytest.mark.parametrize("command", list(COMMANDS))
def test_complete_scenes_run_everywhere(tmp_path, command):
    # every key at its default (the printed scene, a study's scene.toml): nothing refused
    printed = tmp_path / "default.toml"
    printed.write_text(default_scene_text())
    recorded = tmp_path / "scene.toml"
    recorded.write_text(scene_text(load_scene()))
    for path in (printed, recorded):
        load_scene(path, command=command, report=pytest.fail)


def test_every_key_has_users():
    for key in SCENE_KEYS:
        assert users(key) and users(key) <= set(COMMANDS), key.dotted
    with pytest.raises(ValueError):
        check_use(load_scene(), {}, "renderr")


def test_an_lpt_scene_names_its_field_relative_to_itself(tmp_path, monkeypatch):
    from rimcl.lpt.config import load_lpt_scene

    (tmp_path / "sub").mkdir()
    scene = tmp_path / "sub" / "lpt.toml"
    scene.write_text('[field]\npath = "flow.h5"\n')
    monkeypatch.chdir(tmp_path)
    parsed = load_lpt_scene(scene, {"tracers.count": 7})
    assert parsed.study.field_path == str(tmp_path / "sub" / "flow.h5")
    assert parsed.measure.tracers.count == 7
    with pytest.raises(RimclError, match=r"tracers\.margin \(set in the options"):
        load_lpt_scene(scene, {"tracers.margin": 0.2})


def _options_by_key(*path):
    """``{scene key: option}`` of a command, from the keys its options name in brackets."""
    import re

    import click

    command = cli
    for name in path:
        command = command.get_command(click.Context(command), name)
    found = {}
    for param in command.params:
        for key in re.findall(r"\[([a-z]+\.[a-z0-9_]+)", getattr(param, "help", None) or ""):
            found.setdefault(key, param.opts[-1])
    return found


def test_the_same_key_has_the_same_option_everywhere():
    commands = [("study",), ("render",), ("piv", "render"), ("piv", "sequence"), ("lpt", "run")]
    options = {path: _options_by_key(*path) for path in commands}
    for key in {key for found in options.values() for key in found}:
        names = {found[key] for found in options.values() if key in found}
        assert len(names) == 1, (key, names)
    # the options a new user looked for (issue 32): study --time-s, lpt run --tracers
    assert options[("study",)]["field.time_s"] == "--time-s"
    assert options[("lpt", "run")]["tracers.count"] == "--tracers"
    assert options[("lpt", "run")]["field.time_s"] == "--time-s"


@pytest.mark.parametrize("command", [["study"], ["render"], ["piv", "render"]])
def test_step_is_a_number_on_every_measuring_command(tmp_path, command):
    result, files = _run(tmp_path, *command, "--step", "auto")
    assert result.exit_code == 2 and "rimcl trace --step auto" in result.output
    assert files == []

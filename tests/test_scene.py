"""Scene files: defaults, round trips, and one clear error per mistake."""

import pytest

from rimcl.core.errors import RimclError
from rimcl.scene.config import MeasureConfig
from rimcl.scene.keys import SCENE_KEYS, default_scene
from rimcl.scene.load import default_scene_text, load_scene, scene_text
from rimcl.scene.validate import validate_scene


def test_printed_default_scene_documents_every_key_and_reads_back_as_the_default(tmp_path):
    text = default_scene_text()
    for key in SCENE_KEYS:
        assert f"[{key.section}]" in text
        assert f"{key.name} = " in text
    path = tmp_path / "default.toml"
    path.write_text(text)
    # every key as printed, and field.time_s as the shipped sample records it
    expected = default_scene()
    assert expected["field"]["time_s"] is None
    expected["field"]["time_s"] = 0.28
    assert load_scene(path) == expected
    assert load_scene() == expected


def test_scene_text_round_trips_a_changed_scene(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(
        '[cases]\nnames = ["C1", "g=0.01"]\nthresholds = { c1 = 60 }\n'
        '[camera]\nkind = "pupil"\naperture_diameter = 1.5\n[renderer]\npixels = 2048\n'
    )
    scene = load_scene(path)
    assert scene["cases"]["names"] == ["C1", "G=0.01"]
    assert scene["cases"]["thresholds"] == {"C1": 60.0}
    assert scene["camera"]["aperture_diameter"] == 1.5
    assert scene["renderer"]["pixels"] == 2048
    assert scene["tracers"]["count"] == default_scene()["tracers"]["count"]
    again = tmp_path / "again.toml"
    again.write_text(scene_text(scene))
    assert load_scene(again) == scene


def test_overrides_win_and_none_means_not_given(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("[tracers]\ncount = 50\nseed = 3\n")
    scene = load_scene(path, {"tracers.count": 7, "tracers.seed": None, "camera.fan": 5})
    assert (scene["tracers"]["count"], scene["tracers"]["seed"]) == (7, 3)
    assert scene["camera"]["fan"] == 5


def test_relative_field_path_is_relative_to_the_scene_file(tmp_path):
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "scene.toml"
    path.write_text('[field]\npath = "flow.h5"\n')
    assert load_scene(path)["field"]["path"] == str(tmp_path / "sub" / "flow.h5")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[camra]\nfan = 3\n", r"unknown section \[camra\].*did you mean 'camera'\?"),
        ("[camera]\nfann = 3\n", r"unknown key camera.fann.*did you mean 'fan'\?"),
        ("[camera]\npixels = 3\n", r"unknown key camera.pixels.*did you mean 'renderer.pixels'\?"),
        ('[camera]\nkind = "pupill"\n', r"camera.kind .* one of plane, pupil.*'pupil'\?"),
        ("[tracers]\ncount = 0\n", r"tracers.count .* must be positive"),
        ("[tracers]\ncount = 2.5\n", r"tracers.count .* whole number"),
        ('[tracers]\ncount = "many"\n', r"tracers.count .* must be a number"),
        ("[renderer]\nthreshold = -1.0\n", r"renderer.threshold .* at least 0"),
        ("[cases]\nnames = []\n", r"at least one case"),
        ('[cases]\nnames = ["C1", "c1"]\n', r"names case C1 more than once"),
        ('[cases]\nnames = ["C5"]\n', r"unknown case 'C5'.*did you mean 'C[0-4]'\?"),
        ('[cases]\nnames = ["C1"]\nthresholds = { C4 = 50 }\n', r"names C4, which cases.names"),
        ("[camera\n", r"not valid TOML"),
    ],
)
def test_mistakes_get_one_clear_error(tmp_path, text, message):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(RimclError, match=message):
        load_scene(path)


def test_missing_scene_file(tmp_path):
    with pytest.raises(RimclError, match="cannot read scene file"):
        load_scene(tmp_path / "absent.toml")


def test_measure_config_maps_every_scene_choice():
    scene = validate_scene(
        {
            "cases": {"names": ["C1", "C4"], "thresholds": {"C4": 40.0}},
            "field": {"path": "/data/flow.h5", "depth": 2.0},
            "integrator": {"step": 0.02},
            "run": {"device": "pocl"},
        }
    )
    air, water = MeasureConfig.from_scene(scene, "C1"), MeasureConfig.from_scene(scene, "C4")
    assert air.renderer.threshold == default_scene()["renderer"]["threshold"]
    assert water.renderer.threshold == 40.0
    assert (air.depth, air.integrator.step, air.run.device) == (2.0, 0.02, "pocl")
    assert air.time.frames == default_scene()["time"]["frames"]
    default = MeasureConfig.from_scene(default_scene(), "C0")
    assert default.run.device is None
    assert default.camera.fan == default_scene()["camera"]["fan"]
    assert default.tracers.count == default_scene()["tracers"]["count"]

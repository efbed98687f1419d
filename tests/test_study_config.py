"""StudyConfig: a scene parsed once into the typed configuration every study stage takes."""

import json
import pickle

import pytest

from rimcl.scene.config import MeasureConfig
from rimcl.scene.load import load_scene, scene_text
from rimcl.scene.study_config import StudyConfig


@pytest.fixture(scope="module", params=[None, "paper"])
def scene(request):
    overrides = {"cases.names": ["C0", "C3", "G=0.01"], "run.mode": "both", "piv.rays": 9}
    return load_scene(None, overrides, preset=request.param)


def test_each_case_gets_the_configuration_the_scene_gives_it(scene):
    study = StudyConfig.from_scene(scene)
    assert study.names == ["C0", "C3", "G=0.01"]
    # the paper preset: 100 counts for C0, 500 for C3; the default scene: one threshold
    for name in [*study.names, "delta_n"]:
        assert study.measure(name) == MeasureConfig.from_scene(scene, name)
    thresholds = {case.name: case.threshold for case in study.cases}
    if scene["cases"]["thresholds"]:
        assert thresholds == {"C0": 100.0, "C3": 500.0, "G=0.01": 100.0}
    else:
        assert set(thresholds.values()) == {scene["renderer"]["threshold"]}
    assert study.run.mode == "both" and study.piv.rays == 9
    # unset: every m the frames allow
    assert scene["time"]["dt_multiples"] is None
    assert study.dt_multiples == tuple(range(1, scene["time"]["frames"]))


def test_the_scene_record_and_text_are_the_scenes(scene):
    study = StudyConfig.from_scene(scene)
    assert study.scene_record() == json.loads(json.dumps(scene))
    assert study.text == scene_text(scene)
    # a fresh copy each time: a record changed by its user leaves the study as it was
    study.scene_record()["tracers"]["count"] = -1
    assert study.scene_record()["tracers"]["count"] == scene["tracers"]["count"]


def test_a_study_travels_to_dask_workers_and_back_from_scene_toml(scene, tmp_path):
    study = StudyConfig.from_scene(scene)
    assert pickle.loads(pickle.dumps(study)) == study
    assert pickle.loads(pickle.dumps(study.measure("C3"))) == study.measure("C3")
    path = tmp_path / "scene.toml"
    path.write_text(study.text)
    assert StudyConfig.from_scene(load_scene(path)) == study


def test_run_study_takes_a_scene_file_or_a_study_alike(device, tmp_path):
    from rimcl.study.run import run_study

    tiny = {"cases.names": ["C0", "C4"], "tracers.count": 4, "camera.fan": 4}
    path = tmp_path / "tiny.toml"
    path.write_text(scene_text(load_scene(None, {**tiny, "run.device": device.name})))
    first = run_study(path, tmp_path / "out", figures=False)
    assert first.ran == ["C0", "C4"]
    assert (tmp_path / "out" / "scene.toml").read_text() == path.read_text()
    again = run_study(StudyConfig.from_scene(load_scene(path)), tmp_path / "out", figures=False)
    assert again.ran == [] and again.skipped == ["C0", "C4"] and not again.stats_redone

"""The default study's scene: a physical lens camera; the paper's fan is a preset."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.fields.sample import SAMPLE_LENGTH_M
from rimcl.optics.camera import LensCamera, PlaneCamera, Scene
from rimcl.scene.config import MeasureConfig
from rimcl.scene.load import load_scene

SAMPLE_SCENE = Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), True)


def _camera(scene, case="C4", medium_index=1.33):
    return MeasureConfig.from_scene(scene, case).camera.build(SAMPLE_SCENE, medium_index)


def test_the_default_is_a_real_lens_behind_a_wall():
    scene = load_scene()
    camera = _camera(scene)
    assert isinstance(camera, LensCamera)
    assert camera.numerical_aperture <= 0.05
    assert camera.numerical_aperture == pytest.approx(0.0104, abs=2e-4)
    # the fluid/air interface (and a glass wall): the focus lies inside the water
    assert camera.window is not None and camera.window.thickness_mm > 0
    assert camera.focus_x1 > SAMPLE_SCENE.x_sheet
    # the sample's 2π box is the sensor's field of view, 32.5 µm pixels on the sheet
    assert camera.sensor_fov == pytest.approx(np.full(2, 2 * np.pi))
    assert camera.pixel_size * SAMPLE_LENGTH_M == pytest.approx(32.5e-6)
    assert scene["mie"]["enabled"] and scene["sensor"]["noise"]


def test_the_paper_preset_is_the_fan_with_mie_weights():
    scene = load_scene(preset="paper")
    assert isinstance(_camera(scene), PlaneCamera)
    assert scene["camera"]["fan"] == 100
    assert scene["mie"]["enabled"] and scene["mie"]["diameter_um"] == 10.0
    assert not scene["sensor"]["noise"] and scene["renderer"]["bit_depth"] == 10


def test_a_fan_alone_asks_for_the_plane_camera():
    assert load_scene(overrides={"camera.fan": 8})["camera"]["kind"] == "plane"
    both = load_scene(overrides={"camera.fan": 8, "camera.kind": "pupil"})
    assert both["camera"]["kind"] == "pupil"


def test_another_field_needs_its_size_for_the_lens(tmp_path):
    scene = load_scene(overrides={"field.path": str(tmp_path / "flow.h5")})
    with pytest.raises(RimclError, match=r"needs the field's physical size: give field\.length_m"):
        _camera(scene)

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
    # 50 mm at f/11, 300 mm from the sheet: NA = sin(atan((50 / 11 / 2) / 300))
    assert camera.numerical_aperture == pytest.approx(np.sin(np.arctan(25 / 11 / 300)), rel=1e-12)
    # the fluid/air interface (and a glass wall): the focus lies inside the water
    assert camera.window is not None and camera.window.thickness_mm > 0
    assert camera.focus_x1 > SAMPLE_SCENE.x_sheet
    # the sample's 2π box is the sensor's field of view, 32.5 µm pixels on the sheet
    assert camera.sensor_fov == pytest.approx(np.full(2, 2 * np.pi))
    assert camera.pixel_size * SAMPLE_LENGTH_M == pytest.approx(32.5e-6)
    assert scene["mie"]["enabled"] and scene["sensor"]["noise"]


def test_the_default_lens_makes_tracer_images_that_do_not_peak_lock():
    """10 µm tracers at M = 0.2, 532 nm, f/11: d = hypot(2 µm, 2.44 · 1.2 · 0.532 · 11 µm)
    = 17.25 µm, 2.65 px of 6.5 µm, above the summary's own peak-locking limit (f/8: 1.94 px)."""
    from rimcl.study.answer import PEAK_LOCKING_PX

    camera = _camera(load_scene())
    diameter_um = np.hypot(0.2 * 10.0, 2.44 * 1.2 * 0.532 * 11.0)
    assert camera.image_diameter_um == pytest.approx(diameter_um, rel=1e-12)
    assert 4 * camera.psf_sigma_px == pytest.approx(diameter_um / 6.5, rel=1e-12)
    assert 4 * camera.psf_sigma_px >= 2.5 > PEAK_LOCKING_PX
    f8 = _camera(load_scene(overrides={"camera.f_number": 8.0}))
    assert 4 * f8.psf_sigma_px < PEAK_LOCKING_PX


def test_the_sample_carries_a_time_scale_that_a_scene_overrides():
    """The sample's time unit is L0² / (Re ν) for water at 20 °C (ν = 1.0034e-6 m²/s) in its
    66.6 mm box, rounded to 0.28 s; its arrays are untouched, the scales are attributes."""
    import h5py

    from rimcl.fields.sample import sample_path

    with h5py.File(sample_path(), "r") as h5:
        assert h5.attrs["time_s"] == 0.28
        assert h5.attrs["length_m"] == SAMPLE_LENGTH_M
        reynolds = float(h5.attrs["reynolds"])
    assert SAMPLE_LENGTH_M**2 / (reynolds * 1.0034e-6) == pytest.approx(0.28, rel=2e-3)
    assert load_scene()["field"]["time_s"] == 0.28
    assert load_scene(overrides={"field.time_s": 0.5})["field"]["time_s"] == 0.5
    by_velocity = load_scene(overrides={"field.length_m": 0.01, "field.velocity_m_s": 0.02})
    assert by_velocity["field"]["time_s"] == pytest.approx(0.5)


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

"""The device engine through a lens camera, with and without a flat window.

Both engines image the shipped sample through the same :class:`rimcl.optics.camera.LensCamera`:
the device makes the initial directions (behind a window: the same Newton solve as
``LensCamera.directions``), refracts the exit rays at both window faces, tests them
against the pupil and back-projects them onto the focus plane in ``cl/fan.cl``. Flags, ray
counts and areas must agree exactly; centroids to the last bit where the frame images
agree (else within 1e-3 px); the optics columns within 1e-9 px; the ray sample exactly.
"""

import dataclasses

import numpy as np
import pytest
from test_engine import assert_engines_agree

import rimcl
from rimcl.imaging.centroid import TracerFlag
from rimcl.imaging.engine import DeviceEngine
from rimcl.optics.camera import FlatWindow, LensCamera, Scene
from rimcl.optics.trace import _validate_rays
from rimcl.ptv.measure import run_render
from rimcl.scene.config import MeasureConfig, RendererConfig

# 6.5 µm pixels at M = 0.2 on a 1024-px sensor span the sample's 2π box
LENGTH_M = 32.5e-6 * 1024 / (2 * np.pi)
SMALL = {"tracers": 4, "pupil_rays": 64, "psf_sigma": 2.0, "ray_sample": 64}


def _config(engine, device, window_mm, fluid_index, **options):
    options = {**SMALL, "camera": "lens", "engine": engine, "device": device, **options}
    config = MeasureConfig.from_options(frame_image=True, **options)
    camera = dataclasses.replace(
        config.camera,
        length_m=LENGTH_M,
        magnification=0.2,
        sensor_pixels=(1024, 1024),
        window_thickness_mm=window_mm,
        window_index=1.52,
        outside_index=1.0,
        fluid_index=fluid_index,
    )
    return dataclasses.replace(config, camera=camera)


@pytest.mark.parametrize(
    ("case", "window_mm", "fluid_index", "options"),
    [
        ("C1", 0.0, 1.0, {"renderer": "exact", "bit_depth": 10}),
        ("C3", 0.0, 1.0, {"renderer": "paper", "bit_depth": 16}),
        ("C1", 5.0, 1.0, {"renderer": "paper", "bit_depth": 10}),
        ("C3", 3.0, 1.335, {"renderer": "exact", "bit_depth": 16}),
        ("C3", 5.0, 1.0, {"renderer": "paper", "bit_depth": 16, "centroid_weights": "grey"}),
        # the rays aimed through a strong field (rimcl.optics.aiming): the same aim on both
        ("C4", 10.0, 1.335, {"renderer": "exact", "bit_depth": 12, "threshold": 200.0}),
    ],
)
def test_lens_measurement_matches_the_numpy_engine(device, case, window_mm, fluid_index, options):
    numpy_result, device_result = (
        run_render(
            None, case=case, config=_config(engine, device, window_mm, fluid_index, **options)
        )
        for engine in ("numpy", "device")
    )
    assert device_result.config["engine"] == "device"
    assert numpy_result.attrs["camera"] == "lens"
    assert_engines_agree(numpy_result, device_result)
    if case == "C4":  # aimed through the strong field, the rim of the cone misses the pupil
        assert np.bitwise_or.reduce(numpy_result.tracers["flags_meas"]) & TracerFlag.RAYS_VIGNETTED
        assert not numpy_result.rays["collected"].all()


def _scene():
    return Scene(0.0, 2 * np.pi, np.zeros(2), np.full(2, 2 * np.pi), True)


@pytest.mark.parametrize(
    ("f_number", "window", "fluid_index"),
    [
        (8.0, None, 1.0),
        (8.0, FlatWindow(5.0, 1.52, 1.0), 1.0),
        (1.4, FlatWindow(20.0, 1.52, 1.0003), 1.335),
    ],
)
def test_device_directions_are_the_hosts(device, f_number, window, fluid_index):
    """The fan kernel traces the very directions LensCamera.directions and trace_rays make."""
    scene = _scene()
    camera = LensCamera(
        scene,
        LENGTH_M,
        magnification=0.2,
        f_number=f_number,
        pixels=(1024, 1024),
        window=window,
        fluid_index=fluid_index,
        rays=256,
    )
    imaging = RendererConfig(psf_sigma=2.0).build(scene, camera)
    tracers = np.random.default_rng(5).uniform(0.1, 2 * np.pi - 0.1, size=(16, 2))
    tracers[0] = scene.fov_centre  # on the lens axis: the ray along it has no lateral run
    engine = DeviceEngine(camera, scene, imaging, device, len(tracers))
    field = rimcl.Field.from_arrays(
        np.zeros((8, 8, 8)), spacing=(2 * np.pi / 8,) * 3, n_ref=fluid_index, boundary="periodic"
    )
    options = {"step": None, "interp": "trilinear", "precision": "f32"}
    got = engine.initial_directions(field, options, tracers)
    starts = np.repeat(scene.in_sheet(tracers), camera.rays_per_tracer, axis=0)
    _, expected = _validate_rays(starts, camera.directions(tracers).reshape(-1, 3))
    np.testing.assert_array_equal(got.reshape(-1, 3), expected)


def test_ray_aiming_is_per_tracer_so_shards_give_the_whole_runs_numbers(device):
    """Each tracer's aim is found from its own chief rays: measured in two shards, C4
    through the default lens gives the whole run's rows to the last bit."""
    from rimcl.ptv.render_file import merge_results
    from rimcl.scene.load import load_scene
    from rimcl.scene.study_config import StudyConfig

    overrides = {
        "tracers.count": 6,
        "camera.pupil_rays": 16,
        "time.frames": 3,
        "run.device": device.name,
    }
    config = StudyConfig.from_scene(load_scene(None, overrides)).measure("C4")
    whole = run_render(None, case="C4", config=config)
    merged = merge_results(
        [run_render(None, case="C4", config=config, shard=s) for s in ((0, 2), (2, 6))]
    )
    for name, values in whole.tracers.items():
        np.testing.assert_array_equal(merged.tracers[name], values, err_msg=name)

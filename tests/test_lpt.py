"""LPT: rig geometry, calibration, triangulation and the must-hold comparisons.

- Uniform medium, chief rays: image points equal the pinhole-plus-window projection of the
  truth to 1e-9 L; triangulated positions equal the truth within the calibration residual.
- Linear medium n = n0 + g x2: the 3-D error equals the least-squares intersection of the
  cameras' exit rays traced in float64 (straight back-extensions from the exit face) within
  2 %.
- A turbulent field (the shipped sample at C3): the same comparison per tracer within 5 % of
  the error's rms.
- Device and NumPy float64 engines agree.
"""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.fields.field import analytic_field
from rimcl.lpt.calibration import (
    PinholeModel,
    SoloffModel,
    calibrate,
    intersect,
    target_points,
    triangulate,
)
from rimcl.lpt.config import RigConfig, parse_lpt_scene
from rimcl.lpt.flow import Volume
from rimcl.lpt.run import rig_cameras
from rimcl.lpt.views import Tracer, chief_targets, view
from rimcl.optics.reference import sample_field, trace_rays_reference

N0 = 1.333
LENGTH_M = 0.1  # the unit cube is 100 mm, the challenge's width


def _volume():
    return Volume(
        lo=np.zeros(3),
        hi=np.ones(3),
        x_end=1.0,
        seed_lo=np.array([0.35, 0.1, 0.25]),
        seed_hi=np.array([0.65, 0.9, 0.75]),
        periodic=False,
    )


def _cameras(fluid_index=N0, preset="lpt-challenge"):
    return rig_cameras(RigConfig(preset=preset), _volume(), LENGTH_M, fluid_index)


def _tracers(count=12, seed=3):
    volume = _volume()
    return volume.seed(count, np.random.default_rng(seed))


def _box_field(kind, **params):
    return analytic_field(kind, box_lo=[-1.0, -2.0, -2.0], box_hi=[2.0, 3.0, 3.0], **params)


def _models(cameras, kind="soloff", volume=None):
    volume = volume or _volume()
    margin = 0.05 * (volume.seed_hi - volume.seed_lo)
    target = target_points(volume.seed_lo - margin, volume.seed_hi + margin, 5, (13, 9))
    return [calibrate(camera, target, kind) for camera in cameras]


def test_preset_geometry():
    cameras = _cameras()
    assert [c.name for c in cameras] == ["cam1", "cam2", "cam3", "cam4"]
    centre = 0.5 * (_volume().seed_lo + _volume().seed_hi)
    for camera, angle in zip(cameras, (-30, -10, 10, 30), strict=True):
        # the look-at point images to the sensor centre; the axis has the preset's angle
        np.testing.assert_allclose(camera.project(centre[None])[0], [959.5, 599.5], atol=1e-9)
        assert np.degrees(np.arctan2(-camera.forward[1], -camera.forward[0])) == pytest.approx(
            angle
        )
        # the field's 100 mm width fills 96 % of the 19.2 mm sensor: M = 0.18432
        assert camera.magnification == pytest.approx(0.96 * 19.2 / 100.0)
        distance = np.linalg.norm(camera.position - centre) * LENGTH_M * 1e3
        assert 500 < distance < 700  # the challenge's ~600 mm
    assert len(_cameras(preset="stereo")) == 2


def test_dlt_is_exact_for_a_bare_pinhole():
    # no window, fluid index 1: a camera is an exact pinhole, the DLT fits to rounding
    rig = RigConfig(window_thickness_mm=0.0, outside_index=1.0)
    camera = rig_cameras(rig, _volume(), LENGTH_M, 1.0)[1]
    volume = _volume()
    target = target_points(volume.seed_lo, volume.seed_hi, 4, (5, 5))
    model = PinholeModel.fit(target, camera.project(target))
    assert model.residual_px < 1e-8
    points = _tracers()
    np.testing.assert_allclose(model.project(points), camera.project(points), atol=1e-7)


def test_intersect_closed_form():
    truth = np.array([[0.2, -0.4, 1.5]])
    directions = np.array([[[1.0, 0, 0]], [[0, 1.0, 0]], [[0, 0, 1.0]]])
    starts = truth[None] - 3.0 * directions + np.array([[[0, 0.1, 0]], [[0, 0, 0]], [[0, 0, 0]]])
    # lines x2 = -0.3 (along x1), x1 = 0.2 (along x2), x1=0.2,x2=-0.4 (along x3)
    solved = intersect(starts, directions)
    np.testing.assert_allclose(solved, [[0.2, -0.4 + 0.05, 1.5]], atol=1e-12)


def test_uniform_medium_images_and_triangulation(device):
    """K = 0: chief-ray images equal the projection of the truth to 1e-9 L, and the
    triangulated positions equal the truth within the calibration's residual."""
    field = _box_field("uniform", n0=N0)
    cameras = _cameras()
    points = _tracers()
    tracer = Tracer(engine="device", device=device)
    models = _models(cameras)
    centroids = []
    for camera in cameras:
        seen = view(field, camera, points, 1, tracer)
        assert np.all(seen.failed == 0)
        exact = camera.project(points)
        # 1e-9 L on the focus plane, in pixels
        np.testing.assert_allclose(seen.centroid, exact, rtol=0, atol=1e-9 / camera.pixel_size)
        # the exit ray's straight back-extension passes through the tracer
        trace = seen.trace
        offset = points - trace.end_pos
        along = np.sum(offset * trace.end_dir, axis=1, keepdims=True)
        miss = np.linalg.norm(offset - along * trace.end_dir, axis=1)
        assert np.max(miss) < 1e-9
        centroids.append(seen.centroid)
    positions, disparity = triangulate(models, np.stack(centroids))
    for camera, model in zip(cameras, models, strict=True):
        projected = np.linalg.norm(camera.project(positions) - camera.project(points), axis=1)
        assert np.sqrt(np.mean(projected**2)) <= model.residual_px
        assert np.max(projected) <= 0.01
    assert np.max(disparity) <= 0.01


def _lines_float64(field, cameras, points, n_cal, step=2e-3, miss_limit=1e-9):
    """Each camera's chief ray (the ray that reaches the pupil centre) traced in float64,
    continued straight back from the exit face in the calibration fluid: ``E - t D'``
    with ``D'`` the exit direction refracted at the exit face from the local index into
    the calibration fluid's (``D' = D`` where the two agree): the line of sight of a
    camera calibrated in that fluid."""
    starts, directions = [], []
    for camera in cameras:
        targets, miss = chief_targets(field, camera, points, Tracer(engine="numpy", step=step))
        assert np.max(miss) < miss_limit
        aim = camera.aim(points, targets[:, None]).reshape(-1, 3)
        result = trace_rays_reference(field, points, aim, x_end=camera.x_end, step=step)
        assert np.all(result.ok)
        n_exit = sample_field(field, result.end_pos)[0]
        tangential = result.end_dir[:, 1:] * (n_exit / n_cal)[:, None]
        normal = np.sqrt(1.0 - np.sum(tangential**2, axis=1))
        starts.append(result.end_pos)
        directions.append(np.column_stack([normal, tangential]))
    return intersect(np.stack(starts), np.stack(directions))


def test_linear_medium_error_equals_float64_exit_rays(device):
    field = _box_field("linear", n0=N0, g=0.01)
    cameras = _cameras(N0)
    points = _tracers()
    tracer = Tracer(engine="device", device=device)
    models = _models(cameras)
    centroids = np.stack([view(field, c, points, 1, tracer).centroid for c in cameras])
    measured, _ = triangulate(models, centroids)
    error = measured - points
    expected = _lines_float64(field, cameras, points, N0) - points
    size = np.linalg.norm(expected, axis=1)
    assert np.min(size) > 20 * cameras[0].pixel_size * 0.01  # far above the calibration's
    np.testing.assert_array_less(np.linalg.norm(error - expected, axis=1), 0.02 * size)


def test_turbulent_field_error_equals_float64_exit_rays_per_tracer(device):
    """The shipped sample's turbulence at C3, narrow pupils (the chief ray): per tracer, the
    3-D refraction error ``x_meas - x_ref`` (both triangulated on the Soloff models, as the
    LPT stage reports it) equals the float64 exit rays' intersection minus the truth within
    5 % of the error's rms; so does ``x_meas - truth``, which adds the baseline (the
    calibration's residual) to it. The slab lies near the exit face (short paths keep the
    float64 trace fast)."""
    from rimcl.fields.cases import CASES
    from rimcl.fields.field_reader import FieldFile
    from rimcl.fields.sample import sample_path
    from rimcl.lpt.config import IlluminationConfig
    from rimcl.lpt.views import uniform_field

    with FieldFile(sample_path()) as source:
        field = source.field(0, CASES["C3"])
        volume = Volume.of(source, IlluminationConfig(thickness=0.8, centre=5.4))
    length_m = 0.1 / (volume.hi[1] - volume.lo[1])  # as the LPT stage scales a field
    cameras = rig_cameras(RigConfig(), volume, length_m, field.n_ref)
    points = volume.seed(10, np.random.default_rng(3))
    models = _models(cameras, volume=volume)
    tracer = Tracer(engine="device", device=device)

    def triangulated(medium):
        return triangulate(
            models, np.stack([view(medium, c, points, 1, tracer).centroid for c in cameras])
        )[0]

    measured, reference = triangulated(field), triangulated(uniform_field(field))
    # a quarter of the device's step (half a cell); the chief rays' last miss on the pupil
    # plane below 1e-8 L (a millionth of a pixel in the image)
    step = 0.125 * field.spacing[0] / field.n_ref
    expected = _lines_float64(field, cameras, points, field.n_ref, step, 1e-8) - points
    rms = np.sqrt(np.mean(np.sum(expected**2, axis=1)))
    assert rms > 0.3 * cameras[0].pixel_size  # a third of a pixel: far above f32 rounding
    for error in (measured - reference, measured - points):
        np.testing.assert_array_less(np.linalg.norm(error - expected, axis=1), 0.05 * rms)


def test_device_and_numpy_engines_agree(device):
    field = _box_field("linear", n0=N0, g=0.01).on_grid([9, 17, 17], [0, -0.2, -0.2], [1, 1.2, 1.2])
    cameras = _cameras(field.n_ref)
    points = _tracers(6)
    device_views = [view(field, c, points, 4, Tracer(device=device)) for c in cameras]
    numpy_views = [view(field, c, points, 4, Tracer(engine="numpy")) for c in cameras]
    for on_device, in_numpy in zip(device_views, numpy_views, strict=True):
        np.testing.assert_allclose(on_device.centroid, in_numpy.centroid, rtol=0, atol=1e-5)
    models = _models(cameras)
    first = triangulate(models, np.stack([v.centroid for v in device_views]))[0]
    second = triangulate(models, np.stack([v.centroid for v in numpy_views]))[0]
    np.testing.assert_allclose(first, second, rtol=0, atol=1e-5 * cameras[0].pixel_size)


def test_soloff_beats_pinhole_through_the_window():
    cameras = _cameras()
    pinhole, soloff = _models(cameras, "pinhole"), _models(cameras, "soloff")
    for a, b in zip(pinhole, soloff, strict=True):
        assert isinstance(b, SoloffModel)
        assert b.residual_px < a.residual_px
        assert b.residual_px < 0.01


def test_scene_keys_are_checked():
    with pytest.raises(RimclError, match="did you mean 'thickness'"):
        parse_lpt_scene({"illumination": {"thicknes": 1.0}})
    with pytest.raises(RimclError, match=r"rig\.preset in the scene must be one of"):
        parse_lpt_scene({"rig": {"preset": "lpt-chalenge"}})
    with pytest.raises(RimclError, match=r"rimcl lpt does not use camera\.kind"):
        parse_lpt_scene({"camera": {"kind": "plane"}})
    with pytest.raises(RimclError, match="needs position_mm"):
        parse_lpt_scene({"rig": {"cameras": [{"look_at_mm": [1, 2, 3]}]}})
    scene = parse_lpt_scene({})
    assert scene.rig.preset == "lpt-challenge"
    assert scene.study.names == ["C1", "C2", "C3"]


def test_lpt_scene_takes_the_time_scale_from_the_velocity_scale():
    scene = parse_lpt_scene({"field": {"length_m": 0.1, "velocity_m_s": 0.02}})
    assert scene.study.lpt.time_s == 0.1 / 0.02
    with pytest.raises(RimclError, match=r"needs field\.length_m"):
        parse_lpt_scene({"field": {"velocity_m_s": 0.02}})


def _case_stats():
    """A case's statistics as :func:`rimcl.lpt.run.case_statistics` writes them (known rms)."""
    rms = {"refraction": 2.0, "optics": 1.5, "imaging": 0.5, "noise_floor": 0.25,
           "baseline": 0.5, "refraction_self_calibrated": None}  # fmt: skip
    absolute = {k: None if v is None else {"rms": v} for k, v in rms.items()}
    kinematic = {axis: {"absolute": absolute, "truth_rms": 8.0} for axis in ("x1", "x2", "x3")}
    position = {axis: {k: absolute[k] for k in rms} for axis in ("x1", "x2", "x3")}
    return {"pixel_size": 0.01, "fit": {"dt": 0.04}, "position": position,
            "velocity": kinematic, "acceleration": kinematic}  # fmt: skip


def test_lpt_units_are_the_field_values_times_the_scales():
    from rimcl.lpt.units import case_units

    block = case_units(_case_stats(), depth=1.0, length_m=0.1, time_s=0.5)
    velocity = block["velocity"]["x3"]
    assert velocity["rms_refraction"] == {"field": 2.0, "mm_s": 2.0 * (0.1 / 0.5 * 1e3),
                                          "px_frame": 2.0 * (0.04 / 0.01)}  # fmt: skip
    assert velocity["rms_truth"]["mm_s"] == 8.0 * (0.1 / 0.5 * 1e3)
    assert velocity["rms_refraction_self_calibrated"]["mm_s"] is None  # nothing measured
    assert block["acceleration"]["x1"]["rms_baseline"] == {"field": 0.5, "m_s2": 0.5 * 0.1 / 0.25}
    assert block["velocity"]["x2"]["rms_noise_floor"]["mm_s"] == 0.25 * (0.1 / 0.5 * 1e3)
    assert block["position"]["x1"]["rms_optics"]["um"] == 1.5 * 1e5
    assert block["position"]["x2"]["rms_refraction"] == {"field": 2.0, "um": 2.0 * 1e5,
                                                         "px": 2.0 / 0.01}  # fmt: skip
    assert block["scales"]["dt_ms"] == 0.04 * 0.5 * 1e3
    # without a time scale: lengths in µm and px, velocities and accelerations in field units
    block = case_units(_case_stats(), depth=1.0, length_m=0.1)
    assert block["velocity"]["x1"]["rms_refraction"]["mm_s"] is None
    assert block["velocity"]["x1"]["rms_refraction"]["px_frame"] == 2.0 * 4.0
    assert block["acceleration"]["x1"]["rms_refraction"] == {"field": 2.0, "m_s2": None}
    assert "--time-s (field.time_s) for mm/s" in block["note"]


def test_soloff_terms_are_the_monomials():
    from rimcl.lpt.calibration import SOLOFF_EXPONENTS, _soloff_terms

    points = np.random.default_rng(5).uniform(-1, 1, (7, 3))
    direct = np.prod(points[:, None, :] ** SOLOFF_EXPONENTS[None], axis=2)
    np.testing.assert_allclose(_soloff_terms(points), direct, rtol=1e-14, atol=1e-15)
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = 1e-6
        numeric = (_soloff_terms(points + step) - _soloff_terms(points - step)) / 2e-6
        np.testing.assert_allclose(_soloff_terms(points, axis), numeric, rtol=0, atol=1e-8)


def test_triangulation_of_all_frames_at_once_equals_frame_by_frame():
    from rimcl.lpt.run import triangulate_frames

    cameras = _cameras()
    models = _models(cameras)
    points = _tracers(30).reshape(3, 10, 3)
    noise = np.random.default_rng(4).normal(0, 0.3, (3, len(cameras), 10, 2))
    pixels = np.stack([[c.project(p) for c in cameras] for p in points]) + noise
    pixels[1, 2, 4] = np.nan  # a lost image: that tracer has no position
    positions, disparity = triangulate_frames(models, pixels)
    for k in range(3):
        expected = triangulate(models, pixels[k])
        np.testing.assert_allclose(positions[k], expected[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(disparity[k], expected[1], rtol=0, atol=1e-9)
    assert np.all(np.isnan(positions[1, 4])) and np.sum(np.isnan(positions)) == 3

"""Volume self-calibration: it removes what makes cameras disagree, not what they share."""

import numpy as np
import pytest

from rimcl.core.errors import RimclError
from rimcl.lpt.calibration import PinholeModel, calibrate, target_points, triangulate
from rimcl.lpt.config import RigConfig, parse_lpt_scene
from rimcl.lpt.flow import Volume
from rimcl.lpt.run import rig_cameras
from rimcl.lpt.selfcal import self_calibrate

LENGTH_M = 0.1


def _setup(count=1500):
    volume = Volume(
        np.zeros(3),
        np.ones(3),
        1.0,
        np.array([0.35, 0.1, 0.25]),
        np.array([0.65, 0.9, 0.75]),
        False,
    )
    cameras = rig_cameras(RigConfig(), volume, LENGTH_M, 1.333)
    margin = 0.05 * (volume.seed_hi - volume.seed_lo)
    target = target_points(volume.seed_lo - margin, volume.seed_hi + margin, 5, (13, 9))
    models = [calibrate(c, target, "soloff") for c in cameras]
    points = volume.seed(count, np.random.default_rng(7))
    return cameras, models, points


def test_a_camera_misaligned_after_calibration_is_corrected():
    """Camera 2 moved on its sensor after the target (0.8 px across, a 0.5 % scale): the
    disparity is removed, but the positions stay where the first triangulation put them
    (the particles cannot tell which camera moved: every camera is corrected towards the
    common least-squares point)."""
    cameras, models, points = _setup()
    pixels = np.stack([c.project(points) for c in cameras])
    centre = np.array([959.5, 599.5])
    pixels[1] = centre + 1.005 * (pixels[1] - centre) + [0.8, -0.3]
    before, disparity = triangulate(models, pixels)
    result = self_calibrate(models, pixels, (3, 5, 5), 3)
    after, disparity_after = triangulate(result.models, pixels)
    pixel = cameras[0].pixel_size
    assert np.median(np.max(disparity, axis=1)) > 0.5
    assert result.rms_disparity_px[-1] < 0.02 * result.rms_disparity_px[0]
    assert np.max(disparity_after) < 0.05
    error_before = np.sqrt(np.mean((before - points) ** 2))
    error_after = np.sqrt(np.mean((after - points) ** 2))
    assert error_before > 0.05 * pixel
    np.testing.assert_allclose(after, before, rtol=0, atol=0.02 * pixel)
    assert error_after == pytest.approx(error_before, rel=0.05)
    assert result.cells_used == 75 and result.terms == 19


def test_a_shift_every_camera_shares_is_invisible():
    """Images of the points displaced by δ in every camera are consistent: no disparity,
    no correction, and the positions keep the displacement."""
    cameras, models, points = _setup(600)
    delta = np.array([0.004, -0.002, 0.003])
    pixels = np.stack([c.project(points + delta) for c in cameras])
    result = self_calibrate(models, pixels, (3, 4, 4), 2)
    for corrected, model in zip(result.models, models, strict=True):
        shift = corrected.project(points) - model.project(points)
        assert np.max(np.abs(shift)) < 0.02  # the calibration's own residual
    positions, _ = triangulate(result.models, pixels)
    np.testing.assert_allclose(positions - points, np.broadcast_to(delta, points.shape), atol=2e-5)


def test_refusals():
    cameras, models, points = _setup(30)
    pixels = np.stack([c.project(points) for c in cameras])
    with pytest.raises(RimclError, match="sub-volumes"):
        self_calibrate(models, pixels, (5, 5, 5), 1)
    pinholes = [PinholeModel.fit(points, p) for p in pixels]
    with pytest.raises(RimclError, match="Soloff"):
        self_calibrate(pinholes, pixels)
    with pytest.raises(RimclError, match="self_calibration corrects Soloff"):
        parse_lpt_scene({"lpt": {"model": "pinhole"}})

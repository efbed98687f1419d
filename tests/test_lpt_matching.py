"""Matching from the images alone: every tracer found on exact images, none where a camera
disagrees beyond the tolerance, ghosts appearing as the tolerance or density grows."""

import numpy as np

from rimcl.lpt.calibration import calibrate, target_points
from rimcl.lpt.config import RigConfig
from rimcl.lpt.flow import Volume
from rimcl.lpt.matching import match_frame
from rimcl.lpt.run import rig_cameras


def _rig():
    volume = Volume(
        np.zeros(3),
        np.ones(3),
        1.0,
        np.array([0.35, 0.1, 0.25]),
        np.array([0.65, 0.9, 0.75]),
        False,
    )
    cameras = rig_cameras(RigConfig(), volume, 0.1, 1.333)
    margin = 0.05 * (volume.seed_hi - volume.seed_lo)
    target = target_points(volume.seed_lo - margin, volume.seed_hi + margin, 5, (13, 9))
    return volume, cameras, [calibrate(c, target, "soloff") for c in cameras]


def test_exact_images_match_every_tracer_and_no_ghost():
    volume, cameras, models = _rig()
    points = volume.seed(40, np.random.default_rng(1))
    pixels = np.stack([c.project(points) for c in cameras])
    pixels[2, 5] = np.nan  # an image not located: that tracer cannot be matched
    result = match_frame(models, pixels, 0.5)
    assert result["true"] == 39 and result["missed"] == 1
    assert result["ghosts"] == 0 and result["tracers"] == 39


def test_a_camera_off_by_more_than_the_tolerance_loses_every_match():
    volume, cameras, models = _rig()
    points = volume.seed(40, np.random.default_rng(2))
    pixels = np.stack([c.project(points) for c in cameras])
    pixels[3] += [2.0, 0.0]
    assert match_frame(models, pixels, 1.0)["true"] == 0
    assert match_frame(models, pixels, 3.0)["true"] == 40


def test_ghosts_grow_with_the_tolerance_at_a_high_density():
    volume, cameras, models = _rig()
    points = volume.seed(1200, np.random.default_rng(3))
    pixels = np.stack([c.project(points) for c in cameras])
    tight, loose = (match_frame(models, pixels, tol) for tol in (0.5, 3.0))
    assert tight["true"] == loose["true"] == 1200
    assert loose["ghosts"] > tight["ghosts"] and loose["ghosts"] > 0
    assert loose["ghost_fraction"] == loose["ghosts"] / loose["matches"]


def test_no_candidate_pair_is_no_match_not_a_crash():
    """Two tracers whose images no epipolar curve reaches (or no image at all in the first
    camera): nothing matched, every tracer missed."""
    volume, cameras, models = _rig()
    points = volume.seed(2, np.random.default_rng(4))
    pixels = np.stack([c.project(points) for c in cameras])
    pixels[-1] += 60.0  # the last camera's images far off every curve
    result = match_frame(models, pixels, 0.5)
    assert (result["matches"], result["true"], result["missed"]) == (0, 0, 2)
    assert result["ghost_fraction"] is None and result["missed_fraction"] == 1.0
    pixels[0] = np.nan  # the first camera located nothing
    result = match_frame(models, pixels, 0.5)
    assert (result["matches"], result["tracers"], result["missed"]) == (0, 0, 2)

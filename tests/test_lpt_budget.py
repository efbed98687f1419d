"""The LPT error budget of velocity and acceleration (:mod:`rimcl.lpt.budget`): refraction,
its optics and imaging parts, the noise floor and the baseline.

- A uniform medium (G = 0) on a noisy camera: the images through the field and through the
  uniform fluid share their noise draws, so every refraction error is exactly 0 (positions,
  velocities, accelerations, optics and imaging), while the noise floor (the reference
  exposed again with other draws) is positive.
- The parts add up: imaging = refraction − optics, row by row (known arrays).
"""

import numpy as np
import pytest

from rimcl.lpt.budget import budget_lines, kinematic_errors
from rimcl.ptv.track import TrackFit


@pytest.fixture(scope="module")
def uniform(lpt_flow, tmp_path_factory):
    """G = 0 through the tiny flow: stereo rig, noisy sensor, NumPy engine."""
    from rimcl.lpt.config import parse_lpt_scene
    from rimcl.lpt.run import case_statistics, prepare, run_case

    scene = parse_lpt_scene(
        {
            "field": {"path": str(lpt_flow)},
            "tracers": {"count": 16},
            "time": {"frames": 5},
            "sensor": {"noise": True},
            "rig": {"preset": "stereo"},
            "run": {"engine": "numpy"},
            "lpt": {"max_rays": 4, "calibration_grid": [6, 5], "self_calibration": False},
        }
    )
    run = prepare(scene, tmp_path_factory.mktemp("lptfloor"), {})
    try:
        result = run_case(run, scene, "G=0")
    finally:
        run.source.close()
    return result, case_statistics(run, result, scene)


def test_a_uniform_medium_has_no_lpt_refraction_error(uniform):
    result, stats = uniform
    np.testing.assert_array_equal(result["x_meas"], result["x_ref"])
    np.testing.assert_array_equal(result["x_opt_meas"], result["x_opt_ref"])
    assert stats["tracers_kept"] > 0
    for axis in ("x1", "x2", "x3"):
        assert stats["position"][axis]["refraction"]["rms"] == 0
        assert stats["position"][axis]["noise_floor"]["rms"] > 0
        for group in ("velocity", "acceleration"):
            terms = stats[group][axis]
            for name in ("refraction", "optics", "imaging"):
                assert terms[name]["rms_normalized"] == 0, (group, axis, name)
            assert terms["noise_floor"]["rms_normalized"] > 0
            assert terms["absolute"]["noise_floor"]["rms"] > 0
    lines = budget_lines(stats)
    assert len(lines) == 2 and all("noise floor" in line for line in lines)
    assert "x1 0 % (optics 0 %, imaging 0 %; noise floor" in lines[0]


def test_imaging_is_refraction_minus_optics():
    rng = np.random.default_rng(3)

    def fit(values):
        return TrackFit(centres=np.arange(2), position=values, velocity=values, acceleration=values)

    arrays = {kind: rng.normal(size=(2, 4, 3)) for kind in ("meas", "ref", "opt_meas", "opt_ref")}
    truth = rng.normal(size=(2, 4, 3))
    errors = kinematic_errors({k: fit(v) for k, v in arrays.items()}, "velocity", truth)
    np.testing.assert_array_equal(errors["refraction"], arrays["meas"] - arrays["ref"])
    np.testing.assert_array_equal(errors["optics"], arrays["opt_meas"] - arrays["opt_ref"])
    np.testing.assert_allclose(
        errors["optics"] + errors["imaging"], errors["refraction"], rtol=0, atol=1e-15
    )
    np.testing.assert_array_equal(errors["baseline"], arrays["ref"] - truth)
    assert errors["noise_floor"] is None and errors["refraction_self_calibrated"] is None

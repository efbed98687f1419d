"""Refraction apart from the camera's noise: the measured and reference images of a tracer
share the sensor's draws (common random numbers), and the noise floor is a second, independent
exposure of the reference.

- A uniform medium (G = 0) on a noisy camera: refraction errors exactly 0 (positions,
  velocities, accelerations, optics and imaging parts); the verdict says "not resolved".
- The noise floor is positive, and it is the statistic of two independent exposures: the
  velocity and acceleration of the floor's positions minus the reference's, differenced here
  from the tracer table.
- A noiseless camera exposes the same image twice: its floor is exactly 0.
"""

import dataclasses

import numpy as np
import pytest

from rimcl.ptv.measure import run_render
from rimcl.ptv.render_file import write_render
from rimcl.scene.config import MeasureConfig, SensorConfig
from rimcl.stats.document import case_statistics
from rimcl.stats.render_file import load_render
from rimcl.stats.summaries import error_summary

NOISY = SensorConfig(noise=True, peak_electrons=8000.0, read_noise_e=3.0, background_e=8.0, seed=11)
SMALL = {"camera": "plane", "tracers": 12, "fan": 6, "pixels": 1024, "psf_sigma": 2.5}


def _uniform_case(tmp_path_factory, device, sensor, engine="numpy"):
    config = MeasureConfig.from_options(engine=engine, device=device, frames=5, **SMALL)
    result = run_render(None, k_rho=0.0, config=dataclasses.replace(config, sensor=sensor))
    path = write_render(tmp_path_factory.mktemp("floor") / "g0.h5", result)
    return result, case_statistics(load_render(path))


@pytest.fixture(scope="module")
def noisy(tmp_path_factory, device):
    return _uniform_case(tmp_path_factory, device, NOISY)


def test_a_uniform_medium_has_no_refraction_error_on_a_noisy_camera(noisy):
    result, case = noisy
    rows = result.tracers
    for axis in ("x2", "x3"):
        np.testing.assert_array_equal(rows[f"{axis}_meas"], rows[f"{axis}_ref"])
    assert case["n_used"] > 0
    assert case["position_error_median_over_L"] == 0
    for block in (case, case["optics"], case["imaging"]):
        for group, component in (("velocity", "u3"), ("acceleration_fit", "a3")):
            assert block[group][component]["rms_normalized"] == 0, (group, component)
    verdict = case["budget_verdict"]
    assert verdict["total"] == 0 and not verdict["resolved"]
    assert "refraction not resolved" in verdict["text"]
    assert f"the noise floor {100 * verdict['noise_floor']:.3g} %" in verdict["text"]
    assert verdict["noise_floor"] > 0 and verdict["dominant"] in ("noise_floor", "baseline")


def test_the_noise_floor_is_two_independent_exposures(noisy):
    result, case = noisy
    rows, dt = result.tracers, result.attrs["dt"]
    frames, count = result.attrs["n_frames"], result.attrs["n_tracers"]
    assert np.any(rows["x3_floor"] != rows["x3_ref"])
    floor = case["noise_floor"]
    assert floor["position_error_median_over_L"] > 0
    # the paper's forward difference of the floor's and the reference's own positions
    kept = np.all(rows["flags"].reshape(frames, count) == 0, axis=0)
    kept &= np.all(np.isfinite(rows["x3_floor"].reshape(frames, count)), axis=0)

    def velocity(kind):
        x = rows[f"x3_{kind}"].reshape(frames, count)[:, kept]
        return (x[1:] - x[:-1]) / dt

    truth = rows["u3_true"].reshape(frames, count)[:-1, kept]
    expected = error_summary(
        (velocity("floor") - velocity("ref")).ravel(), truth.ravel(), condition=False
    )
    found = floor["velocity"]["u3"]
    assert found["n"] == expected["n"] > 0
    assert found["rms_normalized"] == pytest.approx(expected["rms_normalized"], rel=1e-12)
    assert found["rms_normalized"] > 0
    assert floor["acceleration_fit"]["a3"]["rms_normalized"] > 0
    # in the units block (and the answer) beside refraction, which is exactly 0
    units = case["units"]["velocity"]["u3"]
    assert units["rms_refraction"]["field"] == 0 and units["rms_noise_floor"]["field"] > 0


def test_a_noiseless_camera_has_a_zero_floor(tmp_path_factory, device):
    result, case = _uniform_case(tmp_path_factory, device, SensorConfig())
    np.testing.assert_array_equal(result.tracers["x2_floor"], result.tracers["x2_ref"])
    assert case["noise_floor"]["velocity"]["u3"]["rms_normalized"] == 0

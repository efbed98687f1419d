"""interp="auto" and step="auto": the cheapest setting within the tolerance."""

import logging

import numpy as np
import pyopencl as cl
import pytest
from tracing_fields import oblique_rays, smooth_field

import rimcl
from rimcl.core.errors import RimclError
from rimcl.fields.field import analytic_field
from rimcl.optics.auto_choice import STEP_FACTORS, calibration_subset
from rimcl.optics.trace import PAPER_PIXELS, default_step, default_tolerance
from rimcl.optics.verify import exact_grin


@pytest.fixture(scope="module")
def case():
    field = smooth_field(2e-2, periodic=True, seed=8)
    origins, directions = oblique_rays(64, 1.0, 5.0, 0.3, seed=9)
    return field, origins, directions


def _trace(case, device, **options):
    field, origins, directions = case
    return rimcl.trace_rays(field, origins, directions, x_end=6.0, device=device, **options)


def _candidate(record, interp, step):
    return next(c for c in record["candidates"] if c["interp"] == interp and c["step"] == step)


def test_interpolation_errors_above_the_tolerance_choose_bspline3(case, device, caplog):
    # the trilinear error of this field, as the calibration measures it
    loose = _trace(case, device, interp="auto", tolerance=1.0).config["auto"]
    trilinear_error = _candidate(loose, "trilinear", loose["step"])["error"]
    bspline_error = _candidate(loose, "bspline3", loose["step"])["error"]
    assert bspline_error < trilinear_error / 10
    tolerance = np.sqrt(trilinear_error * bspline_error)
    with caplog.at_level(logging.INFO, logger="rimcl.optics.auto_choice"):
        result = _trace(case, device, interp="auto", tolerance=tolerance)
    record = result.config["auto"]
    assert record["interp"] == "bspline3" and result.config["interp"] == "bspline3"
    assert record["met"] and record["estimated_error"] <= tolerance
    assert "auto: interp bspline3" in caplog.text
    # the estimate is the real error of these rays against the reference setting
    reference = _trace(
        case,
        device,
        interp="bspline3",
        step=record["reference"]["step"],
        precision=record["reference"]["precision"],
    )
    error = np.max(np.linalg.norm(result.image_pos - reference.image_pos, axis=1))
    assert error == pytest.approx(record["estimated_error"], rel=1e-6, abs=1e-12)


def test_a_loose_tolerance_takes_the_cheapest_at_the_largest_step(case, device):
    result = _trace(case, device, interp="auto", step="auto", tolerance=1e-2)
    record = result.config["auto"]
    good = [c for c in record["candidates"] if c["error"] <= 1e-2]
    cheapest = min(good, key=lambda c: c["cost"])
    assert (record["interp"], record["step"]) == (cheapest["interp"], cheapest["step"])
    # trilinear on CPUs; GPU texture units are cheaper still
    assert record["interp"] == ("texture" if device.type & cl.device_type.GPU else "trilinear")
    assert record["step"] == pytest.approx(STEP_FACTORS[0] * default_step(case[0]))
    assert result.step == pytest.approx(record["step"])


def test_auto_step_takes_the_largest_step_within_the_tolerance(case, device):
    tolerance = 1e-6
    record = _trace(case, device, interp="bspline3", step="auto", tolerance=tolerance).config[
        "auto"
    ]
    steps = sorted({c["step"] for c in record["candidates"]}, reverse=True)
    chosen = steps.index(record["step"])
    assert record["estimated_error"] <= tolerance
    assert all(_candidate(record, "bspline3", s)["error"] > tolerance for s in steps[:chosen])
    assert record["reference"]["interp"] == "bspline3"  # same interpolation: step error only


def test_an_unreachable_tolerance_takes_the_most_accurate_and_says_so(case, device, caplog):
    with caplog.at_level(logging.WARNING, logger="rimcl.optics.auto_choice"):
        record = _trace(case, device, interp="auto", tolerance=1e-15).config["auto"]
    assert not record["met"]
    assert record["estimated_error"] == min(c["error"] for c in record["candidates"])
    assert "no candidate met the tolerance" in caplog.text


def test_closed_form_fields_calibrate_the_step_only(device):
    field = analytic_field("grin", n0=1.5, alpha=0.5)
    origins, directions = oblique_rays(8, -0.5, 0.5, 0.4, seed=1)
    origins[:, 2] = 0.0
    result = rimcl.trace_rays(
        field, origins, directions, x_end=np.pi, interp="auto", step="auto", tolerance=1e-6,
        device=device,
    )  # fmt: skip
    record = result.config["auto"]
    assert {c["interp"] for c in record["candidates"]} == {"trilinear"}
    exact = exact_grin(field, origins, directions, np.pi)
    assert np.max(np.linalg.norm(result.end_pos - exact, axis=1)) <= 1e-6


def test_default_tolerance_is_a_hundredth_of_a_paper_pixel(case):
    field, origins, _ = case
    assert default_tolerance(field, origins, 6.0) == pytest.approx(0.01 * 2 * np.pi / PAPER_PIXELS)


def test_the_calibration_subset_spreads_over_the_ray_set():
    rows = calibration_subset(10_000, 256)
    assert len(rows) == 256 and rows[0] == 0 and rows[-1] == 9_999
    assert np.all(np.diff(rows) > 0)
    np.testing.assert_array_equal(calibration_subset(7, 256), np.arange(7))


def test_auto_with_adaptive_steps_is_refused(case, device):
    with pytest.raises(RimclError, match="cannot be combined"):
        _trace(case, device, interp="auto", step="adaptive")

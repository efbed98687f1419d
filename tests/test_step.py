"""Step control: adaptive steps against closed forms and fine fixed steps; refusals."""

import numpy as np
import pytest
from tracing_fields import oblique_rays, smooth_field

import rimcl
from rimcl.core.errors import RimclError
from rimcl.fields.field import analytic_field
from rimcl.optics.trace import LONG_STEP_CELLS, default_step
from rimcl.optics.verify import exact_grin


def _grin_case(count=12):
    field = analytic_field("grin", n0=1.5, alpha=0.5)
    origins, directions = oblique_rays(count, -0.5, 0.5, 0.5, seed=3)
    origins[:, 2] = 0.0
    return field, origins, directions, exact_grin(field, origins, directions, np.pi)


@pytest.mark.parametrize(("precision", "tolerance"), [("f32c", 1e-6), ("f64", 1e-10)])
def test_adaptive_steps_meet_the_tolerance_on_the_grin_rod(device, has_fp64, precision, tolerance):
    if precision == "f64" and not has_fp64:
        pytest.skip("needs cl_khr_fp64")
    field, origins, directions, exact = _grin_case()
    result = rimcl.trace_rays(
        field,
        origins,
        directions,
        x_end=np.pi,
        step="adaptive",
        tolerance=tolerance,
        precision=precision,
        device=device,
    )
    assert result.counts["ok"] == len(origins)
    error = np.max(np.linalg.norm(result.end_pos - exact, axis=1))
    assert error <= tolerance
    assert result.config["step_control"] == "adaptive"
    assert result.config["tolerance"] == tolerance
    # steps per ray are reported; the step grew far beyond the default 1e-3
    assert np.all(result.steps > 0)
    assert result.config["mean_step"] > 10 * default_step(field)
    assert result.config["sharma_steps"] >= 3 * result.steps.sum()


def test_tighter_tolerances_take_more_steps_and_stay_within_them(device):
    field, origins, directions, exact = _grin_case(6)
    steps, errors = [], []
    for tolerance in (1e-4, 1e-5, 1e-6):
        result = rimcl.trace_rays(
            field, origins, directions, x_end=np.pi, step="adaptive", tolerance=tolerance,
            device=device,
        )  # fmt: skip
        steps.append(result.steps.sum())
        errors.append(np.max(np.linalg.norm(result.end_pos - exact, axis=1)))
    assert steps[0] < steps[1] < steps[2]
    assert all(
        error <= tolerance for error, tolerance in zip(errors, (1e-4, 1e-5, 1e-6), strict=True)
    )


def test_adaptive_steps_on_a_grid_match_a_fine_fixed_step(device):
    field = smooth_field(3e-2, periodic=True, seed=6)
    origins, directions = oblique_rays(24, 1.0, 5.0, 0.3, seed=7)
    kwargs = dict(x_end=6.0, interp="bspline3", device=device)
    fine = rimcl.trace_rays(field, origins, directions, step=default_step(field) / 8, **kwargs)
    tolerance = 1e-5
    result = rimcl.trace_rays(
        field, origins, directions, step="adaptive", tolerance=tolerance, **kwargs
    )
    np.testing.assert_array_equal(result.status, fine.status)
    assert np.max(np.abs(result.image_pos - fine.image_pos)) <= tolerance


def test_the_step_limit_is_counted_not_dropped(device):
    field, origins, directions, _ = _grin_case(5)
    result = rimcl.trace_rays(
        field, origins, directions, x_end=np.pi, step="adaptive", max_steps=3, device=device
    )
    assert result.counts["max_steps"] == 5
    assert np.all(np.isnan(result.image_pos))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"step": "adaptive", "tolerance": -1.0}, "tolerance must be a positive length"),
        ({"step": "adaptive", "tolerance": 1e-12}, "below what precision f32c can resolve"),
        ({"step": "adaptive", "tolerance": 1e-7, "precision": "f32"}, "or precision f64"),
        ({"step": "fast"}, "step must be a number, None, 'adaptive' or 'auto'"),
        ({"step": 5.0}, "larger than the field"),
        ({"step": 1e-12}, "more than a million steps per cell"),
        ({"step": 2e-7, "precision": "f32"}, "float32 resolution"),
    ],
)
def test_steps_that_make_no_sense_are_refused(device, options, message):
    field = smooth_field(1e-3)
    with pytest.raises(RimclError, match=message):
        rimcl.trace_rays(field, [[0.0, 0.5, 0.5]], [[1.0, 0.0, 0.0]], x_end=1.0, device=device,
                         **options)  # fmt: skip


def test_a_long_fixed_step_is_flagged(device):
    field = smooth_field(1e-3)
    long_step = 3 * LONG_STEP_CELLS * float(np.min(field.spacing)) / field.n_ref
    result = rimcl.trace_rays(
        field, [[0.0, 0.5, 0.5]], [[1.0, 0.0, 0.0]], x_end=1.0, step=long_step, device=device
    )
    assert "cells of arc" in result.config["warnings"][0]
    default = rimcl.trace_rays(field, [[0.0, 0.5, 0.5]], [[1.0, 0.0, 0.0]], x_end=1.0,
                               device=device)  # fmt: skip
    assert "warnings" not in default.config

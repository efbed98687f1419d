"""``interp="auto"`` and ``step="auto"``: the cheapest setting that is accurate enough.

A short calibration on a subset of the rays (evenly spread over the ray set) traces each
candidate setting and a tighter reference, measures the largest difference of the image
points ``r'`` between them, and keeps the cheapest candidate whose difference stays
within the tolerance (model no more than a scene needs).

- ``step="auto"``: candidates are the default step (half a cell of arc) times
  ``4, 2, 1, 1/2, 1/4, 1/8``; the reference takes a quarter of the smallest. With a
  fixed ``interp`` the reference uses the same interpolation (only the step is judged).
- ``interp="auto"``: candidates are ``trilinear``, ``bspline3`` and, on GPUs with image
  support, ``texture``; the reference is ``bspline3`` (the most accurate) at the fine
  step, so the interpolation error counts.
- The reference runs in ``f64`` where the device has it (else ``f32c``); candidates run
  in the caller's precision.

Cost of a candidate: Sharma steps per ray times the relative cost of one step with its
interpolation (:data:`STEP_COST`). Timing the calibration itself would be noise.
"""

import logging

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import Field
from rimcl.optics.trace import (
    _check_step,
    _round_to_pairs,
    default_step,
    default_tolerance,
    plan_steps,
    run_trace,
)

logger = logging.getLogger(__name__)

#: Rays of the calibration subset (at most).
SUBSET_RAYS = 256
#: Candidate steps of ``step="auto"``, as multiples of the default step, largest first.
STEP_FACTORS = (4.0, 2.0, 1.0, 0.5, 0.25, 0.125)
#: The reference step is this fraction of the smallest candidate step.
REFERENCE_STEP_FRACTION = 0.25
#: Relative cost of one Sharma step per interpolation, on CPUs and on GPUs (kernel time,
#: measured with benchmarks/speed.py on a 128³ field: PoCL 3.1 on a 2-core AMD EPYC,
#: f32c, 16 rays per work-item for trilinear and 8 for the others; NVIDIA H100, one ray
#: per work-item).
STEP_COST = {
    "cpu": {"trilinear": 1.0, "texture": 6.3, "bspline3": 4.1},
    "gpu": {"trilinear": 1.0, "texture": 0.8, "bspline3": 3.7},
}


def calibration_subset(count, size=SUBSET_RAYS):
    """Indices of ``size`` rays spread evenly over a set of ``count`` (all if fewer)."""
    if count <= size:
        return np.arange(count)
    return np.unique(np.linspace(0, count - 1, size).round().astype(np.int64))


def _device_kind(device):
    import pyopencl as cl

    return "gpu" if device.type & cl.device_type.GPU else "cpu"


def _candidate_interps(field, interp, device):
    if not isinstance(field, Field):
        return ["trilinear"]  # closed forms are not interpolated
    if interp != "auto":
        return [interp]
    found = ["trilinear", "bspline3"]
    if _device_kind(device) == "gpu" and device.image_support:
        found.insert(1, "texture")
    return found


def _candidate_steps(field, step, x_end, origins, precision):
    if step != "auto":
        return [default_step(field) if step is None else float(step)]
    found = []
    for factor in STEP_FACTORS:
        candidate = default_step(field) * factor
        try:
            _check_step(field, candidate, x_end, origins, precision)
        except RimclError:
            continue
        found.append(candidate)
    if not found:
        raise RimclError("no step of the auto ladder suits this field and these rays")
    return found


def _image_error(result, reference):
    """Largest |r' - r'_ref| (length units) over the rays; inf if a candidate loses a ray
    that the reference traces to the exit plane."""
    both = result.ok & reference.ok
    if np.any(reference.ok & ~result.ok):
        return float("inf")
    if not np.any(both):
        return float("inf")
    distance = np.linalg.norm(result.image_pos[both] - reference.image_pos[both], axis=1)
    return float(np.max(distance))


def calibrate(
    field,
    origins,
    directions,
    *,
    x_end,
    interp,
    step,
    precision,
    device,
    tolerance=None,
    kernel_shape=None,
):
    """Choose the interpolation and/or step for ``auto`` (see the module text).

    Parameters
    ----------
    field : Field or AnalyticField
    origins, directions : ndarray, float64, shape (N, 3)
        The validated rays of the call (unit directions).
    x_end : float
    interp : {"trilinear", "texture", "bspline3", "auto"}
    step : float, None or "auto"
    precision : {"f32", "f32c", "f64"}
    device : pyopencl.Device
    tolerance : float, optional
        Allowed r' error (length units); default
        :func:`rimcl.optics.trace.default_tolerance` (0.01 pixel of the paper's camera).
    kernel_shape : rimcl.optics.shapes.KernelShape, optional

    Returns
    -------
    dict
        ``interp`` and ``step`` chosen, ``estimated_error`` (length units),
        ``tolerance``, ``met`` (False if no candidate met the tolerance: the most
        accurate one is chosen), ``reference`` (its settings), ``subset_rays`` and
        ``candidates`` (each with ``interp``, ``step``, ``error``, ``cost``).
    """
    from rimcl.core.device import has_fp64

    if step == "adaptive":
        raise RimclError("step='adaptive' cannot be combined with interp='auto'; pick one")
    tolerance = default_tolerance(field, origins, x_end) if tolerance is None else tolerance
    tolerance = float(tolerance)
    if not tolerance > 0:
        raise RimclError(f"the tolerance must be a positive length, got {tolerance}")
    rows = calibration_subset(len(origins))
    sub_origins, sub_directions = origins[rows], directions[rows]
    interps = _candidate_interps(field, interp, device)
    steps = _candidate_steps(field, step, x_end, sub_origins, precision)
    reference_interp = "bspline3" if len(interps) > 1 else interps[0]
    reference_step = min(steps) * REFERENCE_STEP_FRACTION
    reference_precision = "f64" if has_fp64(device) else "f32c"

    def trace(interp_name, step_value, precision_name):
        return run_trace(
            field,
            sub_origins,
            sub_directions,
            x_end=x_end,
            plan=plan_steps(field, step_value, x_end, sub_origins, precision_name),
            interp=interp_name if isinstance(field, Field) else "trilinear",
            precision=precision_name,
            device=device,
            kernel_shape=kernel_shape,
        )

    reference = trace(reference_interp, reference_step, reference_precision)
    costs = STEP_COST[_device_kind(device)]
    candidates = []
    for interp_name in interps:
        for step_value in steps:
            result = trace(interp_name, step_value, precision)
            per_ray = result.config["sharma_steps"] / len(rows)
            candidates.append(
                {
                    "interp": interp_name,
                    "step": _round_to_pairs(step_value),
                    "error": _image_error(result, reference),
                    "cost": per_ray * costs.get(interp_name, 1.0),
                    "rays_not_ok": int(np.count_nonzero(~result.ok)),
                }
            )
    good = [c for c in candidates if c["error"] <= tolerance]
    chosen = (
        min(good, key=lambda c: c["cost"]) if good else min(candidates, key=lambda c: c["error"])
    )
    record = {
        "interp": chosen["interp"],
        "step": chosen["step"],
        "estimated_error": chosen["error"],
        "tolerance": tolerance,
        "met": bool(good),
        "reference": {
            "interp": reference_interp,
            "step": reference.step,
            "precision": reference_precision,
        },
        "subset_rays": len(rows),
        "candidates": candidates,
    }
    message = (
        f"auto: interp {chosen['interp']}, step {chosen['step']:.4g}: estimated r' error "
        f"{chosen['error']:.2e} (tolerance {tolerance:.2e}, {len(rows)} calibration rays)"
    )
    if good:
        logger.info(message)
    else:
        logger.warning(message + ": no candidate met the tolerance; using the most accurate")
    return record

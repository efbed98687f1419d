"""Rays through a uniform field: straight lines, in closed form.

What the integrator of :mod:`rimcl.optics.trace` approximates step by step, with its
statuses and its step limit; a measurement's reference pass images through such a field.
"""

import numpy as np

from rimcl.optics.trace import (
    STATUS_NAMES,
    TraceResult,
    _default_max_steps,
    _validate_rays,
    angle_between,
    direction_angles,
    plan_steps,
)


def straight_path_limit(field, step, x_end, origins, directions, precision="f32c"):
    """The longest path (length units) :func:`rimcl.trace_rays` follows through the uniform
    ``field`` at ``step`` before it gives up (its default ``max_steps``), for
    :func:`straight_rays`."""
    plan = plan_steps(field, step, x_end, origins, precision)
    max_steps = _default_max_steps(field, plan.step, x_end, origins, directions)
    return max_steps * plan.step * field.n_ref


def straight_rays(field, origins, directions, *, x_end, max_length=np.inf):
    """Rays through a uniform field (:attr:`rimcl.Field.is_uniform`): straight lines.

    What :func:`rimcl.trace_rays` approximates step by step, in closed form and float64, with no
    steps: the exit point on ``x1 = x_end`` is ``r0 + ((x_end - x1_0) / d1) d``, the exit
    direction ``d``, so the image point is the start point (to rounding). A measurement's
    reference pass (and a case with ``G = 0``) images through such a field; both engines
    use this (the device engine in ``cl/fan.cl``, ``RIMCL_STRAIGHT``) with the same float64
    operations.

    Parameters
    ----------
    field : rimcl.Field
        Uniform: only its reference index and its box (clamped fields) are used.
    origins, directions : array_like, shape (N, 3)
    x_end : float
    max_length : float, optional
        Rays that would reach the plane only after a longer path are ``max_steps``, as the
        integrator gives up (:func:`straight_path_limit`).

    Returns
    -------
    TraceResult
        ``ok``; ``turned_back`` for rays that do not move towards the exit plane;
        ``exit_side`` for rays that leave the box of a clamped field sideways before it;
        ``max_steps`` for the others longer than ``max_length``.
    """
    origins, directions = _validate_rays(origins, directions)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        run = (x_end - origins[:, 0]) / directions[:, 0]
        end_pos = origins + run[:, None] * directions
        end_dir = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        distance = (end_pos[:, 0] - origins[:, 0]) / end_dir[:, 0]
        image_pos = end_pos - distance[:, None] * end_dir
    image_pos[:, 0] = origins[:, 0]
    status = np.zeros(len(origins), dtype=np.int8)
    lateral = end_pos[:, 1:]
    outside = np.any(lateral < field.box_lo[1:], axis=1) | np.any(lateral > field.box_hi[1:], 1)
    finite = np.all(np.isfinite(end_pos), axis=1) & np.all(np.isfinite(end_dir), axis=1)
    status[~finite] = STATUS_NAMES.index("non_finite")  # never ok (see _finish)
    status[run > max_length] = STATUS_NAMES.index("max_steps")
    status[outside] = STATUS_NAMES.index("exit_side")
    status[~(run > 0) | ~np.isfinite(run)] = STATUS_NAMES.index("turned_back")
    image_pos[status != 0] = np.nan
    count = len(origins)
    return TraceResult(
        origins=origins,
        directions=directions,
        image_pos=image_pos,
        end_pos=end_pos,
        end_dir=end_dir,
        deflection=angle_between(directions, end_dir),
        deflection_angles=direction_angles(end_dir) - direction_angles(directions),
        path_length=run,
        optical_path=field.n_ref * run,
        n_metric=np.zeros((count, 3)),
        exit_index=np.full(count, field.n_ref),
        steps=np.zeros(count, dtype=np.int64),
        status=status,
        step=0.0,
        config={"straight": True, "x_end": float(x_end)},
    )

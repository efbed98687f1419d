"""Ray aiming: a lens camera's rays aimed at its pupil through the field, not a uniform fluid.

A lens collects the light a tracer sends into its pupil. :meth:`LensCamera.directions` aims
each tracer's rays at points spread over the pupil as if the fluid were uniform. Where the
index varies, the field bends them; once it bends them by more than the pupil's half angle
seen from the tracer (about 0.006 rad in water for the default f/11 lens at 300 mm), every
aimed ray misses the pupil and the tracer is lost (``no_rays``), or most of them and its
image dims below the threshold, although a real lens still collects the light the tracer
sends in the directions that the field bends onto the pupil.

Ray aiming, as optical design codes do it, finds that cone: for each tracer, the shift
``Δ`` of the aim points on the pupil plane that brings its chief ray (aimed at the pupil
centre) to the pupil centre through the field, by the fixed-point iteration
``Δ ← Δ − miss`` with the chief ray traced through the field each time (aiming at
``A + Δ`` from ``x`` is aiming at ``A`` from ``x − Δ``, so the camera aims the rays from
the shifted tracer :func:`aim_origins` gives, and they start at the tracer). Through a
uniform medium the chief ray lands on the centre and ``Δ = 0``: the reference pass aims
as before. The field bends neighbouring directions alike, so the shifted cone fills the
pupil; the pupil test still decides, ray by ray, which are collected.
"""

import numpy as np

from rimcl.optics.camera import LensCamera
from rimcl.optics.tracing import trace_rays

#: Newton steps of the chief ray's aim (each traces three rays per tracer).
AIM_ITERATIONS = 12
#: Shift of the two Jacobian probes, in pupil radii.
JACOBIAN_STEP = 0.1
#: Longest Newton step, in pupil radii.
MAX_STEP = 8.0
#: A chief ray this close to the pupil centre (in pupil radii) is aimed: its tracer stops.
AIM_TOLERANCE = 1e-7


def _starts(scene, positions):
    """Rays' start points ``(N, 3)``: tracers ``(x2, x3)`` on the sheet, or ``(x1, x2, x3)``
    each at its own depth (PIV's tracers across a light sheet)."""
    positions = np.asarray(positions, dtype=np.float64)
    return positions if positions.shape[-1] == 3 else scene.in_sheet(positions)


def chief_misses(camera, field, positions, origins, trace_options):
    """Where each chief ray aimed from ``origins`` (``(N, 2)``) and started at ``positions``
    (``(N, 2)`` on the sheet or ``(N, 3)`` at their own depths) lands on the pupil plane,
    relative to the pupil centre (``(N, 2)``, field units; NaN where the ray fails or
    reflects)."""
    scene = camera.scene
    result = trace_rays(
        field,
        _starts(scene, positions),
        camera.chief_directions(origins),
        x_end=scene.x_end,
        **trace_options,
    )
    centre = camera.pupil.centre
    with np.errstate(invalid="ignore", divide="ignore"):
        points, directions = camera.through_window(
            result.end_pos, result.end_dir, result.exit_index
        )
        run = (centre[0] - points[:, 0]) / directions[:, 0]
        landing = points[:, 1:] + run[:, None] * directions[:, 1:]
    miss = landing - centre[1:]
    miss[result.status != 0] = np.nan
    return miss


def aim_origins(camera, field, positions, trace_options, iterations=AIM_ITERATIONS):
    """The points each tracer's rays are aimed from (the tracer minus its aim shift).

    Newton steps on the chief ray's miss ``m(Δ)`` on the pupil plane, its 2 x 2 Jacobian by
    forward differences (two more chief rays, the shift moved by :data:`JACOBIAN_STEP` of
    the pupil radius along ``x2`` and ``x3``); each tracer keeps the shift of its smallest
    miss (a step that does not shrink it is not taken further).

    Parameters
    ----------
    camera : PlaneCamera, PupilCamera or LensCamera
        Only a :class:`LensCamera` aims through the field; any other camera aims from the
        tracers themselves.
    field : Field or AnalyticField
    positions : ndarray, shape (N, 2) or (N, 3)
        The tracers ``(x2, x3)`` on the sheet, or ``(x1, x2, x3)`` each at its own depth
        (the rays start there; the aim is a shift of ``(x2, x3)``).
    trace_options : dict
        ``step``, ``interp``, ``precision`` and ``device`` of :func:`rimcl.trace_rays`.
    iterations : int
        Newton steps at most (each tracer stops once within :data:`AIM_TOLERANCE`).

    Returns
    -------
    ndarray, float64, shape (N, 2)
        The tracers' ``(x2, x3)`` themselves through a uniform field or for other
        cameras; else ``(x2, x3) − Δ``.
    """
    positions = np.asarray(positions, dtype=np.float64)
    lateral = positions if positions.shape[-1] == 2 else positions[:, 1:]
    uniform = getattr(field, "is_uniform", False)  # an analytic field is never skipped
    if not isinstance(camera, LensCamera) or uniform or not len(positions):
        return lateral
    radius = 0.5 * camera.pupil.diameter
    step = JACOBIAN_STEP * radius
    probes = np.array([[0.0, 0.0], [step, 0.0], [0.0, step]])
    shift = np.zeros_like(lateral)
    best, best_size = shift.copy(), np.full(len(positions), np.inf)
    # every tracer is traced each step (a fixed number of rays: PoCL compiles its work-group
    # function per launch shape, and a shrinking set cost seconds a step); those already
    # within tolerance keep their shift, and the steps stop once all are
    tripled = np.repeat(positions, 3, axis=0)
    tripled_lateral = tripled if tripled.shape[-1] == 2 else tripled[:, 1:]
    for _ in range(int(iterations)):
        shifts = (shift[:, None, :] + probes[None]).reshape(-1, 2)
        miss = chief_misses(camera, field, tripled, tripled_lateral - shifts, trace_options)
        miss = miss.reshape(len(positions), 3, 2)
        size = np.hypot(*miss[:, 0].T)
        better = size < best_size
        best[better], best_size[better] = shift[better], size[better]
        jacobian = np.stack([miss[:, 1] - miss[:, 0], miss[:, 2] - miss[:, 0]], axis=-1) / step
        usable = np.isfinite(jacobian).all(axis=(1, 2)) & np.isfinite(miss[:, 0]).all(axis=1)
        usable &= np.abs(np.linalg.det(np.where(usable[:, None, None], jacobian, 1.0))) > 1e-6
        newton = np.zeros_like(shift)
        if usable.any():
            newton[usable] = -np.linalg.solve(jacobian[usable], miss[usable, 0][..., None])[..., 0]
        # at most MAX_STEP pupil radii a step (a nearly singular Jacobian near a caustic)
        length = np.hypot(*newton.T)[:, None]
        limit = MAX_STEP * radius
        newton = np.where(length > limit, newton * (limit / np.maximum(length, limit)), newton)
        # from the best shift so far: a step that made the miss larger is not continued
        shift = best + np.where(better[:, None], newton, 0.5 * (shift - best))
        done = best_size <= AIM_TOLERANCE * radius
        shift[done] = best[done]
        if done.all():
            break
    return lateral - best

"""Each tracer seen by each camera: rays aimed at the camera's pupil, traced, imaged.

A camera with a narrow pupil sees a tracer through one thin bundle of rays. The chief ray
is the ray that *reaches* the pupil centre: aimed first through the uniform calibration
fluid and the window, then re-aimed at the pupil centre minus its miss until it hits the
centre (:func:`chief_targets`; through the field the aimed ray misses it, and a ray off
the centre images where it crosses the focus plane, not where the camera's line of sight
for it lies). The bundle is the chief ray's aim point plus the pupil's offsets: its centre
for one ray, else a mirrored Vogel spiral; the rays are traced through the field to the
exit face ``x1 = x_end``, carried through the window (with the fluid's index at the exit
point), and imaged by the lens (:meth:`RigCamera.image_of_rays`). The
tracer's image centroid is the mean of its rays' image points (the optics part of the
error budget: no pixels, equal weights). Through a uniform field the rays are straight
lines (:func:`rimcl.optics.straight.straight_rays`), exactly.

The number of rays is chosen by convergence (:func:`choose_ray_count`): the smallest count
in ``1, 4, 8, 16, …`` whose centroids agree with the next count's within a tolerance (px)
on every sampled tracer.
"""

import dataclasses
import itertools
import operator

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import Field
from rimcl.optics.reference import trace_rays_reference
from rimcl.optics.straight import straight_rays


@dataclasses.dataclass(frozen=True)
class Tracer:
    """How rays are traced: the engine and the integrator's settings.

    Attributes
    ----------
    engine : {"device", "numpy"}
        ``device``: :func:`rimcl.trace_rays` (OpenCL); ``numpy``: the float64 NumPy twin
        :func:`rimcl.optics.reference.trace_rays_reference` (slow; for checks).
    interp, precision : str
    step : float or None
    device : object
        As :func:`rimcl.select_device` takes it.
    batch_size : int
    """

    engine: str = "device"
    interp: str = "trilinear"
    precision: str = "f32c"
    step: float = None
    device: object = None
    batch_size: int = 131072

    def __call__(self, field, origins, directions, x_end):
        """Trace rays to ``x1 = x_end``; a uniform field gives straight lines."""
        if getattr(field, "is_uniform", False):
            return straight_rays(field, origins, directions, x_end=x_end)
        if self.engine == "numpy":
            if self.interp not in ("trilinear", "texture", "bspline3"):
                raise RimclError(f"the numpy engine needs a fixed interpolation, not {self.interp}")
            return trace_rays_reference(
                field, origins, directions, x_end=x_end, step=self.step, interp=self.interp
            )
        from rimcl.optics.tracing import trace_rays

        return trace_rays(
            field,
            origins,
            directions,
            x_end=x_end,
            step=self.step,
            interp=self.interp,
            precision=self.precision,
            device=self.device,
            batch_size=self.batch_size,
        )


def uniform_field(field):
    """A uniform field of ``field``'s reference index, grid extent and boundary."""
    counts = np.asarray(field.counts)
    extent = field.spacing * (counts if field.periodic else counts - 1)
    return Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=extent / 2 if field.periodic else extent,
        origin=field.origin,
        n_ref=field.n_ref,
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
        boundary=field.boundary,
    )


@dataclasses.dataclass
class View:
    """One camera's view of tracers.

    Attributes
    ----------
    images : ndarray, shape (N, K, 2)
        Image point of every ray (px); NaN for rays that did not reach the exit face.
    centroid : ndarray, shape (N, 2)
        Mean of each tracer's ray images (px); NaN if any of its rays failed.
    failed : ndarray of int, shape (N,)
        Rays of each tracer that did not leave through the exit face.
    trace : TraceResult
        The traced rays (N·K rows, tracer-major).
    directions : ndarray, shape (N, K, 3)
        Each ray's unit direction as it leaves the tracer (for Mie weights).
    """

    images: np.ndarray
    centroid: np.ndarray
    failed: np.ndarray
    trace: object
    directions: np.ndarray


#: Re-aims of the chief ray at most, and the miss (field length units) that ends them.
CHIEF_ITERATIONS = 6
CHIEF_TOLERANCE = 1e-10


def _exit_index(result, camera):
    """Fluid index at each ray's exit point (the window's inner face): the trace's
    ``exit_index`` (``n`` sampled there, as for every camera; the calibration fluid's for
    rays that failed, whose images are dropped)."""
    return np.where(result.ok, result.exit_index, camera.fluid_index)


def chief_targets(field, camera, points, tracer):
    """Aim points that make each tracer's chief ray reach the pupil centre.

    Returns
    -------
    targets : ndarray, shape (N, 3)
        Where to aim (through the uniform fluid) so that the traced ray hits the centre.
    miss : ndarray, shape (N,)
        The last ray's distance from the centre on the pupil plane (field length units);
        NaN for rays that failed.
    """
    targets = np.broadcast_to(camera.position, points.shape).copy()
    if getattr(field, "is_uniform", False):
        return targets, np.zeros(len(points))
    for _ in range(CHIEF_ITERATIONS):
        directions = camera.aim(points, targets[:, None]).reshape(-1, 3)
        result = tracer(field, points, directions, camera.x_end)
        offset = camera.pupil_miss(result.end_pos, result.end_dir, _exit_index(result, camera))
        offset[~result.ok] = np.nan
        miss = np.linalg.norm(offset, axis=1)
        if not np.any(miss > CHIEF_TOLERANCE):
            break
        targets -= np.nan_to_num(offset)
    return targets, miss


def view(field, camera, points, rays, tracer, chief=None):
    """Trace ``rays`` rays from every point to ``camera`` and image them.

    Parameters
    ----------
    field : Field or AnalyticField
    camera : rimcl.lpt.rig.RigCamera
    points : ndarray, shape (N, 3)
        Tracer positions (field length units).
    rays : int
        Rays per tracer (1: the chief ray only).
    tracer : Tracer
    chief : ndarray, shape (N, 3), optional
        The chief rays' aim points (:func:`chief_targets`), when already known.

    Returns
    -------
    View
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if chief is None:
        chief, _ = chief_targets(field, camera, points, tracer)
    pupil = camera.pupil_points(rays) - camera.position
    directions = camera.aim(points, chief[:, None] + pupil[None]).reshape(-1, 3)
    origins = np.repeat(points, len(pupil), axis=0)
    result = tracer(field, origins, directions, camera.x_end)
    ok = result.ok
    exit_index = _exit_index(result, camera)
    images = camera.image_of_rays(result.end_pos, result.end_dir, exit_index)
    images[~ok] = np.nan
    images = images.reshape(len(points), len(pupil), 2)
    failed = np.sum(~ok.reshape(len(points), len(pupil)), axis=1)
    return View(
        images,
        images.mean(axis=1),
        failed,
        result,
        directions.reshape(len(points), len(pupil), 3),
    )


def ray_counts(max_rays):
    """The candidate counts ``1, 4, 8, 16, …`` up to ``max_rays``."""
    counts, count = [1], 4
    while count <= max_rays:
        counts.append(count)
        count *= 2
    return counts


def choose_ray_count(field, camera, points, tracer, tolerance_px, max_rays, centroid=None):
    """The fewest rays per tracer whose image centroid has converged.

    Parameters
    ----------
    field, camera, tracer
        As :func:`view`.
    points : ndarray, shape (N, 3)
        The tracers to test (a sample).
    tolerance_px : float
        Largest allowed change of a centroid (px) to the next count.
    max_rays : int
    centroid : callable, optional
        ``centroid(view) -> (N, 2)`` px: the centroid tested (the rendered and located
        image, :mod:`rimcl.lpt.images`); default the mean of the rays' image points.

    Returns
    -------
    dict
        ``rays`` (the choice), ``converged`` (bool), ``tolerance_px``, ``counts`` (the
        candidates) and ``changes_px``: per count tried, the largest centroid change to the
        next count (the search stops at the first change within the tolerance).
    """
    counts = ray_counts(max_rays)
    if centroid is None:
        centroid = operator.attrgetter("centroid")
    chief, _ = chief_targets(field, camera, points, tracer)  # the same for every count

    def located(count):
        return centroid(view(field, camera, points, count, tracer, chief))

    # counts are tried in turn and the search stops at the first converged one
    changes, chosen, converged = [], counts[-1], False
    previous = located(counts[0])
    for count, following in itertools.pairwise(counts):
        current = located(following)
        change = np.linalg.norm(current - previous, axis=-1)
        changes.append(float(np.nanmax(change)) if np.any(np.isfinite(change)) else None)
        if changes[-1] is not None and changes[-1] <= tolerance_px:
            chosen, converged = count, True
            break
        previous = current
    return {
        "rays": int(chosen),
        "converged": converged,
        "tolerance_px": float(tolerance_px),
        "counts": counts,
        "changes_px": changes,
        "sample": len(points),
    }

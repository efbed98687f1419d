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
centre) to the pupil centre through the field (aiming at ``A + Δ`` from ``x`` is aiming at
``A`` from ``x − Δ``, so the camera aims the rays from the shifted tracer
:func:`aim_origins` gives, and they start at the tracer). :func:`aim` finds it by Newton
from the uniform-fluid aim, then by Newton from every basin a scan of shifts finds, so no
chief ray that some scanned aim brings to the pupil is lost. Through a uniform medium the
chief ray lands on the centre and ``Δ = 0``: the reference pass aims as before. The field
bends neighbouring directions alike, so the shifted cone fills the pupil; the pupil test
still decides, ray by ray, which are collected.

Where the field folds the rays, several separate shifts bring the chief ray to the pupil:
the lens sees the tracer several times (multiple images, physics). :attr:`Aim.branches`
counts them; the tracer is imaged through one of them (:attr:`Aim.origins`).
"""

import dataclasses

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
#: Newton from the uniform-fluid aim is kept where its chief ray lands this near the pupil
#: centre (pupil radii); elsewhere the aim nearest the centre is taken.
KEEP_FIRST = 1e-3
#: Spacing of the aim scan's grid of shifts, in pupil radii.
SCAN_SPACING = 1.0
#: Largest half width of the aim scan, in pupil radii.
SCAN_EXTENT = 16.0
#: The scan reaches this many pupil radii beyond the field's largest displacement of the
#: chief ray met.
SCAN_MARGIN = 2.0
#: Grid points whose miss is below this many pupil radii (and a local minimum) start Newton.
SCAN_CANDIDATE = 3.0
#: Newton starts per tracer from the scan, at most.
SCAN_STARTS = 6
#: Aims whose shifts lie closer than this (pupil radii) are one image.
BRANCH_SEPARATION = 0.5


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


def _newton(camera, field, positions, shift, trace_options, iterations):
    """Newton steps on the chief ray's miss from the starting shifts ``shift`` (``(M, 2)``,
    one row per entry of ``positions``, ``(M, 2)`` or ``(M, 3)``).

    The 2 x 2 Jacobian by forward differences (two more chief rays, the shift moved by
    :data:`JACOBIAN_STEP` of the pupil radius along ``x2`` and ``x3``); each row keeps the
    shift of its smallest miss (a step that does not shrink it is not taken further), so
    it never ends farther from the pupil centre than it starts.

    Returns
    -------
    best : ndarray, shape (M, 2)
        The shift of the smallest miss.
    size : ndarray, shape (M,)
        That miss (field units; inf where no chief ray left the field).
    """
    radius = 0.5 * camera.pupil.diameter
    step = JACOBIAN_STEP * radius
    probes = np.array([[0.0, 0.0], [step, 0.0], [0.0, step]])
    shift = np.array(shift, dtype=np.float64)
    best, best_size = shift.copy(), np.full(len(positions), np.inf)
    # every row is traced each step (a fixed number of rays: PoCL compiles its work-group
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
    return best, best_size


def _scan_starts(camera, field, positions, lateral, trace_options):
    """Newton starts from a scan of aim shifts: the grid's local minima of the miss.

    An aim shift ``Δ`` brings the chief ray to the pupil centre where ``Δ = −d(Δ)``, ``d``
    the field's displacement of the chief ray on the pupil plane (``miss − Δ``): such aims
    lie no farther from the uniform-fluid aim than ``|d|`` reaches. Each tracer's chief ray
    is traced from the shifts of a square grid (spacing :data:`SCAN_SPACING` pupil radii)
    out to ``|d(0)|`` plus :data:`SCAN_MARGIN` radii, then on to the largest ``|d|`` met
    there plus the margin where that reaches farther, at most :data:`SCAN_EXTENT` radii
    (all tracers' chief rays in one trace per pass). Each tracer's scan depends on its own
    rays only, so shards give the whole run's aims. The grid points whose miss is a local
    minimum among their 8 neighbours and below :data:`SCAN_CANDIDATE` radii (at most
    :data:`SCAN_STARTS` per tracer, the smallest first) start Newton.

    Returns
    -------
    tracer : ndarray of int, shape (S,)
        The tracer of each start.
    shift : ndarray, shape (S, 2)
        The starting shifts (field units).
    """
    radius = 0.5 * camera.pupil.diameter
    spacing = SCAN_SPACING * radius
    side = round(SCAN_EXTENT / SCAN_SPACING)
    margin = SCAN_MARGIN / SCAN_SPACING
    offsets = spacing * np.arange(-side, side + 1)
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
    ring = np.rint(np.max(np.abs(grid), axis=1) / spacing)  # square ring of each grid point
    count = len(positions)
    size = np.full((count, len(grid)), np.inf)
    with np.errstate(invalid="ignore"):
        # |d(0)|: the uniform-fluid aim's miss
        reach = np.hypot(*chief_misses(camera, field, positions, lateral, trace_options).T)
    scanned = np.full(count, -1.0)
    for _ in range(2):
        reach = np.where(np.isfinite(reach), reach, 0.0)
        wanted = np.minimum(side, np.ceil(reach / spacing - 1e-9) + margin)
        rows, points = np.nonzero((ring[None] > scanned[:, None]) & (ring[None] <= wanted[:, None]))
        if not len(rows):
            break
        shifts = grid[points]
        with np.errstate(invalid="ignore"):
            miss = chief_misses(
                camera, field, positions[rows], lateral[rows] - shifts, trace_options
            )
            size[rows, points] = np.hypot(*miss.T)
            displaced = np.hypot(*(miss - shifts).T)  # |d| at the scanned shifts
        scanned = np.maximum(scanned, wanted)
        reach = np.zeros(count)
        np.maximum.at(reach, rows, np.where(np.isfinite(displaced), displaced, 0.0))
    size = np.where(np.isfinite(size), size, np.inf).reshape(count, 2 * side + 1, 2 * side + 1)
    padded = np.pad(size, ((0, 0), (1, 1), (1, 1)), constant_values=np.inf)
    neighbours = np.stack(
        [
            padded[:, 1 + a : 2 + a + 2 * side, 1 + b : 2 + b + 2 * side]
            for a in (-1, 0, 1)
            for b in (-1, 0, 1)
            if a or b
        ]
    )
    minimum = (size <= neighbours.min(axis=0)) & (size < SCAN_CANDIDATE * radius)
    size = np.where(minimum, size, np.inf).reshape(count, -1)
    order = np.argsort(size, axis=1, kind="stable")[:, :SCAN_STARTS]
    chosen = np.isfinite(np.take_along_axis(size, order, axis=1))
    tracer = np.broadcast_to(np.arange(count)[:, None], order.shape)[chosen]
    return tracer, grid[order[chosen]]


@dataclasses.dataclass(frozen=True)
class Aim:
    """Each tracer's aim through the field, and the separate aims that reach the pupil.

    Attributes
    ----------
    origins : ndarray, float64, shape (N, 2)
        The point ``(x2, x3)`` each tracer's rays are aimed from (the tracer minus its aim
        shift): the aim of Newton from the uniform-fluid aim where it reaches the pupil
        centre, else the aim whose chief ray lands nearest the centre.
    miss : ndarray, float64, shape (N,)
        How far that chief ray lands from the pupil centre (pupil radii).
    branches : ndarray, int64, shape (N,)
        Separate aims (shifts more than :data:`BRANCH_SEPARATION` pupil radii apart) whose
        chief rays land inside the pupil: the images a lens records of the tracer; 0 where
        none does (1 for every tracer through a uniform field).
    """

    origins: np.ndarray
    miss: np.ndarray
    branches: np.ndarray


def aim(camera, field, positions, trace_options, iterations=AIM_ITERATIONS, scan=True):
    """Aim each tracer's rays through the field: Newton, a scan of aims, Newton again.

    1. Newton steps from the uniform-fluid aim (:func:`_newton`); through weak fields they
       reach the pupil centre.
    2. A scan of aim shifts around the uniform aim (:func:`_scan_starts`, the chief rays of
       every tracer batched through one trace) finds every basin where a chief ray comes
       near the pupil centre; Newton from each such grid point. Since Newton keeps the
       smallest miss it starts from, the aim found lands at least as near the pupil centre
       as the best aim of the scan's grid: it cannot lose a chief ray the scan reaches.
    3. The aims whose chief rays land inside the pupil, told apart by their shifts, are the
       tracer's separate images (a field that folds the rays makes several).

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
    scan : bool
        False: Newton from the uniform-fluid aim only (one image per tracer).

    Returns
    -------
    Aim
    """
    positions = np.asarray(positions, dtype=np.float64)
    lateral = positions if positions.shape[-1] == 2 else positions[:, 1:]
    count = len(positions)
    uniform = getattr(field, "is_uniform", False)  # an analytic field is never skipped
    if not isinstance(camera, LensCamera) or uniform or not count:
        return Aim(lateral, np.zeros(count), np.ones(count, dtype=np.int64))
    radius = 0.5 * camera.pupil.diameter
    first, first_size = _newton(
        camera, field, positions, np.zeros_like(lateral), trace_options, iterations
    )
    shifts, sizes, owners = [first], [first_size], [np.arange(count)]
    if scan:
        tracer, starts = _scan_starts(camera, field, positions, lateral, trace_options)
        if len(tracer):
            found, found_size = _newton(
                camera, field, positions[tracer], starts, trace_options, iterations
            )
            shifts.append(found)
            sizes.append(found_size)
            owners.append(tracer)
    shifts, sizes, owners = (np.concatenate(a) for a in (shifts, sizes, owners))
    # the uniform-fluid aim's Newton where it reaches the centre (weak fields: the aim of
    # every earlier version), else the aim that lands nearest (the first on a tie)
    order = np.lexsort((sizes, owners))
    nearest = order[np.searchsorted(owners[order], np.arange(count))]
    best = np.where(first_size <= KEEP_FIRST * radius, np.arange(count), nearest)
    branches = np.zeros(count, dtype=np.int64)
    inside = sizes < radius
    for t in np.unique(owners[inside]):
        kept = []
        for s in shifts[inside & (owners == t)][np.argsort(sizes[inside & (owners == t)])]:
            if all(np.hypot(*(s - k)) > BRANCH_SEPARATION * radius for k in kept):
                kept.append(s)
        branches[t] = len(kept)
    return Aim(lateral - shifts[best], sizes[best] / radius, branches)


def aim_origins(camera, field, positions, trace_options, iterations=AIM_ITERATIONS):
    """The points each tracer's rays are aimed from (:attr:`Aim.origins` of :func:`aim`).

    Returns
    -------
    ndarray, float64, shape (N, 2)
        The tracers' ``(x2, x3)`` themselves through a uniform field or for other
        cameras; else ``(x2, x3) − Δ``.
    """
    return aim(camera, field, positions, trace_options, iterations).origins

"""The synthetic PTV measurement: tracers → rays → images → centroids → tracks (DESIGN §6).

For each frame, tracers are imaged twice by the same code: through the flow's
refractive-index field (the *measured* images) and through a uniform field (the
*reference* images, where every ray returns to its tracer). Work proceeds in batches of
tracers (the *fused path*): a batch's rays are traced, rendered into per-tracer windows
and centroided, and only per-tracer numbers are kept, so memory does not grow with the
number of tracers or rays.

The reference does not depend on the refractive-index case. :func:`run_render` returns it
in :attr:`RenderResult.reference`; pass it to later calls with the same configuration
(and seed) to skip recomputing it, as a study over cases does.

Output file (``rimcl_schema = "render"``, ``schema_version = 1``), written by
:func:`write_render`; the README documents every dataset.
"""

import dataclasses
import json
import logging
import math
import numbers
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from rimcl.camera import CAMERAS, PlaneCamera, PupilCamera, Scene, seed_tracers
from rimcl.centroid import (
    CENTROID_WEIGHTS,
    EXCLUDING,
    NO_POSITION,
    NOTES,
    TracerFlag,
    flag_names,
    locate,
    not_found,
)
from rimcl.errors import RimclError
from rimcl.field import Field
from rimcl.provenance import atomic_path, check_output, stamp_h5, to_json
from rimcl.render import FrameImage, Renderer, quantize, scale_for
from rimcl.trace import STATUS_NAMES, default_step, trace_rays
from rimcl.track import SheetVelocity, first_difference, integrate_tracks, second_difference

logger = logging.getLogger(__name__)

SCHEMA = "render"
SCHEMA_VERSION = 1
TRACKING_SUBSTEPS = 8  # RK4 steps between frames (error ~1e-9 of the motion at Δt = 0.005)
DEFAULT_RAYS_PER_BATCH = 1 << 17  # rays traced per batch: ~40 MB of host memory
DEFAULT_RAY_SAMPLE = 20_000

# per tracer and frame: what one imaging pass (reference or measured) records
_IMAGE_COLUMNS = {
    "x2": np.float64,
    "x3": np.float64,
    "area": np.int64,
    "perimeter": np.float64,
    "circularity": np.float64,
    "n_rays_ok": np.int64,
    "flags": np.int64,
    "peak": np.float64,
    "scale": np.float64,
}


def _new_images(frames, tracers):
    return {
        name: np.full((frames, tracers), np.nan if dtype is np.float64 else 0, dtype=dtype)
        for name, dtype in _IMAGE_COLUMNS.items()
    }


@dataclasses.dataclass
class Reference:
    """The case-independent part of a render run: true tracks and reference images.

    Attributes
    ----------
    key : dict
        The configuration it was made for (compared when it is reused).
    tracks : ndarray, shape (F, N, 2)
        True tracer positions ``(x2, x3)`` at each frame.
    true_velocity : ndarray, shape (N, 2) or None
        Flow velocity ``(u2, u3)`` at ``(x_0, t_0)``; None for a single frame.
    outside : ndarray, bool, shape (F, N)
        True positions outside the velocity grid (clamped fields only).
    images : dict of str to ndarray (F, N)
        Reference image results (``x2, x3, area, perimeter, circularity, n_rays_ok,
        flags, peak, scale``; ``peak`` is the unclipped brightest pixel in counts, ``scale``
        the 10-bit factor reused for the measured images).
    ray_counts : dict of str to int
        Trace status counts of all reference rays, plus ``vignetted``.
    ray_steps : int
        Integration steps of all reference rays.
    """

    key: dict
    tracks: np.ndarray
    true_velocity: np.ndarray
    outside: np.ndarray
    images: dict
    ray_counts: dict
    ray_steps: int


@dataclasses.dataclass
class RenderResult:
    """Everything :func:`write_render` writes.

    Attributes
    ----------
    attrs : dict
        Root attributes of the output file.
    config : dict
        The full configuration (recorded with versions and device).
    tracers : dict of str to ndarray
        One row per tracer and frame (frame-major: all tracers of frame 0 first).
    velocity, acceleration : dict of str to ndarray, or None
        One row per tracer; None with fewer than 2 (3) frames.
    rays : dict of str to ndarray
        A random subsample of the measured rays of the first frame.
    ray_attrs : dict
        Status counts of all rays traced (measured and reference).
    reference : Reference
        Reusable for another case with the same configuration.
    timings : dict of str to float
        Wall time per stage (s): ``track``, ``trace``, ``render``, ``centroid``.
    frame_image : ndarray of uint16, shape (rows, columns) or None
        The full first frame (measured), if asked for.
    device : pyopencl.Device
    """

    attrs: dict
    config: dict
    tracers: dict
    velocity: dict
    acceleration: dict
    rays: dict
    ray_attrs: dict
    reference: Reference
    timings: dict
    frame_image: np.ndarray
    device: object


def _open_source(field, stack):
    """A field file reader: from a path, the shipped sample (None), or an open reader."""
    if field is None:
        from rimcl.flow import sample_path

        field = sample_path()
    if isinstance(field, (str, Path)):
        from rimcl.flow.fieldfile import FieldFile

        return stack.enter_context(FieldFile(field)), str(Path(field).resolve())
    path = getattr(field, "path", None)
    return field, "<in memory>" if path is None else str(Path(path).resolve())


def _case_of(source, case, k_rho):
    """Case name and G; files of δn carry their own index and take neither."""
    if getattr(source, "kind", "density") == "delta_n":
        if case is not None or k_rho is not None:
            raise RimclError("this field file stores delta_n directly; --case/--k-rho do not apply")
        return "delta_n", float("nan")
    from rimcl.flow.cases import resolve_k_rho

    return resolve_k_rho(case, k_rho)


def _load_frame(source, frame, k_rho):
    if math.isnan(k_rho):
        return source.field(frame)
    return source.field(frame, k_rho)


def _uniform_like(source):
    """A uniform field (n = 1) with the grid's extent and boundary, on 2 nodes per axis.

    Tracing through it gives the same floats as through a zero δn on the full grid (the
    interpolated δn and ∇n are exactly 0 either way), without a full-size copy.
    """
    spacing = np.asarray(source.spacing, dtype=np.float64)
    counts = np.asarray(source.shape)[::-1]
    periodic = source.boundary == "periodic"
    extent = spacing * (counts if periodic else counts - 1)
    return Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=extent / 2 if periodic else extent,
        origin=source.origin,
        n_ref=1.0,
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
        boundary=source.boundary,
    )


def _make_camera(
    scene,
    camera,
    fan,
    pupil_rays,
    aperture_diameter,
    focal_length,
    f_number,
    camera_distance,
    view_angle,
):
    if camera not in CAMERAS:
        raise RimclError(f"unknown camera {camera!r}; choose from {CAMERAS}")
    if camera == "plane":
        return PlaneCamera(scene, int(fan))
    distance = 4.0 * scene.depth if camera_distance is None else float(camera_distance)
    if aperture_diameter is None and focal_length is None and f_number is None:
        aperture_diameter = 0.25 * distance
    return PupilCamera.from_optics(
        scene,
        distance,
        diameter=aperture_diameter,
        focal_length=focal_length,
        f_number=f_number,
        view_angle=float(view_angle),
        rays=int(pupil_rays),
    )


class _Pass:
    """One imaging pass (reference or measured) over all tracers of all frames."""

    def __init__(self, frames, tracers, renderer, threshold, weights, timings):
        self.images = _new_images(frames, tracers)
        self.renderer = renderer
        self.threshold = threshold
        self.weights = weights
        self.timings = timings
        self.status_counts = np.zeros(len(STATUS_NAMES), dtype=np.int64)
        self.vignetted = 0
        self.ray_steps = 0

    def counts(self):
        """Trace status counts of every ray of this pass, plus the vignetted ones."""
        counts = {name: int(c) for name, c in zip(STATUS_NAMES, self.status_counts, strict=True)}
        counts["vignetted"] = int(self.vignetted)
        return counts

    def image_tracer(self, frame, tracer, points, flags, scale=None, canvas=None):
        """Render and locate one tracer from the image points ``(K, 2)`` of its rays."""
        row = self.images
        row["n_rays_ok"][frame, tracer] = len(points)
        if len(points) == 0:
            blob, window, saturated = not_found(flags | TracerFlag.NO_RAYS), None, False
        else:
            start = time.perf_counter()
            pixels = self.renderer.to_pixels(points)
            window = self.renderer.window_for(pixels)
            raw, outside = self.renderer.render(pixels, np.ones(len(pixels)), window)
            if outside:
                flags |= TracerFlag.RAYS_OUTSIDE_WINDOW
            full_scale = self.renderer.full_scale
            if scale is None:  # the reference pass sets each tracer's scale
                scale = scale_for(raw, full_scale)
            counts, saturated = quantize(raw, scale, full_scale)
            row["peak"][frame, tracer] = float(np.max(raw)) * scale
            middle = time.perf_counter()
            blob = locate(counts, self.threshold, self.weights)
            self.timings["render"] += middle - start
            self.timings["centroid"] += time.perf_counter() - middle
            if canvas is not None:
                canvas.add(window, counts)
        flags |= blob.flags
        if saturated:
            flags |= TracerFlag.SATURATED
        if not blob.flags & NO_POSITION:
            x2, x3 = self.renderer.to_sheet([window.col0 + blob.col, window.row0 + blob.row])
            row["x2"][frame, tracer], row["x3"][frame, tracer] = x2, x3
        row["area"][frame, tracer] = blob.area
        row["perimeter"][frame, tracer] = blob.perimeter
        row["circularity"][frame, tracer] = blob.circularity
        row["flags"][frame, tracer] = int(flags)
        row["scale"][frame, tracer] = scale if scale is not None else np.nan


def _image_frame(
    pass_,
    frame,
    field,
    positions,
    scene,
    camera,
    trace_options,
    batch,
    scales=None,
    canvas=None,
    sampler=None,
    bar=None,
):
    """Trace, render and centroid every tracer of one frame, one batch at a time."""
    rays = camera.rays_per_tracer
    for first in range(0, len(positions), batch):
        ids = np.arange(first, min(first + batch, len(positions)))
        origins = np.repeat(scene.in_sheet(positions[ids]), rays, axis=0)
        directions = camera.directions(positions[ids]).reshape(-1, 3)
        start = time.perf_counter()
        result = trace_rays(field, origins, directions, x_end=scene.x_end, **trace_options)
        pass_.timings["trace"] += time.perf_counter() - start
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir)
        pass_.status_counts += np.bincount(result.status, minlength=len(STATUS_NAMES))
        pass_.vignetted += int(np.count_nonzero(ok & ~collected))
        pass_.ray_steps += int(result.steps.sum())
        if sampler is not None:
            sampler.take(ids[0] * rays, result, collected)
        points = result.image_pos[:, 1:].reshape(len(ids), rays, 2)
        ok = ok.reshape(len(ids), rays)
        collected = collected.reshape(len(ids), rays)
        for k, tracer in enumerate(ids):
            flags = TracerFlag(0)
            if not ok[k].all():
                flags |= TracerFlag.RAYS_FAILED
            if (ok[k] & ~collected[k]).any():
                flags |= TracerFlag.RAYS_VIGNETTED
            scale = None if scales is None else scales[frame, tracer]
            pass_.image_tracer(frame, tracer, points[k][collected[k]], flags, scale, canvas)
        if bar is not None:
            bar.update(len(ids))


class _RaySampler:
    """Keeps a fixed random subset of rays (by global ray index) as batches go by."""

    def __init__(self, total, count, rng):
        count = min(int(count), total)
        self.chosen = np.sort(rng.choice(total, size=count, replace=False))
        self.parts = []

    def take(self, offset, result, collected):
        lo, hi = np.searchsorted(self.chosen, [offset, offset + len(result.status)])
        local = self.chosen[lo:hi] - offset
        d0 = result.directions[local]
        self.parts.append(
            {
                "ray": self.chosen[lo:hi],
                "theta0": np.arctan2(np.linalg.norm(d0[:, 1:], axis=1), d0[:, 0]),
                "deflection": result.deflection[local],
                "n_metric": np.linalg.norm(result.n_metric[local], axis=1),
                "path_length": result.path_length[local],
                "displacement": np.linalg.norm(
                    result.image_pos[local, 1:] - result.origins[local, 1:], axis=1
                ),
                "status": result.status[local],
                "collected": collected[local],
            }
        )

    def table(self, rays_per_tracer):
        names = (
            "ray",
            "theta0",
            "deflection",
            "n_metric",
            "path_length",
            "displacement",
            "status",
            "collected",
        )
        table = {name: np.concatenate([p[name] for p in self.parts]) for name in names}
        table["tracer_id"] = table["ray"] // rays_per_tracer
        return table


def _progress(enabled, total):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="tracer", desc="render", disable=None)


def _true_motion(source, scene, tracers, times, frame_ids):
    """True tracks ``(F, N, 2)``, velocity at ``(x_0, t_0)`` and the outside-grid mask."""
    if len(times) == 1:
        return tracers[None], None, np.zeros((1, len(tracers)), dtype=bool)
    if not source.has_velocity:
        raise RimclError(
            f"{getattr(source, 'path', 'the field')} holds no velocity, which tracking the "
            "tracers over several frames needs (use --frames 1 for positions only)"
        )
    planes = [source.sheet_velocity(source.times[f], scene.x_sheet) for f in frame_ids]
    velocity = SheetVelocity(
        planes, times, source.origin[1:], source.spacing[1:], source.boundary == "periodic"
    )
    tracks = integrate_tracks(velocity, tracers, times, TRACKING_SUBSTEPS)
    outside = np.stack([~velocity.inside(p) for p in tracks])
    return tracks, velocity(tracers, times[0]), outside


def run_render(
    field=None,
    *,
    case=None,
    k_rho=None,
    tracers=1000,
    camera="plane",
    fan=32,
    pupil_rays=1024,
    aperture_diameter=None,
    focal_length=None,
    f_number=None,
    camera_distance=None,
    view_angle=0.0,
    renderer="exact",
    pixels=8192,
    psf_sigma=2.3,
    threshold=100.0,
    centroid_weights="excess",
    max_window=512,
    bit_depth=10,
    interp="trilinear",
    precision="f32c",
    step=None,
    seed=0,
    frames=3,
    start_frame=0,
    margin=0.05,
    x_sheet=None,
    depth=None,
    frame_image=False,
    ray_sample=DEFAULT_RAY_SAMPLE,
    rays_per_batch=DEFAULT_RAYS_PER_BATCH,
    reference=None,
    device=None,
    progress=False,
):
    """Run the synthetic PTV measurement of one refractive-index case.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file (default: the shipped sample).
    case : str, optional
        ``"C0"`` … ``"C4"``; or give ``k_rho``. Not for files storing ``delta_n``.
    k_rho : float, optional
        Gladstone–Dale product ``G`` (``n = 1 + G ρ``); 0 is a uniform medium.
    tracers : int
        Number of tracers, seeded uniformly over the field of view.
    camera : {"plane", "pupil"}
        ``plane``: rays aimed at a ``fan x fan`` grid on the exit plane (the paper);
        ``pupil``: ``pupil_rays`` rays aimed over a circular aperture.
    fan : int
        Aim points per side of the plane camera (paper: 100).
    pupil_rays : int
        Rays per tracer of the pupil camera.
    aperture_diameter : float, optional
        Pupil diameter (length units); or ``focal_length`` / ``f_number``. Default: a
        quarter of the camera distance.
    focal_length, f_number : float, optional
    camera_distance : float, optional
        From the sheet to the pupil centre along the viewing axis (length units; default
        4 L1).
    view_angle : float
        Angle of the viewing axis to ``x1``, towards ``+x2`` (degrees).
    renderer : {"exact", "paper"}
        Pixel-integrated Gaussian per ray, or the paper's binning and Gaussian filter.
    pixels : int
        Pixels across the wider side of the field of view (paper: 8192).
    psf_sigma : float
        Gaussian point-spread σ (pixels). 2.3 px gives a ~10 px tracer image at a
        threshold of 100 counts, as in the paper.
    threshold : float
        Grey threshold in counts of the camera (paper, 10 bits: 100 for air, 500 for water).
    centroid_weights : {"excess", "grey"}
        See :mod:`rimcl.centroid`.
    max_window : int
        Largest per-tracer window side (pixels).
    bit_depth : int
        Bits per pixel of the camera, 8 to 16 (paper: 10). The rounding to counts moves
        centroids by a few 1e-4 pixel at 10 bits, a floor under small refraction errors.
    interp, precision, step :
        Passed to :func:`rimcl.trace_rays`.
    seed : int
        Seeds tracers and the ray subsample; the same seed gives the same tracers and rays
        in every case (common random numbers).
    frames : {1, 2, 3}
        Frames imaged: 1 (positions), 2 (+ velocity), 3 (+ acceleration).
    start_frame : int
        First stored frame used; frames are consecutive.
    margin : float
        Edge band of the field of view left free of tracers (fraction of its width).
    x_sheet, depth : float, optional
        Sheet position and traced depth ``L1`` (defaults: see :meth:`Scene.from_grid`).
    frame_image : bool
        Also keep a full image of all tracers of the first frame (measured).
    ray_sample : int
        Measured rays of the first frame kept for diagnostics.
    rays_per_batch : int
        Rays traced per batch; bounds the memory.
    reference : Reference, optional
        From an earlier result with the same configuration: skips the reference pass.
    device : str or pyopencl.Device, optional
    progress : bool
        Show a progress bar.

    Returns
    -------
    RenderResult
    """
    from rimcl.device import describe_device, select_device

    if centroid_weights not in CENTROID_WEIGHTS:
        raise RimclError(
            f"unknown centroid weights {centroid_weights!r}; choose from {CENTROID_WEIGHTS}"
        )
    if int(frames) not in (1, 2, 3):
        raise RimclError(f"frames must be 1, 2 or 3, got {frames}")
    if int(pixels) < 1:
        raise RimclError(f"the image needs at least 1 pixel, got {pixels}")
    if step is not None and not (isinstance(step, numbers.Real) and step > 0):
        raise RimclError(f"the step must be a positive number (or None: half a cell), got {step!r}")
    frames = int(frames)
    with ExitStack() as stack:
        source, source_name = _open_source(field, stack)
        case_name, g = _case_of(source, case, k_rho)
        frame_ids = list(range(int(start_frame), int(start_frame) + frames))
        if start_frame < 0 or frame_ids[-1] >= source.n_frames:
            raise RimclError(
                f"{frames} frames from frame {start_frame} need frames up to {frame_ids[-1]}, "
                f"but the field has {source.n_frames} (0..{source.n_frames - 1})"
            )
        times = np.asarray(source.times, dtype=np.float64)[frame_ids]
        dt = float(times[1] - times[0]) if frames > 1 else float("nan")
        if frames == 3 and not math.isclose(times[2] - times[1], dt, rel_tol=1e-6):
            raise RimclError(
                f"frames {frame_ids} are not equally spaced in time ({times.tolist()}); "
                "the second difference needs equal spacing"
            )
        scene = Scene.from_grid(
            source.origin, source.spacing, source.shape, source.boundary, x_sheet, depth
        )
        cam = _make_camera(
            scene,
            camera,
            fan,
            pupil_rays,
            aperture_diameter,
            focal_length,
            f_number,
            camera_distance,
            view_angle,
        )
        pixel_size = float(np.max(scene.fov_size)) / int(pixels)
        rend = Renderer(
            renderer,
            pixel_size,
            tuple(scene.fov_lo),
            float(psf_sigma),
            int(max_window),
            int(bit_depth),
        )
        if not (np.isfinite(threshold) and 0 <= threshold < rend.full_scale):
            raise RimclError(
                f"the threshold must be in [0, {rend.full_scale}) counts of the "
                f"{rend.bit_depth}-bit camera, got {threshold}"
            )
        device = select_device(device)
        tracer_stream, sample_stream = np.random.SeedSequence(int(seed)).spawn(2)
        start_positions = seed_tracers(tracers, scene, np.random.default_rng(tracer_stream), margin)
        count = len(start_positions)
        batch = max(1, int(rays_per_batch) // cam.rays_per_tracer)
        calibration = None
        if interp == "auto":
            calibration = _calibrate_interp(
                source,
                frame_ids[0],
                g,
                scene,
                cam,
                start_positions,
                rend,
                precision,
                step,
                device,
            )
            interp = calibration["interp"]
        key = {
            "field": source_name,
            "grid": {
                "origin": np.asarray(source.origin).tolist(),
                "spacing": np.asarray(source.spacing).tolist(),
                "shape_n3_n2_n1": list(source.shape),
                "boundary": source.boundary,
            },
            "frames": frame_ids,
            "times": times.tolist(),
            "scene": scene.describe(),
            "tracers": count,
            "seed": int(seed),
            "margin": float(margin),
            "camera": cam.describe(),
            "render": {
                **rend.describe(),
                "threshold": float(threshold),
                "centroid_weights": centroid_weights,
            },
            "trace": {
                "interp": interp,
                "precision": precision,
                "step": None if step is None else float(step),
                "device": describe_device(device),
            },
        }
        ref_step = _reference_step(step, source)
        timings = {"track": 0.0, "trace": 0.0, "render": 0.0, "centroid": 0.0}
        passes = frames if reference is not None else 2 * frames
        bar = _progress(progress, passes * count)
        try:
            if reference is None:
                reference = _make_reference(
                    source,
                    scene,
                    cam,
                    rend,
                    key,
                    start_positions,
                    times,
                    frame_ids,
                    threshold,
                    centroid_weights,
                    timings,
                    batch,
                    device,
                    ref_step,
                    interp,
                    precision,
                    bar,
                )
            elif reference.key != key:
                changed = sorted(k for k in key if reference.key.get(k) != key[k])
                raise RimclError(
                    "the reference was made for another configuration (differs in: "
                    f"{', '.join(changed)})"
                )
            measured = _Pass(frames, count, rend, threshold, centroid_weights, timings)
            sampler = _RaySampler(
                count * cam.rays_per_tracer, ray_sample, np.random.default_rng(sample_stream)
            )
            canvas = None
            if frame_image:
                extent = np.ceil(scene.fov_size / pixel_size).astype(int)
                canvas = FrameImage(extent[0], extent[1], rend.full_scale)
            options = {"step": step, "interp": interp, "precision": precision, "device": device}
            delta_n_max = 0.0
            for f, frame in enumerate(frame_ids):
                field_f = _load_frame(source, frame, g)
                delta_n_max = max(delta_n_max, field_f.delta_n_range)
                _image_frame(
                    measured,
                    f,
                    field_f,
                    reference.tracks[f],
                    scene,
                    cam,
                    options,
                    batch,
                    scales=reference.images["scale"],
                    canvas=canvas if f == 0 else None,
                    sampler=sampler if f == 0 else None,
                    bar=bar,
                )
                del field_f
        finally:
            if bar is not None:
                bar.close()
        config = {
            **key,
            "case": case_name,
            "k_rho": g,
            "start_frame": int(start_frame),
            "rays_per_batch": int(rays_per_batch),
            "ray_sample": int(ray_sample),
            "tracking_substeps": TRACKING_SUBSTEPS,
            "reference_step": ref_step,
        }
        if calibration is not None:
            config["auto"] = calibration
    return _assemble(
        config,
        key,
        reference,
        measured,
        sampler,
        cam,
        rend,
        scene,
        times,
        dt,
        case_name,
        g,
        delta_n_max,
        timings,
        canvas,
        device,
    )


#: Tracers whose rays calibrate ``interp="auto"`` (evenly spread over the tracer set).
CALIBRATION_TRACERS = 16


def _calibrate_interp(source, frame, g, scene, cam, positions, rend, precision, step, device):
    """Choose the interpolation for ``interp="auto"`` once, on the first measured frame.

    The tolerance is 0.01 pixel of this camera. Every batch, frame and the reference then
    use the same choice, so the reference stays comparable (DESIGN §4.3).
    """
    from rimcl.calibrate import calibrate

    chosen = np.unique(np.linspace(0, len(positions) - 1, CALIBRATION_TRACERS).astype(int))
    origins = np.repeat(scene.in_sheet(positions[chosen]), cam.rays_per_tracer, axis=0)
    directions = cam.directions(positions[chosen]).reshape(-1, 3)
    record = calibrate(
        _load_frame(source, frame, g),
        origins,
        directions,
        x_end=scene.x_end,
        interp="auto",
        step=step,
        precision=precision,
        device=device,
        tolerance=0.01 * rend.pixel_size,
    )
    logger.info(
        "auto: interp %s, estimated r' error %.2e (0.01 pixel = %.2e)",
        record["interp"],
        record["estimated_error"],
        record["tolerance"],
    )
    return record


def _reference_step(step, source):
    """The step of the reference traces: the one the user gave, or the tracer's default
    for this grid at n = 1 (what a zero-G case of the same grid uses)."""
    if step is not None:
        return float(step)
    probe = Field.from_arrays(
        np.zeros((2, 2, 2), dtype=np.float32),
        spacing=source.spacing,
        n_ref=1.0,
        gradient=np.zeros((2, 2, 2, 3), dtype=np.float32),
    )
    return default_step(probe)


def _make_reference(
    source,
    scene,
    cam,
    rend,
    key,
    start_positions,
    times,
    frame_ids,
    threshold,
    centroid_weights,
    timings,
    batch,
    device,
    ref_step,
    interp,
    precision,
    bar,
):
    start = time.perf_counter()
    tracks, true_velocity, outside = _true_motion(source, scene, start_positions, times, frame_ids)
    timings["track"] += time.perf_counter() - start
    uniform = _uniform_like(source)
    options = {"step": ref_step, "interp": interp, "precision": precision, "device": device}
    ref = _Pass(len(frame_ids), len(start_positions), rend, threshold, centroid_weights, timings)
    for f in range(len(frame_ids)):
        _image_frame(ref, f, uniform, tracks[f], scene, cam, options, batch, bar=bar)
    if ref.status_counts[0] == ref.vignetted:
        raise RimclError(
            "no ray of any tracer reaches the camera even through a uniform medium: "
            "check the camera geometry (distance, view angle, aperture) against the field"
        )
    return Reference(
        key=key,
        tracks=tracks,
        true_velocity=true_velocity,
        outside=outside,
        images=ref.images,
        ray_counts=ref.counts(),
        ray_steps=ref.ray_steps,
    )


def _assemble(
    config,
    key,
    reference,
    measured,
    sampler,
    cam,
    rend,
    scene,
    times,
    dt,
    case_name,
    g,
    delta_n_max,
    timings,
    canvas,
    device,
):
    frames, count = reference.tracks.shape[:2]
    ref, meas = reference.images, measured.images
    truth_flags = np.where(reference.outside, int(TracerFlag.OUTSIDE_FIELD), 0)
    every = ref["flags"] | meas["flags"] | truth_flags
    flags, notes = every & int(EXCLUDING), every & int(NOTES)

    def rows(values):
        return np.asarray(values).reshape(-1)

    ids = np.tile(np.arange(count), frames)
    tracers = {
        "id": ids,
        "frame": np.repeat(np.arange(frames), count),
        "time": np.repeat(times, count),
        "x2_true": rows(reference.tracks[..., 0]),
        "x3_true": rows(reference.tracks[..., 1]),
        "x2_ref": rows(ref["x2"]),
        "x3_ref": rows(ref["x3"]),
        "x2_meas": rows(meas["x2"]),
        "x3_meas": rows(meas["x3"]),
        "area_ref": rows(ref["area"]),
        "area_meas": rows(meas["area"]),
        "perimeter_ref": rows(ref["perimeter"]),
        "perimeter_meas": rows(meas["perimeter"]),
        "circularity_ref": rows(ref["circularity"]),
        "circularity_meas": rows(meas["circularity"]),
        "n_rays": np.full(frames * count, cam.rays_per_tracer, dtype=np.int64),
        "n_rays_ok": rows(meas["n_rays_ok"]),
        "n_rays_ok_ref": rows(ref["n_rays_ok"]),
        "peak_ref": rows(ref["peak"]),
        "peak_meas": rows(meas["peak"]),
        "flags": rows(flags),
        "notes": rows(notes),
        "flags_ref": rows(ref["flags"]),
        "flags_meas": rows(meas["flags"]),
    }
    positions = {
        "true": reference.tracks,
        "ref": np.stack([ref["x2"], ref["x3"]], axis=-1),
        "meas": np.stack([meas["x2"], meas["x3"]], axis=-1),
    }
    velocity = acceleration = None
    if frames >= 2:
        velocity = {"id": np.arange(count)}
        truth = {"true": reference.true_velocity}
        for kind in ("true", "ref", "meas"):
            u = truth.get(kind)
            u = first_difference(positions[kind], dt) if u is None else u
            velocity[f"u2_{kind}"], velocity[f"u3_{kind}"] = u[:, 0], u[:, 1]
        velocity["flags"] = np.bitwise_or.reduce(flags[:2], axis=0)
        velocity["notes"] = np.bitwise_or.reduce(notes[:2], axis=0)
    if frames >= 3:
        acceleration = {"id": np.arange(count)}
        for kind in ("true", "ref", "meas"):
            a = second_difference(positions[kind], dt)
            acceleration[f"a2_{kind}"], acceleration[f"a3_{kind}"] = a[:, 0], a[:, 1]
        acceleration["flags"] = np.bitwise_or.reduce(flags[:3], axis=0)
        acceleration["notes"] = np.bitwise_or.reduce(notes[:3], axis=0)
    attrs = {
        "rimcl_schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "case": case_name,
        "k_rho": g,
        "delta_n_max": delta_n_max,
        "length_L": scene.depth,
        "pixel_size": rend.pixel_size,
        "dt": dt,
        "flag_names": json.dumps(flag_names()),
        "note_bits": int(NOTES),
        "n_tracers": count,
        "n_frames": frames,
        "rays_per_tracer": cam.rays_per_tracer,
        "renderer": rend.kind,
        "camera": config["camera"]["camera"],
        "threshold": config["render"]["threshold"],
        "psf_sigma_px": rend.psf_sigma,
        "x_sheet": scene.x_sheet,
        "x_end": scene.x_end,
        "fov_lo": scene.fov_lo,
        "fov_hi": scene.fov_hi,
        "field": config["field"],
    }
    ray_attrs = {f"count_{k}": v for k, v in measured.counts().items()}
    ray_attrs.update({f"ref_count_{k}": v for k, v in reference.ray_counts.items()})
    ray_attrs["ray_steps"] = measured.ray_steps
    ray_attrs["ref_ray_steps"] = reference.ray_steps
    ray_attrs["sampled_from_frame"] = 0
    return RenderResult(
        attrs=attrs,
        config=config,
        tracers=tracers,
        velocity=velocity,
        acceleration=acceleration,
        rays=sampler.table(cam.rays_per_tracer),
        ray_attrs=ray_attrs,
        reference=reference,
        timings=dict(timings),
        frame_image=None if canvas is None else canvas.counts,
        device=device,
    )


def write_render(path, result, overwrite=False):
    """Write a :class:`RenderResult` to an HDF5 file, atomically and stamped.

    Parameters
    ----------
    path : str or Path
    result : RenderResult
    overwrite : bool
        Replace an existing file (otherwise an existing file is an error).

    Returns
    -------
    pathlib.Path
    """
    import h5py

    path = Path(path)
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        for name, value in result.attrs.items():
            h5.attrs[name] = value
        stamp_h5(h5, result.config, result.device)
        h5.attrs["timings_s"] = to_json(result.timings)
        groups = {
            "tracers": result.tracers,
            "velocity": result.velocity,
            "acceleration": result.acceleration,
            "rays": result.rays,
        }
        for group_name, table in groups.items():
            if table is None:
                continue
            group = h5.create_group(group_name)
            for name, values in table.items():
                group.create_dataset(name, data=values)
        for name, value in result.ray_attrs.items():
            h5["rays"].attrs[name] = value
    return path


def check_frame_image(path, overwrite=False):
    """Refuse, before any work, a frame-image path that is not PNG or TIFF or not writable.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    if path.suffix.lower() not in (".png", ".tif", ".tiff"):
        raise RimclError(f"frame image {path} must end in .png, .tif or .tiff")
    return check_output(path, overwrite)


def write_frame_image(path, result, overwrite=False):
    """Write the full first-frame image as a 16-bit PNG or TIFF (x3 upwards).

    The configuration and versions go into the image's text metadata.
    """
    from PIL import Image, PngImagePlugin

    from rimcl.provenance import versions

    if result.frame_image is None:
        raise RimclError("this result holds no frame image (run with frame_image=True)")
    path = check_frame_image(path, overwrite)
    note = to_json({"config": result.config, "versions": versions()})
    image = Image.fromarray(np.ascontiguousarray(result.frame_image[::-1]))
    with atomic_path(path, overwrite=overwrite) as tmp:
        if path.suffix.lower() == ".png":
            info = PngImagePlugin.PngInfo()
            info.add_text("rimcl", note)
            image.save(tmp, format="PNG", pnginfo=info)
        else:
            image.save(tmp, format="TIFF", description=note)
    return path

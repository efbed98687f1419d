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
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from rimcl.camera import Scene, seed_tracers
from rimcl.centroid import EXCLUDING, NOTES, TracerFlag, flag_names
from rimcl.config import MeasureConfig
from rimcl.errors import RimclError
from rimcl.field import Field
from rimcl.imaging import Imaging, empty_columns, image_batch
from rimcl.provenance import atomic_path, check_output, stamp_h5, to_json
from rimcl.render import FrameImage
from rimcl.trace import STATUS_NAMES, default_step, trace_rays
from rimcl.track import SheetVelocity, first_difference, integrate_tracks, second_difference

logger = logging.getLogger(__name__)

SCHEMA = "render"
SCHEMA_VERSION = 1
TRACKING_SUBSTEPS = 8  # RK4 steps between frames (error ~1e-9 of the motion at Δt = 0.005)


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
        Reference image columns (:data:`rimcl.imaging.IMAGE_COLUMNS`; ``scale`` is the
        factor reused for the measured images).
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


@dataclasses.dataclass
class Setup:
    """One run's configuration resolved against its field: what every stage shares.

    Attributes
    ----------
    source : FieldFile
        The open field file.
    scene : rimcl.camera.Scene
        Sheet, exit plane and field of view.
    camera : PlaneCamera or PupilCamera
    imaging : rimcl.imaging.Imaging
    trace_options : dict
        ``interp``, ``precision``, ``step`` and ``device`` for :func:`rimcl.trace_rays`.
    frame_ids : list of int
        Stored frames imaged.
    times : ndarray, shape (F,)
    dt : float
        Time between frames (NaN for one frame).
    start_positions : ndarray, shape (N, 2)
        Tracers at the first frame.
    batch : int
        Tracers traced per batch.
    key : dict
        The case-independent configuration (a reusable reference must match it).
    timings : dict of str to float
        Seconds per stage, filled as the stages run.
    engine : rimcl.engine.DeviceEngine or None
        The device pipeline (``engine = "device"``); None for the NumPy engine.
    """

    source: object
    scene: Scene
    camera: object
    imaging: Imaging
    trace_options: dict
    frame_ids: list
    times: np.ndarray
    dt: float
    start_positions: np.ndarray
    batch: int
    key: dict
    timings: dict
    engine: object = None


def _frames_of(source, time_config):
    """Frame indices, their times and the spacing, checked against the file."""
    frames, start_frame = int(time_config.frames), int(time_config.start_frame)
    frame_ids = list(range(start_frame, start_frame + frames))
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
    return frame_ids, times, dt


def _setup(source, source_name, g, config, streams):
    """Resolve the configuration against the field: scene, camera, imaging, tracers, key."""
    from rimcl.device import describe_device, select_device

    frame_ids, times, dt = _frames_of(source, config.time)
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, config.x_sheet, config.depth
    )
    camera = config.camera.build(scene)
    imaging = config.renderer.build(scene)
    device = select_device(config.run.device)
    start_positions = seed_tracers(
        config.tracers.count,
        scene,
        np.random.default_rng(streams[0]),
        config.tracers.margin,
    )
    integrator = config.integrator
    trace_options = {
        "step": integrator.step,
        "interp": integrator.interp,
        "precision": integrator.precision,
        "device": device,
    }
    setup = Setup(
        source=source,
        scene=scene,
        camera=camera,
        imaging=imaging,
        trace_options=trace_options,
        frame_ids=frame_ids,
        times=times,
        dt=dt,
        start_positions=start_positions,
        batch=max(1, int(config.run.rays_per_batch) // camera.rays_per_tracer),
        key={},
        timings={"track": 0.0, "trace": 0.0, "render": 0.0, "centroid": 0.0},
    )
    if config.run.engine == "device":
        from rimcl.engine import DeviceEngine

        setup.engine = DeviceEngine(camera, scene, imaging, device, setup.batch)
    calibration = None
    if integrator.interp == "auto":
        calibration = _calibrate_interp(setup, g)
        trace_options["interp"] = calibration["interp"]
    setup.key = {
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
        "tracers": len(start_positions),
        "seed": int(config.tracers.seed),
        "margin": float(config.tracers.margin),
        "camera": camera.describe(),
        "render": imaging.describe(),
        "trace": {
            "interp": trace_options["interp"],
            "precision": integrator.precision,
            "step": None if integrator.step is None else float(integrator.step),
            "device": describe_device(device),
        },
    }
    return setup, calibration


class _Pass:
    """One imaging pass (reference or measured) over all tracers of all frames."""

    def __init__(self, frames, tracers):
        self.images = empty_columns((frames, tracers))
        self.status_counts = np.zeros(len(STATUS_NAMES), dtype=np.int64)
        self.vignetted = 0
        self.ray_steps = 0

    def counts(self):
        """Trace status counts of every ray of this pass, plus the vignetted ones."""
        counts = {name: int(c) for name, c in zip(STATUS_NAMES, self.status_counts, strict=True)}
        counts["vignetted"] = int(self.vignetted)
        return counts


def _image_frame(setup, pass_, frame, field, positions, scales=None, extras=None):
    """Trace, render and locate every tracer of one frame, one batch at a time (stage 1–3).

    Parameters
    ----------
    setup : Setup
    pass_ : _Pass
        Receives the image columns of frame ``frame`` and the ray counts.
    field : rimcl.Field
        The refractive-index field of this frame (or the uniform one).
    positions : ndarray, shape (N, 2)
        Tracer positions at this frame.
    scales : ndarray, shape (N,), optional
        The reference pass's scale factors (None in the reference pass).
    extras : dict, optional
        ``sampler`` (a :class:`_RaySampler`), ``canvas`` (a :class:`FrameImage`) and
        ``bar`` (a progress bar), each optional.
    """
    if setup.engine is not None:
        setup.engine.image_frame(setup, pass_, frame, field, positions, scales, extras)
        return
    extras = extras or {}
    camera, scene, timings = setup.camera, setup.scene, setup.timings
    rays = camera.rays_per_tracer
    for first in range(0, len(positions), setup.batch):
        ids = np.arange(first, min(first + setup.batch, len(positions)))
        origins = np.repeat(scene.in_sheet(positions[ids]), rays, axis=0)
        directions = camera.directions(positions[ids]).reshape(-1, 3)
        start = time.perf_counter()
        result = trace_rays(field, origins, directions, x_end=scene.x_end, **setup.trace_options)
        timings["trace"] += time.perf_counter() - start
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir)
        pass_.status_counts += np.bincount(result.status, minlength=len(STATUS_NAMES))
        pass_.vignetted += int(np.count_nonzero(ok & ~collected))
        pass_.ray_steps += int(result.steps.sum())
        if extras.get("sampler") is not None:
            extras["sampler"].take(ids[0] * rays, result, collected)
        ok = ok.reshape(len(ids), rays)
        collected = collected.reshape(len(ids), rays)
        flags = np.where(ok.all(axis=1), 0, int(TracerFlag.RAYS_FAILED))
        flags |= np.where((ok & ~collected).any(axis=1), int(TracerFlag.RAYS_VIGNETTED), 0)
        columns = image_batch(
            setup.imaging,
            result.image_pos[:, 1:].reshape(len(ids), rays, 2),
            collected,
            1.0,
            flags,
            scales=None if scales is None else scales[ids],
            timings=timings,
            canvas=extras.get("canvas"),
        )
        for name, values in columns.items():
            pass_.images[name][frame, ids] = values
        if extras.get("bar") is not None:
            extras["bar"].update(len(ids))


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


def run_render(field=None, *, case=None, k_rho=None, config=None, reference=None, progress=False):
    """Run the synthetic PTV measurement of one refractive-index case.

    The stages: resolve the configuration against the field (:class:`Setup`); the true
    tracks and the reference images through a uniform medium (:func:`make_reference`,
    skipped when ``reference`` is given); the measured images through each frame's field;
    velocities, accelerations and the output tables.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file (default: the shipped sample).
    case : str, optional
        ``"C0"`` … ``"C4"``; or give ``k_rho``. Not for files storing ``delta_n``.
    k_rho : float, optional
        Gladstone–Dale product ``G`` (``n = 1 + G ρ``); 0 is a uniform medium.
    config : rimcl.config.MeasureConfig, optional
        Camera, renderer, integrator, tracers, time and run settings (defaults: the
        dataclasses' defaults).
    reference : Reference, optional
        From an earlier result with the same configuration: skips the reference pass.
    progress : bool
        Show a progress bar.

    Returns
    -------
    RenderResult
    """
    config = MeasureConfig() if config is None else config
    with ExitStack() as stack:
        source, source_name = _open_source(field, stack)
        case_name, g = _case_of(source, case, k_rho)
        streams = np.random.SeedSequence(int(config.tracers.seed)).spawn(2)
        setup, calibration = _setup(source, source_name, g, config, streams)
        count = len(setup.start_positions)
        frames = len(setup.frame_ids)
        bar = _progress(progress, (frames if reference is not None else 2 * frames) * count)
        try:
            if reference is None:
                reference = make_reference(setup, bar)
            elif reference.key != setup.key:
                changed = sorted(k for k in setup.key if reference.key.get(k) != setup.key[k])
                raise RimclError(
                    "the reference was made for another configuration (differs in: "
                    f"{', '.join(changed)})"
                )
            sampler = _RaySampler(
                count * setup.camera.rays_per_tracer,
                config.run.ray_sample,
                np.random.default_rng(streams[1]),
            )
            canvas = None
            if config.run.frame_image:
                pixel_size = setup.imaging.renderer.pixel_size
                extent = np.ceil(setup.scene.fov_size / pixel_size).astype(int)
                canvas = FrameImage(extent[0], extent[1], setup.imaging.renderer.full_scale)
            measured, delta_n_max = _measure(setup, g, reference, sampler, canvas, bar)
        finally:
            if bar is not None:
                bar.close()
        run_config = {
            **setup.key,
            "case": case_name,
            "k_rho": g,
            "start_frame": int(config.time.start_frame),
            "rays_per_batch": int(config.run.rays_per_batch),
            "ray_sample": int(config.run.ray_sample),
            "engine": config.run.engine,
            "tracking_substeps": TRACKING_SUBSTEPS,
            "reference_step": _reference_step(config.integrator.step, source),
        }
        if calibration is not None:
            run_config["auto"] = calibration
    result = _assemble(setup, run_config, reference, measured, sampler, delta_n_max)
    result.frame_image = None if canvas is None else canvas.counts
    return result


def _measure(setup, g, reference, sampler, canvas, bar):
    """The measured pass: every frame through its field, with the reference's scales."""
    measured = _Pass(len(setup.frame_ids), len(setup.start_positions))
    delta_n_max = 0.0
    for f, frame in enumerate(setup.frame_ids):
        field = _load_frame(setup.source, frame, g)
        delta_n_max = max(delta_n_max, field.delta_n_range)
        extras = {"bar": bar}
        if f == 0:
            extras.update(sampler=sampler, canvas=canvas)
        _image_frame(
            setup,
            measured,
            f,
            field,
            reference.tracks[f],
            scales=reference.images["scale"][f],
            extras=extras,
        )
        del field
    return measured, delta_n_max


#: Tracers whose rays calibrate ``interp="auto"`` (evenly spread over the tracer set).
CALIBRATION_TRACERS = 16


def _calibrate_interp(setup, g):
    """Choose the interpolation for ``interp="auto"`` once, on the first measured frame.

    The tolerance is 0.01 pixel of this camera. Every batch, frame and the reference then
    use the same choice, so the reference stays comparable (DESIGN §4.3).
    """
    from rimcl.calibrate import calibrate

    positions, camera = setup.start_positions, setup.camera
    chosen = np.unique(np.linspace(0, len(positions) - 1, CALIBRATION_TRACERS).astype(int))
    origins = np.repeat(setup.scene.in_sheet(positions[chosen]), camera.rays_per_tracer, axis=0)
    directions = camera.directions(positions[chosen]).reshape(-1, 3)
    record = calibrate(
        _load_frame(setup.source, setup.frame_ids[0], g),
        origins,
        directions,
        x_end=setup.scene.x_end,
        interp="auto",
        step=setup.trace_options["step"],
        precision=setup.trace_options["precision"],
        device=setup.trace_options["device"],
        tolerance=0.01 * setup.imaging.renderer.pixel_size,
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


def make_reference(setup, bar=None):
    """True tracks and the reference images (through a uniform medium) of every frame.

    Parameters
    ----------
    setup : Setup
    bar : tqdm progress bar, optional

    Returns
    -------
    Reference
    """
    start = time.perf_counter()
    tracks, true_velocity, outside = _true_motion(
        setup.source, setup.scene, setup.start_positions, setup.times, setup.frame_ids
    )
    setup.timings["track"] += time.perf_counter() - start
    uniform = _uniform_like(setup.source)
    reference_setup = dataclasses.replace(
        setup,
        trace_options={
            **setup.trace_options,
            "step": _reference_step(setup.trace_options["step"], setup.source),
        },
    )
    ref = _Pass(len(setup.frame_ids), len(setup.start_positions))
    for f in range(len(setup.frame_ids)):
        _image_frame(reference_setup, ref, f, uniform, tracks[f], extras={"bar": bar})
    if ref.status_counts[0] == ref.vignetted:
        raise RimclError(
            "no ray of any tracer reaches the camera even through a uniform medium: "
            "check the camera geometry (distance, view angle, aperture) against the field"
        )
    return Reference(
        key=setup.key,
        tracks=tracks,
        true_velocity=true_velocity,
        outside=outside,
        images=ref.images,
        ray_counts=ref.counts(),
        ray_steps=ref.ray_steps,
    )


def _kinematics(positions, true_velocity, flags, notes, dt):
    """Velocity (2 frames) and acceleration (3 frames) tables of every position kind."""
    frames, count = flags.shape
    velocity = acceleration = None
    if frames >= 2:
        velocity = {"id": np.arange(count)}
        for kind, track in positions.items():
            u = true_velocity if kind == "true" else first_difference(track, dt)
            velocity[f"u2_{kind}"], velocity[f"u3_{kind}"] = u[:, 0], u[:, 1]
        velocity["flags"] = np.bitwise_or.reduce(flags[:2], axis=0)
        velocity["notes"] = np.bitwise_or.reduce(notes[:2], axis=0)
    if frames >= 3:
        acceleration = {"id": np.arange(count)}
        for kind, track in positions.items():
            a = second_difference(track, dt)
            acceleration[f"a2_{kind}"], acceleration[f"a3_{kind}"] = a[:, 0], a[:, 1]
        acceleration["flags"] = np.bitwise_or.reduce(flags[:3], axis=0)
        acceleration["notes"] = np.bitwise_or.reduce(notes[:3], axis=0)
    return velocity, acceleration


def _assemble(setup, config, reference, measured, sampler, delta_n_max):
    """The output tables of one run (stage 4): positions, velocities, accelerations."""
    frames, count = reference.tracks.shape[:2]
    ref, meas = reference.images, measured.images
    truth_flags = np.where(reference.outside, int(TracerFlag.OUTSIDE_FIELD), 0)
    every = ref["flags"] | meas["flags"] | truth_flags
    flags, notes = every & int(EXCLUDING), every & int(NOTES)

    def rows(values):
        return np.asarray(values).reshape(-1)

    camera, renderer, scene = setup.camera, setup.imaging.renderer, setup.scene
    tracers = {
        "id": np.tile(np.arange(count), frames),
        "frame": np.repeat(np.arange(frames), count),
        "time": np.repeat(setup.times, count),
        "x2_true": rows(reference.tracks[..., 0]),
        "x3_true": rows(reference.tracks[..., 1]),
    }
    for suffix, images in (("ref", ref), ("meas", meas)):
        tracers[f"x2_{suffix}"] = rows(images["x2"])
        tracers[f"x3_{suffix}"] = rows(images["x3"])
    tracers.update(
        {
            "x2_opt": rows(meas["x2_opt"]),
            "x3_opt": rows(meas["x3_opt"]),
            "x2_opt_ref": rows(ref["x2_opt"]),
            "x3_opt_ref": rows(ref["x3_opt"]),
        }
    )
    for name in ("area", "perimeter", "circularity"):
        tracers[f"{name}_ref"] = rows(ref[name])
        tracers[f"{name}_meas"] = rows(meas[name])
    tracers.update(
        {
            "n_rays": np.full(frames * count, camera.rays_per_tracer, dtype=np.int64),
            "n_rays_ok": rows(meas["n_rays_ok"]),
            "n_rays_ok_ref": rows(ref["n_rays_ok"]),
            "peak_ref": rows(ref["peak"]),
            "peak_meas": rows(meas["peak"]),
            "flags": rows(flags),
            "notes": rows(notes),
            "flags_ref": rows(ref["flags"]),
            "flags_meas": rows(meas["flags"]),
        }
    )
    positions = {
        "true": reference.tracks,
        "ref": np.stack([ref["x2"], ref["x3"]], axis=-1),
        "meas": np.stack([meas["x2"], meas["x3"]], axis=-1),
        "opt": np.stack([meas["x2_opt"], meas["x3_opt"]], axis=-1),
        "opt_ref": np.stack([ref["x2_opt"], ref["x3_opt"]], axis=-1),
    }
    velocity, acceleration = _kinematics(positions, reference.true_velocity, flags, notes, setup.dt)
    attrs = {
        "rimcl_schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "case": config["case"],
        "k_rho": config["k_rho"],
        "delta_n_max": delta_n_max,
        "length_L": scene.depth,
        "pixel_size": renderer.pixel_size,
        "dt": setup.dt,
        "flag_names": json.dumps(flag_names()),
        "note_bits": int(NOTES),
        "n_tracers": count,
        "n_frames": frames,
        "rays_per_tracer": camera.rays_per_tracer,
        "renderer": renderer.kind,
        "camera": config["camera"]["camera"],
        "threshold": config["render"]["threshold"],
        "psf_sigma_px": renderer.psf_sigma,
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
        rays=sampler.table(camera.rays_per_tracer),
        ray_attrs=ray_attrs,
        reference=reference,
        timings=dict(setup.timings),
        frame_image=None,
        device=setup.trace_options["device"],
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

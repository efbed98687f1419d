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
import itertools
import json
import logging
import math
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.memory import check_field_memory, check_field_upload, check_render_memory
from rimcl.core.provenance import atomic_path, check_output, stamp_h5, to_json
from rimcl.fields.crop import CroppedSource
from rimcl.fields.field import Field
from rimcl.fields.media import index_from_density
from rimcl.imaging.centroid import EXCLUDING, NOTES, TracerFlag, flag_names
from rimcl.imaging.frames import Imaging, empty_columns, image_batch
from rimcl.imaging.render import FrameImage
from rimcl.imaging.sensor import MEASURED_PASS, REFERENCE_PASS
from rimcl.optics.camera import Scene, seed_tracers
from rimcl.optics.straight import straight_path_limit, straight_rays
from rimcl.optics.trace import STATUS_NAMES, default_step
from rimcl.optics.tracing import trace_rays
from rimcl.ptv.track import (
    SheetVelocity,
    integrate_tracks,
    second_differences,
    sliding_fit,
    track_acceleration,
    track_velocity,
)
from rimcl.scene.config import MeasureConfig

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
    true_velocity, true_acceleration : ndarray, shape (F, N, 2) or None
        Flow velocity ``u(x_k, t_k)`` and Lagrangian acceleration ``Du/Dt`` along the true
        tracks at each frame; None for a single frame.
    outside : ndarray, bool, shape (F, N)
        True positions outside the velocity grid (clamped fields only).
    images : dict of str to ndarray (F, N)
        Reference image columns (:data:`rimcl.imaging.frames.IMAGE_COLUMNS`; ``scale`` is the
        factor reused for the measured images).
    ray_counts : dict of str to int
        Trace status counts of all reference rays, plus ``vignetted``.
    ray_steps : int
        Integration steps of all reference rays.
    """

    key: dict
    tracks: np.ndarray
    true_velocity: np.ndarray
    true_acceleration: np.ndarray
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
    kinematics : dict of str to (dict of str to ndarray, or None)
        The tables ``velocity``, ``acceleration`` (the paper's differences),
        ``velocity_fit`` and ``acceleration_fit`` (sliding polynomial fit): one row per
        tracer and evaluation frame, frame-major; None where the run has too few frames.
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
    kinematics: dict
    rays: dict
    ray_attrs: dict
    reference: Reference
    timings: dict
    frame_image: np.ndarray
    device: object


def open_source(field, stack):
    """A field file reader: from a path, the shipped sample (None), or an open reader."""
    if field is None:
        from rimcl.fields.sample import sample_path

        field = sample_path()
    if isinstance(field, (str, Path)):
        from rimcl.fields.fieldfile import FieldFile

        return stack.enter_context(FieldFile(field)), str(Path(field).resolve())
    path = getattr(field, "path", None)
    return field, "<in memory>" if path is None else str(Path(path).resolve())


@dataclasses.dataclass(frozen=True)
class CaseIndex:
    """How one case turns the field file into refractive index.

    Attributes
    ----------
    name : str
        ``C0``…``C4``, ``G=…``, ``dT=…``/``dS=…`` or ``delta_n``.
    g : float
        Gladstone–Dale product (NaN for ``delta_n`` files and fluid cases).
    fluid : rimcl.fields.media.Fluid, optional
        For a fluid case: the fluid whose ``n(T)`` or ``n(S)`` maps the density.
    difference : float
        ``ΔT`` (K) or ``ΔS`` (g/kg) of a fluid case.
    light, heavy : float
        The field's two dimensionless densities (fluid cases).
    """

    name: str
    g: float
    fluid: object = None
    difference: float = 0.0
    light: float = 1.0
    heavy: float = 1.105

    def field(self, source, frame, time):
        """The field of a stored frame, or interpolated in time when ``frame`` is None."""
        if self.fluid is None:
            return _load_frame(source, frame, time, self.g)
        if self.difference == 0:
            # a uniform fluid images every ray to its tracer whatever its index: traced at
            # n = 1 (G = 0) it is the reference itself, bit for bit
            return _load_frame(source, frame, time, 0.0)
        # G = 1 gives δn = ρ - mean ρ and n_ref = 1 + mean ρ: the density, at any time
        unit = _load_frame(source, frame, time, 1.0)
        density = unit.delta_n.astype(np.float64) + (unit.n_ref - 1.0)
        index = index_from_density(
            density, self.fluid, self.difference, unit.gradient, self.light, self.heavy
        )
        return Field.from_arrays(
            index.delta_n,
            spacing=unit.spacing,
            origin=unit.origin,
            n_ref=index.n_ref,
            gradient=index.gradient,
            boundary=unit.boundary,
            attrs={**unit.attrs, "case": self.name},
        )


def case_of(source, case, k_rho, fluid_config):
    """The :class:`CaseIndex` of a case; files of δn carry their own index."""
    from rimcl.fields.cases import fluid_case, resolve_k_rho

    if getattr(source, "kind", "density") == "delta_n":
        if case is not None or k_rho is not None:
            raise RimclError("this field file stores delta_n directly; --case/--k-rho do not apply")
        return CaseIndex("delta_n", float("nan"))
    difference = None if case is None else fluid_case(case)
    if difference is None:
        return CaseIndex(*resolve_k_rho(case, k_rho))
    fluid = fluid_config.build()
    if fluid is None:
        raise RimclError(f"case {case} needs a fluid: set [fluid] kind (water, air, saltwater)")
    quantity, value = difference
    if (quantity == "salinity") != (fluid.kind == "saltwater"):
        raise RimclError(
            f"case {case}: a {fluid.kind} case varies the {fluid.unit}, not {quantity}"
        )
    return CaseIndex(
        str(case).strip(),
        float("nan"),
        fluid,
        value,
        float(fluid_config.light_density),
        float(fluid_config.heavy_density),
    )


def _load_frame(source, frame, time, k_rho):
    """The field of a stored frame, or interpolated in time when ``frame`` is None."""
    arguments = () if math.isnan(k_rho) else (k_rho,)
    if frame is None:
        return source.field_at(time, *arguments)
    return source.field(frame, *arguments)


def uniform_like(source):
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
    scene : rimcl.optics.camera.Scene
        Sheet, exit plane and field of view.
    camera : PlaneCamera or PupilCamera
    imaging : rimcl.imaging.frames.Imaging
    mie : rimcl.imaging.mie.MieWeights or None
        Ray weights (None: uniform).
    trace_options : dict
        ``interp``, ``precision``, ``step`` and ``device`` for :func:`rimcl.trace_rays`.
    frame_ids : list of int or None
        Stored frames imaged (None: interpolated in time).
    time : rimcl.scene.config.TimeConfig
    times : ndarray, shape (F,)
    dt : float
        Time between frames (NaN for one frame).
    start_positions : ndarray, shape (N, 2)
        Tracers at the first frame (those of the shard).
    first_tracer : int
        Index of the first of them among all tracers of the run.
    batch : int
        Tracers traced per batch.
    key : dict
        The case-independent configuration (a reusable reference must match it).
    timings : dict of str to float
        Seconds per stage, filled as the stages run.
    engine : rimcl.imaging.engine.DeviceEngine or None
        The device pipeline (``engine = "device"``); None for the NumPy engine.
    """

    source: object
    scene: Scene
    camera: object
    imaging: Imaging
    mie: object
    trace_options: dict
    frame_ids: list
    time: object
    times: np.ndarray
    dt: float
    start_positions: np.ndarray
    first_tracer: int
    batch: int
    key: dict
    timings: dict
    engine: object = None


def _check_memory(source, source_name, config, camera, imaging, device, frames):
    """Refuse, before anything is allocated, a run that cannot fit in host or device memory."""
    renderer = imaging.renderer
    check_field_memory(source.shape, f"a frame of {source_name}")
    check_render_memory(
        int(config.tracers.count),
        camera.rays_per_tracer,
        int(config.run.rays_per_batch),
        frames,
        renderer.max_window,
        math.ceil(float(np.max(camera.scene.fov_size)) / renderer.pixel_size),
        renderer.psf_sigma,
        bool(config.run.frame_image),
    )
    check_field_upload(
        source.shape, device, config.integrator.interp, f"the field of {source_name}"
    )


def _shard_range(shard, total):
    """``(first, stop)`` tracer indices of a shard (None: all ``total`` tracers)."""
    if shard is None:
        return 0, total
    first, stop = (int(v) for v in shard)
    if not 0 <= first < stop <= total:
        raise RimclError(f"a shard must be tracers first..stop within 0..{total}, got {shard}")
    return first, stop


def _frames_of(source, time_config):
    """Frames imaged: stored frame indices (None where interpolated), times and spacing.

    Frame ``k`` is at ``t_0 + k Δt``, ``t_0`` the time of stored frame ``start_frame`` and
    ``Δt`` the configured spacing (default: the stored spacing there). A time that is a
    stored frame's (to 1e-9 of ``Δt``) uses it; another is interpolated in time.
    """
    frames, start_frame = int(time_config.frames), int(time_config.start_frame)
    stored = np.asarray(source.times, dtype=np.float64)
    if not 0 <= start_frame < len(stored):
        raise RimclError(
            f"the start frame {start_frame} is not in the field (frames 0..{len(stored) - 1})"
        )
    if time_config.dt is not None:
        dt = float(time_config.dt)
    elif frames > 1:
        if start_frame + 1 >= len(stored):
            raise RimclError(
                f"{frames} frames from frame {start_frame} need frames up to "
                f"{start_frame + frames - 1}, but the field has {len(stored)} "
                f"(0..{len(stored) - 1})"
            )
        dt = float(stored[start_frame + 1] - stored[start_frame])
    else:
        dt = float("nan")
    times = stored[start_frame] + dt * np.arange(frames) if frames > 1 else stored[[start_frame]]
    slack = 1e-9 * (abs(dt) if frames > 1 else 1.0)
    if times[-1] > stored[-1] + slack:
        raise RimclError(
            f"{frames} frames {dt:g} apart from t = {times[0]:g} need the field up to "
            f"t = {times[-1]:g}, but it ends at t = {stored[-1]:g} "
            f"({len(stored)} frames, 0..{len(stored) - 1})"
        )
    nearest = np.clip(np.searchsorted(stored, times), 0, len(stored) - 1)
    frame_ids = []
    for t, j in zip(times, nearest, strict=True):
        candidates = [i for i in (j - 1, j) if 0 <= i < len(stored)]
        match = [i for i in candidates if abs(stored[i] - t) <= slack]
        frame_ids.append(int(match[0]) if match else None)
    if frames > 1:
        times = np.array(
            [stored[f] if f is not None else t for f, t in zip(frame_ids, times, strict=True)]
        )
        spacing = np.diff(times)
        if not np.allclose(spacing, dt, rtol=1e-6, atol=0):
            raise RimclError(
                f"frames {frame_ids} are not equally spaced in time ({times.tolist()}); "
                "differences and fits need equal spacing"
            )
    return frame_ids, times, dt


def _setup(source, source_name, case_index, config, streams, shard):
    """Resolve the configuration against the field: scene, camera, imaging, tracers, key."""
    from rimcl.core.device import describe_device, select_device

    frame_ids, times, dt = _frames_of(source, config.time)
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, config.x_sheet, config.depth
    )
    camera = config.camera.build(scene)
    sensor = config.sensor.build(config.renderer.bit_depth, config.tracers.seed)
    imaging = config.renderer.build(scene, camera, sensor)
    mie = config.mie.build(config.fluid.build())
    device = select_device(config.run.device, need_fp64=config.run.engine == "device")
    _check_memory(source, source_name, config, camera, imaging, device, len(frame_ids))
    every_tracer = seed_tracers(
        config.tracers.count,
        scene,
        np.random.default_rng(streams[0]),
        config.tracers.margin,
    )
    first, stop = _shard_range(shard, len(every_tracer))
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
        mie=mie,
        trace_options=trace_options,
        frame_ids=frame_ids,
        time=config.time,
        times=times,
        dt=dt,
        start_positions=every_tracer[first:stop],
        first_tracer=first,
        batch=max(1, int(config.run.rays_per_batch) // camera.rays_per_tracer),
        key={},
        timings={"track": 0.0, "trace": 0.0, "render": 0.0, "centroid": 0.0},
    )
    if config.run.engine == "device":
        from rimcl.imaging.engine import DeviceEngine

        setup.engine = DeviceEngine(
            camera, scene, imaging, device, setup.batch, first_tracer=setup.first_tracer, mie=mie
        )
    calibration = None
    if integrator.interp == "auto":
        calibration = _calibrate_interp(setup, case_index, every_tracer)
        trace_options["interp"] = calibration["interp"]
    setup.key = {
        "field": source_name,
        "box": None if config.box is None else [list(pair) for pair in config.box],
        "grid": {
            "origin": np.asarray(source.origin).tolist(),
            "spacing": np.asarray(source.spacing).tolist(),
            "shape_n3_n2_n1": list(source.shape),
            "boundary": source.boundary,
        },
        "frames": frame_ids,
        "times": times.tolist(),
        "scene": scene.describe(),
        "tracers": len(every_tracer),
        "shard": [first, stop],
        "seed": int(config.tracers.seed),
        "margin": float(config.tracers.margin),
        "camera": camera.describe(),
        "render": imaging.describe(),
        "mie": None if mie is None else mie.describe(),
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

    def __init__(self, pass_id, frames, tracers):
        self.pass_id = pass_id
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
        if field.is_uniform:  # the reference medium, G = 0: straight lines, no steps
            options = setup.trace_options
            limit = straight_path_limit(
                field, options["step"], scene.x_end, origins, directions, options["precision"]
            )
            result = straight_rays(field, origins, directions, x_end=scene.x_end, max_length=limit)
        else:
            result = trace_rays(
                field, origins, directions, x_end=scene.x_end, **setup.trace_options
            )
        timings["trace"] += time.perf_counter() - start
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir)
        pass_.status_counts += np.bincount(result.status, minlength=len(STATUS_NAMES))
        pass_.vignetted += int(np.count_nonzero(ok & ~collected))
        pass_.ray_steps += int(result.steps.sum())
        if extras.get("sampler") is not None:
            extras["sampler"].take((setup.first_tracer + ids[0]) * rays, result, collected)
        ok = ok.reshape(len(ids), rays)
        collected = collected.reshape(len(ids), rays)
        flags = np.where(ok.all(axis=1), 0, int(TracerFlag.RAYS_FAILED))
        flags |= np.where((ok & ~collected).any(axis=1), int(TracerFlag.RAYS_VIGNETTED), 0)
        if hasattr(camera, "image_points"):  # a lens behind a window images through it
            points = camera.image_points(result.end_pos, result.end_dir)
        else:
            points = result.image_pos[:, 1:]
        weights = 1.0 if setup.mie is None else setup.mie.weights(directions)
        columns = image_batch(
            setup.imaging,
            points.reshape(len(ids), rays, 2),
            collected,
            np.reshape(weights, (len(ids), rays)) if setup.mie is not None else weights,
            flags,
            scales=None if scales is None else scales[ids],
            timings=timings,
            canvas=extras.get("canvas"),
            noise=(pass_.pass_id, frame, setup.first_tracer + ids),
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
        """Keep the chosen rays among rays ``offset, offset + 1, ...`` of a whole batch.

        Parameters
        ----------
        offset : int
            Run-wide index of the batch's first ray.
        result : rimcl.optics.trace.TraceResult
            Every ray of the batch.
        collected : ndarray, bool, shape (rays of the batch,)
        """
        lo, hi = np.searchsorted(self.chosen, [offset, offset + len(result.status)])
        local = self.chosen[lo:hi] - offset
        self.keep(self.chosen[lo:hi], result, collected, local)

    def keep(self, rays, result, collected, rows=slice(None)):
        """Keep rays ``rays`` (run-wide indices, increasing), whose records are the
        ``rows`` of ``result`` and ``collected`` (default: all of them, in order)."""
        d0 = result.directions[rows]
        self.parts.append(
            {
                "ray": rays,
                "theta0": np.arctan2(np.linalg.norm(d0[:, 1:], axis=1), d0[:, 0]),
                "deflection": result.deflection[rows],
                "n_metric": np.linalg.norm(result.n_metric[rows], axis=1),
                "path_length": result.path_length[rows],
                "displacement": np.linalg.norm(
                    result.image_pos[rows, 1:] - result.origins[rows, 1:], axis=1
                ),
                "status": result.status[rows],
                "collected": collected[rows],
            }
        )

    def table(self, rays_per_tracer):
        """The kept rays, one column per name (empty columns when none was kept)."""
        empty = {
            "ray": np.int64,
            "theta0": np.float64,
            "deflection": np.float64,
            "n_metric": np.float64,
            "path_length": np.float64,
            "displacement": np.float64,
            "status": np.int8,
            "collected": bool,
        }
        parts = self.parts or [{name: np.zeros(0, kind) for name, kind in empty.items()}]
        table = {name: np.concatenate([p[name] for p in parts]) for name in empty}
        table["tracer_id"] = table["ray"] // rays_per_tracer
        return table


def _progress(enabled, total):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="tracer", desc="render", disable=None)


def _true_motion(source, scene, tracers, times):
    """True tracks ``(F, N, 2)``, velocity and acceleration along them (``(F, N, 2)`` each,
    None for one frame) and the outside-grid mask ``(F, N)``."""
    if len(times) == 1:
        return tracers[None], None, None, np.zeros((1, len(tracers)), dtype=bool)
    if not source.has_velocity:
        raise RimclError(
            f"{getattr(source, 'path', 'the field')} holds no velocity, which tracking the "
            "tracers over several frames needs (use --frames 1 for positions only)"
        )
    velocity = SheetVelocity.from_source(source, scene.x_sheet, times[0], times[-1])
    stored_spacing = float(np.min(np.diff(velocity.times))) if len(velocity.times) > 1 else 0
    substeps = TRACKING_SUBSTEPS
    if stored_spacing > 0:
        # RK4 steps no longer than the reference's 1/8 of the stored spacing
        substeps = max(
            substeps, math.ceil(TRACKING_SUBSTEPS * (times[1] - times[0]) / stored_spacing)
        )
    tracks = integrate_tracks(velocity, tracers, times, substeps)
    outside = np.stack([~velocity.inside(p) for p in tracks])
    true_velocity = track_velocity(velocity, tracks, times)
    true_acceleration = track_acceleration(velocity, tracks, times)
    return tracks, true_velocity, true_acceleration, outside


def run_render(
    field=None, *, case=None, k_rho=None, config=None, reference=None, shard=None, progress=False
):
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
    config : rimcl.scene.config.MeasureConfig, optional
        Camera, renderer, integrator, tracers, time and run settings (defaults: the
        dataclasses' defaults).
    reference : Reference, optional
        From an earlier result with the same configuration: skips the reference pass.
    shard : (int, int), optional
        Measure only tracers ``first..stop-1`` of the run (the same tracers, rays and
        numbers as in the whole run); :func:`merge_results` joins shards.
    progress : bool
        Show a progress bar.

    Returns
    -------
    RenderResult
    """
    config = MeasureConfig() if config is None else config
    with ExitStack() as stack:
        source, source_name = open_source(field, stack)
        if config.box is not None:
            source = CroppedSource(source, config.box)
        case_index = case_of(source, case, k_rho, config.fluid)
        streams = np.random.SeedSequence(int(config.tracers.seed)).spawn(2)
        setup, calibration = _setup(source, source_name, case_index, config, streams, shard)
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
                config.tracers.count * setup.camera.rays_per_tracer,
                config.run.ray_sample,
                np.random.default_rng(streams[1]),
            )
            canvas = None
            if config.run.frame_image:
                pixel_size = setup.imaging.renderer.pixel_size
                extent = np.ceil(setup.scene.fov_size / pixel_size).astype(int)
                canvas = FrameImage(extent[0], extent[1], setup.imaging.renderer.full_scale)
            measured, delta_n_max = _measure(setup, case_index, reference, sampler, canvas, bar)
        finally:
            if bar is not None:
                bar.close()
        run_config = {
            **setup.key,
            "case": case_index.name,
            "k_rho": None if math.isnan(case_index.g) else case_index.g,
            "fluid": None
            if case_index.fluid is None
            else {**case_index.fluid.describe(), "difference": case_index.difference},
            "start_frame": int(config.time.start_frame),
            "rays_per_batch": int(config.run.rays_per_batch),
            "ray_sample": int(config.run.ray_sample),
            "engine": config.run.engine,
            "tracking_substeps": TRACKING_SUBSTEPS,
            "reference_step": reference_step(config.integrator.step, source),
        }
        if calibration is not None:
            run_config["auto"] = calibration
    result = _assemble(setup, run_config, reference, measured, sampler, delta_n_max)
    result.frame_image = None if canvas is None else canvas.counts
    return result


def _measure(setup, case_index, reference, sampler, canvas, bar):
    """The measured pass: every frame through its field, with the reference's scales."""
    measured = _Pass(MEASURED_PASS, len(setup.frame_ids), len(setup.start_positions))
    delta_n_max = 0.0
    for f, frame in enumerate(setup.frame_ids):
        field = case_index.field(setup.source, frame, setup.times[f])
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


def _calibrate_interp(setup, case_index, positions):
    """Choose the interpolation for ``interp="auto"`` once, on the first measured frame.

    The tolerance is 0.01 pixel of this camera. Every batch, frame and the reference then
    use the same choice, so the reference stays comparable (DESIGN §4.3).
    """
    from rimcl.optics.auto_choice import calibrate

    camera = setup.camera
    chosen = np.unique(np.linspace(0, len(positions) - 1, CALIBRATION_TRACERS).astype(int))
    origins = np.repeat(setup.scene.in_sheet(positions[chosen]), camera.rays_per_tracer, axis=0)
    directions = camera.directions(positions[chosen]).reshape(-1, 3)
    record = calibrate(
        case_index.field(setup.source, setup.frame_ids[0], setup.times[0]),
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


def reference_step(step, source):
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
    tracks, true_velocity, true_acceleration, outside = _true_motion(
        setup.source, setup.scene, setup.start_positions, setup.times
    )
    setup.timings["track"] += time.perf_counter() - start
    uniform = uniform_like(setup.source)
    reference_setup = dataclasses.replace(
        setup,
        trace_options={
            **setup.trace_options,
            "step": reference_step(setup.trace_options["step"], setup.source),
        },
    )
    ref = _Pass(REFERENCE_PASS, len(setup.frame_ids), len(setup.start_positions))
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
        true_acceleration=true_acceleration,
        outside=outside,
        images=ref.images,
        ray_counts=ref.counts(),
        ray_steps=ref.ray_steps,
    )


def _frame_rows(ids, frames_used, columns, flags, notes, window):
    """One table of per-tracer estimates at evaluation frames, frame-major.

    ``columns`` maps a name to an ``(M, N)`` array over the ``M`` evaluation frames
    ``frames_used``; each row's flags and notes are the union over the ``window`` frames
    its estimate uses, starting at ``frames_used - offset`` (see :func:`kinematics_tables`).
    """
    frames_used = np.asarray(frames_used)
    first_frames, span = window
    union = np.stack([np.bitwise_or.reduce(flags[f : f + span], axis=0) for f in first_frames])
    union_notes = np.stack(
        [np.bitwise_or.reduce(notes[f : f + span], axis=0) for f in first_frames]
    )
    count = len(ids)
    table = {
        "id": np.tile(ids, len(frames_used)),
        "frame": np.repeat(frames_used, count),
    }
    table.update({name: values.reshape(-1) for name, values in columns.items()})
    table["flags"] = union.reshape(-1)
    table["notes"] = union_notes.reshape(-1)
    return table


def kinematics_tables(ids, positions, truth, flags, notes, dt, time_config):
    """Velocity and acceleration tables of every position kind (DESIGN §6.6, §13).

    Parameters
    ----------
    ids : ndarray, shape (N,)
        Tracer ids.
    positions : dict of str to ndarray (F, N, 2)
        Positions per kind (``true``, ``ref``, ``meas``, ``opt``, ``opt_ref``).
    truth : dict
        ``velocity`` and ``acceleration``, each ``(F, N, 2)``: ``u`` and ``Du/Dt`` along
        the true tracks.
    flags, notes : ndarray, int, shape (F, N)
    dt : float
        Frame spacing (time units).
    time_config : rimcl.scene.config.TimeConfig
        The fit window and order.

    ``velocity``: the paper's forward difference ``(x_{k+1} - x_k)/Δt`` at frames
    ``0 … F-2``, truth ``u(x_k, t_k)``; ``acceleration``: the second difference at frames
    ``1 … F-2``, truth the same difference of the true positions (the paper's);
    ``velocity_fit``, ``acceleration_fit``: a sliding polynomial fit over ``fit_window``
    frames at each window centre, truth ``u`` and ``Du/Dt`` there. Tables a run has too
    few frames for are None.
    """
    frames = len(flags)
    measured = {k: v for k, v in positions.items() if k != "true"}
    tables = dict.fromkeys(("velocity", "acceleration", "velocity_fit", "acceleration_fit"))
    if frames >= 2:
        columns = {}
        for kind, track in measured.items():
            u = (track[1:] - track[:-1]) / dt
            columns[f"u2_{kind}"], columns[f"u3_{kind}"] = u[..., 0], u[..., 1]
        u = truth["velocity"][:-1]
        columns["u2_true"], columns["u3_true"] = u[..., 0], u[..., 1]
        used = np.arange(frames - 1)
        tables["velocity"] = _frame_rows(ids, used, columns, flags, notes, (used, 2))
    if frames >= 3:
        columns = {}
        for kind, track in positions.items():
            a = second_differences(track, dt)
            columns[f"a2_{kind}"], columns[f"a3_{kind}"] = a[..., 0], a[..., 1]
        used = np.arange(1, frames - 1)
        tables["acceleration"] = _frame_rows(ids, used, columns, flags, notes, (used - 1, 3))
    window, order = int(time_config.fit_window), int(time_config.fit_order)
    if frames >= window:
        u_columns, a_columns = {}, {}
        centres = None
        for kind, track in measured.items():
            fit = sliding_fit(track, dt, window, order)
            centres = fit.centres
            u_columns[f"u2_{kind}"], u_columns[f"u3_{kind}"] = fit.velocity.transpose(2, 0, 1)
            a_columns[f"a2_{kind}"], a_columns[f"a3_{kind}"] = fit.acceleration.transpose(2, 0, 1)
        u, a = truth["velocity"][centres], truth["acceleration"][centres]
        u_columns["u2_true"], u_columns["u3_true"] = u[..., 0], u[..., 1]
        a_columns["a2_true"], a_columns["a3_true"] = a[..., 0], a[..., 1]
        span = (centres - window // 2, window)
        tables["velocity_fit"] = _frame_rows(ids, centres, u_columns, flags, notes, span)
        tables["acceleration_fit"] = _frame_rows(ids, centres, a_columns, flags, notes, span)
    return tables


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
    ids = np.arange(setup.first_tracer, setup.first_tracer + count)
    tracers = {
        "id": np.tile(ids, frames),
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
    truth = {"velocity": reference.true_velocity, "acceleration": reference.true_acceleration}
    kinematics = kinematics_tables(ids, positions, truth, flags, notes, setup.dt, setup.time)
    if reference.true_velocity is not None:
        for name, values in (("u", reference.true_velocity), ("a", reference.true_acceleration)):
            tracers[f"{name}2_true"] = rows(values[..., 0])
            tracers[f"{name}3_true"] = rows(values[..., 1])
    attrs = {
        "rimcl_schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "case": config["case"],
        "k_rho": float("nan") if config["k_rho"] is None else config["k_rho"],
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
        kinematics=kinematics,
        rays=sampler.table(camera.rays_per_tracer),
        ray_attrs=ray_attrs,
        reference=reference,
        timings=dict(setup.timings),
        frame_image=None,
        device=setup.trace_options["device"],
    )


def _join_frames(parts, frames):
    """Frame-major rows of shards ``(F * N_i,)`` joined into ``(F * sum N_i,)``."""
    return np.concatenate([p.reshape(frames, -1) for p in parts], axis=1).reshape(-1)


def merge_results(parts):
    """Join the results of consecutive shards of one run into the whole run's result.

    Parameters
    ----------
    parts : sequence of RenderResult
        From :func:`run_render` with ``shard`` ranges that tile ``0..N`` in order.

    Returns
    -------
    RenderResult
        Equal, table by table, to the result of the unsharded run.
    """
    parts = list(parts)
    first = parts[0]
    frames = int(first.attrs["n_frames"])
    ranges = [tuple(p.config["shard"]) for p in parts]
    total = int(first.config["tracers"])
    if (
        ranges[0][0] != 0
        or ranges[-1][1] != total
        or any(a[1] != b[0] for a, b in itertools.pairwise(ranges))
    ):
        raise RimclError(f"shards {ranges} do not tile the {total} tracers in order")

    def rows(tables):
        if tables[0] is None:
            return None
        evaluated = len(np.unique(tables[0]["frame"]))
        return {k: _join_frames([t[k] for t in tables], evaluated) for k in tables[0]}

    tracers = {k: _join_frames([p.tracers[k] for p in parts], frames) for k in first.tracers}
    ray_attrs = dict(first.ray_attrs)
    for name in ray_attrs:
        if name != "sampled_from_frame":
            ray_attrs[name] = sum(p.ray_attrs[name] for p in parts)
    refs = [p.reference for p in parts]
    key = {**refs[0].key, "shard": [0, total]}
    reference = Reference(
        key=key,
        tracks=np.concatenate([r.tracks for r in refs], axis=1),
        true_velocity=None
        if refs[0].true_velocity is None
        else np.concatenate([r.true_velocity for r in refs], axis=1),
        true_acceleration=None
        if refs[0].true_acceleration is None
        else np.concatenate([r.true_acceleration for r in refs], axis=1),
        outside=np.concatenate([r.outside for r in refs], axis=1),
        images={k: np.concatenate([r.images[k] for r in refs], axis=1) for k in refs[0].images},
        ray_counts={k: sum(r.ray_counts[k] for r in refs) for k in refs[0].ray_counts},
        ray_steps=sum(r.ray_steps for r in refs),
    )
    frame_image = None
    if first.frame_image is not None:
        stacked = np.sum([p.frame_image.astype(np.int64) for p in parts], axis=0)
        full_scale = int(first.config["render"]["full_scale"])
        frame_image = np.minimum(stacked, full_scale).astype(np.uint16)
    return RenderResult(
        attrs={
            **first.attrs,
            "n_tracers": total,
            "delta_n_max": max(p.attrs["delta_n_max"] for p in parts),
        },
        config={**first.config, "shard": [0, total]},
        tracers=tracers,
        kinematics={k: rows([p.kinematics[k] for p in parts]) for k in first.kinematics},
        rays={k: np.concatenate([p.rays[k] for p in parts]) for k in first.rays},
        ray_attrs=ray_attrs,
        reference=reference,
        timings={k: sum(p.timings[k] for p in parts) for k in first.timings},
        frame_image=frame_image,
        device=first.device,
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
        groups = {"tracers": result.tracers, **result.kinematics, "rays": result.rays}
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

    from rimcl.core.provenance import versions

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

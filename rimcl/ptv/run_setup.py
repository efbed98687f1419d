"""One measurement's configuration resolved against its field, before any ray is traced.

:func:`resolve_setup` turns a :class:`rimcl.scene.config.MeasureConfig` and an open field into
a :class:`Setup`: the frames imaged and their times, the scene, camera, imaging chain and ray
weights, the device (after the memory checks), the tracers of the shard, the calibrated
interpolation for ``interp = "auto"``, and the case-independent key a reusable reference
must match.
"""

import dataclasses
import logging
import math

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.core.memory import check_field_memory, check_field_upload, check_render_memory
from rimcl.imaging.frames import Imaging
from rimcl.optics.camera import Scene, seed_tracers

logger = logging.getLogger(__name__)


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


def resolve_setup(source, source_name, case_index, config, streams, shard):
    """Resolve the configuration against the field: scene, camera, imaging, tracers, key."""
    from rimcl.core.device import describe_device, select_device

    frame_ids, times, dt = _frames_of(source, config.time)
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, config.x_sheet, config.depth
    )
    # the case's mean index: the lens is focused through it, the tracers scatter in it
    medium_index = case_index.mean_index(source, frame_ids[0], times[0])
    camera = config.camera.build(scene, medium_index)
    sensor = config.sensor.build(config.renderer.bit_depth, config.tracers.seed)
    imaging = config.renderer.build(scene, camera, sensor)
    mie = config.mie.build(config.fluid.build(), medium_index)
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
            camera,
            scene,
            imaging,
            device,
            setup.batch,
            first_tracer=setup.first_tracer,
            mie=mie,
            tracers=stop - first,
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


#: Tracers whose rays calibrate ``interp="auto"`` (evenly spread over the tracer set).
CALIBRATION_TRACERS = 16


def _calibrate_interp(setup, case_index, positions):
    """Choose the interpolation for ``interp="auto"`` once, on the first measured frame.

    The tolerance is 0.01 pixel of this camera. Every batch, frame and the reference then
    use the same choice, so the reference stays comparable.
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

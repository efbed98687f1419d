"""PIV frames (:func:`image_frames`): every tracer's rays traced through one field per
exposure and deposited as pixel-integrated Gaussians into full frames, weighted by the
sheet intensity (and Mie intensities), then digitised by the camera's sensor (the imaging
model of :mod:`rimcl.piv.render`).

Two engines make the light of a frame: ``"device"`` (:class:`rimcl.imaging.frame_device.
DeviceFrames`: rays made, traced, imaged and splatted on the OpenCL device, one work-item
per tile of the frame, in a fixed order) and ``"numpy"`` (the reference: rays traced by
:func:`rimcl.trace_rays` and deposited by :func:`deposit_rays`). Through a uniform field
(the uniform-medium pair) both engines run the rays straight in closed form
(:func:`rimcl.optics.straight.straight_rays`; ``cl/fan.cl`` with ``RIMCL_STRAIGHT``). Both
digitise with the same :class:`rimcl.imaging.sensor.Sensor` on the host.
"""

import dataclasses
import time

import numpy as np
from scipy.special import ndtr

from rimcl.core.errors import RimclError
from rimcl.imaging.engine import tracer_directions
from rimcl.imaging.sensor import MEASURED_PASS, NoiseKey, Sensor
from rimcl.optics.aiming import aim_origins
from rimcl.optics.camera import LensCamera
from rimcl.optics.straight import straight_path_limit, straight_rays
from rimcl.optics.trace import STATUS_NAMES
from rimcl.optics.tracing import trace_rays
from rimcl.piv.imaging_config import sheet_intensity
from rimcl.scene.config import DEFAULT_RAYS_PER_BATCH, ENGINES

DEPOSIT_CHUNK = 1 << 15  # rays deposited at once: a few tens of MB of pixel stamps


@dataclasses.dataclass
class PivFrames:
    """A frame pair of one medium and what its rays did.

    Attributes
    ----------
    images : ndarray, uint16, shape (F, rows, columns)
        Camera counts of each exposure (A and B of a pair), row 0 at the top of the view
        (the highest ``x3``; :func:`rimcl.piv.imaging_config.frame_pixels`).
    optics : ndarray, float64, shape (F, N, 2)
        Per exposure and tracer, the light-weighted mean ``(x2, x3)`` of the image points
        of its collected rays (length units); NaN where none was collected.
    collected : ndarray, int, shape (F, N)
        Collected rays per exposure and tracer.
    ray_counts : dict of str to int
        Trace status counts of all rays of both exposures, plus ``vignetted`` and
        ``off_frame`` (collected rays imaged outside the frame, their light lost).
    saturated_pixels : list of int
        Pixels at the ADC's full scale, per exposure.
    seconds : dict of str to float
        ``trace`` and ``render`` (device engine: kernel times), ``digitize``, and ``wall``
        (all of :func:`image_frames`, the device engine's kernel builds included).
    scales : list of float
        Counts (with sensor noise: mean photoelectrons) per unit of light, per exposure.
    engine : str
    """

    images: np.ndarray
    optics: np.ndarray
    collected: np.ndarray
    ray_counts: dict
    saturated_pixels: list
    seconds: dict
    scales: list = None
    engine: str = "numpy"


def deposit_rays(light, pixels, weights, renderer):
    """Add the image of rays to a full frame, each a pixel-integrated Gaussian.

    Each ray adds ``weight · ∫∫ G_σ`` over every pixel within ``renderer.pad`` pixels of
    its own pixel: for a single ray exactly what :meth:`rimcl.imaging.render.Renderer.render`
    gives in :meth:`~rimcl.imaging.render.Renderer.window_for` its point. Unlike a window per
    tracer, the cost does not grow with how far refraction spreads a tracer's rays.

    Parameters
    ----------
    light : ndarray, float64, shape (rows, columns)
        The frame; added to in place. Light beyond its edges is lost.
    pixels : ndarray, shape (K, 2)
        Finite image points in pixel coordinates (column, row).
    weights : ndarray, shape (K,)
        Light per ray.
    renderer : rimcl.imaging.render.Renderer
        Its ``psf_sigma`` and ``pad``.

    Returns
    -------
    int
        Rays whose own pixel lies outside the frame.
    """
    rows, cols = light.shape
    offsets = np.arange(-renderer.pad, renderer.pad + 1)
    for first in range(0, len(pixels), DEPOSIT_CHUNK):
        points = pixels[first : first + DEPOSIT_CHUNK]
        cells = np.floor(points).astype(np.int64)[:, :, None] + offsets  # (K, 2, S)
        centred = cells - points[:, :, None]
        share = ndtr((centred + 1) / renderer.psf_sigma) - ndtr(centred / renderer.psf_sigma)
        light_of = weights[first : first + DEPOSIT_CHUNK, None, None]
        stamps = (share[:, 1, :, None] * light_of) * share[:, 0, None, :]  # (K, S, S)
        row_of = np.broadcast_to(cells[:, 1, :, None], stamps.shape)
        col_of = np.broadcast_to(cells[:, 0, None, :], stamps.shape)
        inside = (row_of >= 0) & (row_of < rows) & (col_of >= 0) & (col_of < cols)
        flat = row_of[inside] * cols + col_of[inside]
        light += np.bincount(flat, weights=stamps[inside], minlength=light.size).reshape(rows, cols)
    own = np.floor(pixels).astype(np.int64)
    return int(np.count_nonzero(np.any((own < 0) | (own >= [cols, rows]), axis=1)))


def _expose(
    field, positions, intensity, camera, scene, renderer, shape, options, batch, mie, aim_from=None
):
    """Light of one exposure with NumPy: trace every tracer's rays, deposit them in one frame.

    ``aim_from`` (``(N, 2)``): the points each tracer's rays are aimed from (default: the
    tracers' own ``(x2, x3)``).

    Returns
    -------
    light : ndarray, float64, shape ``shape``
        Unscaled light per pixel.
    optics : ndarray, shape (N, 2)
    collected : ndarray of int, shape (N,)
    totals : dict
        As :meth:`rimcl.imaging.frame_device.DeviceFrames.expose`'s.
    """
    rays = camera.rays_per_tracer
    aim_from = positions[:, 1:] if aim_from is None else aim_from
    light = np.zeros(shape)
    optics = np.full((len(positions), 2), np.nan)
    collected_count = np.zeros(len(positions), dtype=np.int64)
    totals = {
        "status": np.zeros(len(STATUS_NAMES), dtype=np.int64),
        "vignetted": 0,
        "off_frame": 0,
        "seconds": {"trace": 0.0, "render": 0.0},
    }
    for first in range(0, len(positions), batch):
        ids = np.arange(first, min(first + batch, len(positions)))
        start = time.perf_counter()
        directions = tracer_directions(camera, positions[ids], aim_from[ids])
        origins = np.repeat(positions[ids], rays, axis=0)
        if field.is_uniform:  # the uniform medium: straight lines, no steps (as cl/fan.cl)
            limit = straight_path_limit(
                field,
                options.get("step"),
                scene.x_end,
                origins,
                directions.reshape(-1, 3),
                options.get("precision", "f32c"),
            )
            result = straight_rays(
                field, origins, directions.reshape(-1, 3), x_end=scene.x_end, max_length=limit
            )
        else:
            result = trace_rays(
                field, origins, directions.reshape(-1, 3), x_end=scene.x_end, **options
            )
        middle = time.perf_counter()
        ok = result.status == 0
        # Snell at a wall takes each ray's own index where it leaves the field (as the fan kernel)
        collected = ok & camera.collected(result.end_pos, result.end_dir, result.exit_index)
        totals["status"] += np.bincount(result.status, minlength=len(STATUS_NAMES))
        totals["vignetted"] += int(np.count_nonzero(ok & ~collected))
        if isinstance(camera, LensCamera):
            # a lens images every ray onto the plane it is focused on (through its window)
            points = camera.image_points(result.end_pos, result.end_dir, result.exit_index)
        else:
            points = result.image_pos[:, 1:]
        lit = collected.reshape(len(ids), rays)
        counts = lit.sum(axis=1)
        collected_count[ids] = counts
        # the optics part is the plain mean of the collected rays' image points (a
        # centroid of ray positions, whatever light each ray carries)
        sums = np.where(lit[..., None], points.reshape(len(ids), rays, 2), 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            optics[ids] = np.where(counts[:, None] > 0, sums / counts[:, None], np.nan)
        weights = np.repeat(intensity[ids], rays)
        if mie is not None:
            weights = weights * mie.weights(directions).reshape(-1)
        totals["off_frame"] += deposit_rays(
            light, renderer.to_pixels(points[collected]), weights[collected], renderer
        )
        totals["seconds"]["trace"] += middle - start
        totals["seconds"]["render"] += time.perf_counter() - middle
    return light, optics, collected_count, totals


def reference_light(camera, scene, mie=None):
    """Light of all rays of an in-focus tracer at the sheet centre (each ray's weight: 1, or
    its Mie intensity): what :meth:`PivImaging.scale` divides by."""
    if mie is None:
        return float(camera.rays_per_tracer)
    centre = np.concatenate([[scene.x_sheet], scene.fov_centre])[None, :]
    return float(np.sum(mie.weights(tracer_directions(camera, centre))))


def image_frames(
    fields,
    positions,
    scene,
    camera,
    imaging,
    trace_options=None,
    rays_per_batch=DEFAULT_RAYS_PER_BATCH,
    engine="numpy",
    sensor=None,
    mie=None,
    noise=(MEASURED_PASS, 0),
    bar=None,
):
    """Frames of tracers seen through one field per exposure.

    Parameters
    ----------
    fields : sequence of F Field or AnalyticField
        The refractive-index field at each exposure.
    positions : ndarray, shape (F, N, 3)
        Tracer positions ``(x1, x2, x3)`` at each exposure (length units).
    scene : rimcl.optics.camera.Scene
    camera : PlaneCamera, PupilCamera or LensCamera
        Built by :meth:`rimcl.scene.config.CameraConfig.build`.
    imaging : PivImaging
    trace_options : dict, optional
        ``step``, ``interp``, ``precision``, ``device`` for :func:`rimcl.trace_rays`.
    rays_per_batch : int
        Rays traced per batch of the NumPy engine; bounds the memory.
    engine : {"numpy", "device"}
        Who traces and splats (see the module); both digitise alike.
    sensor : rimcl.imaging.sensor.Sensor, optional
        Default: the deterministic camera of ``imaging.bit_depth`` bits.
    mie : rimcl.imaging.mie.MieWeights, optional
        Weigh every ray by its Mie intensity (from its initial direction).
    noise : (int, int)
        ``(pass, first frame)`` of a noisy sensor's draws: exposure ``f`` draws with
        ``NoiseKey(pass, first + f, 0)`` over the frame's pixels.
    bar : optional
        Progress bar, advanced by tracers imaged.

    Returns
    -------
    PivFrames
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[2] != 3 or positions.shape[0] != len(fields):
        raise RimclError(
            f"tracer positions must have shape (frames, N, 3) with one field per frame, got "
            f"{positions.shape} for {len(fields)} fields"
        )
    if engine not in ENGINES:
        raise RimclError(f"unknown engine {engine!r}; choose from {ENGINES}")
    sensor = Sensor(bit_depth=int(imaging.bit_depth)) if sensor is None else sensor
    if int(sensor.bit_depth) != int(imaging.bit_depth):
        raise RimclError(
            f"the sensor has {sensor.bit_depth} bits but the PIV frames {imaging.bit_depth}"
        )
    options = dict(trace_options or {})
    thickness = imaging.thickness(scene, camera)
    renderer = imaging.renderer(scene, camera)
    shape = imaging.frame_shape(scene, camera)
    batch = max(1, int(rays_per_batch) // camera.rays_per_tracer)
    frames_engine = None
    # a lens's rays aimed at its pupil through each exposure's field (rimcl.optics.aiming),
    # the same aim for both engines, traced with the engines' own options
    aim_options = {"step": None, "interp": "trilinear", "precision": "f32c", **options}
    if engine == "device":
        from rimcl.core.device import select_device
        from rimcl.imaging.frame_device import DeviceFrames

        device = select_device(options.pop("device", None), need_fp64=True)
        # trace_rays' defaults where the caller gives none
        options = {"step": None, "interp": "trilinear", "precision": "f32c", **options}
        frames_engine = DeviceFrames(camera, scene, renderer, shape, device, mie)
    fixed = imaging.scale(reference_light(camera, scene, mie), renderer.psf_sigma, sensor)
    images, optics, collected, saturated, scales = [], [], [], [], []
    seconds = {"trace": 0.0, "render": 0.0, "digitize": 0.0}
    wall = time.perf_counter()
    status = np.zeros(len(STATUS_NAMES), dtype=np.int64)
    vignetted = off_frame = 0
    for index, (field, where) in enumerate(zip(fields, positions, strict=True)):
        intensity = sheet_intensity(where[:, 0], scene.x_sheet, thickness)
        started = time.perf_counter()
        aim_from = aim_origins(camera, field, where, aim_options)
        seconds["trace"] += time.perf_counter() - started
        if frames_engine is not None:
            light, mean_points, count, totals = frames_engine.expose(
                field, where, intensity, options, bar, aim_from
            )
        else:
            light, mean_points, count, totals = _expose(
                field,
                where,
                intensity,
                camera,
                scene,
                renderer,
                shape,
                options,
                batch,
                mie,
                aim_from,
            )
            if bar is not None:
                bar.update(len(where))
        status += totals["status"]
        vignetted += totals["vignetted"]
        off_frame += totals["off_frame"]
        for name, value in totals["seconds"].items():
            seconds[name] += value
        started = time.perf_counter()
        scale = fixed if imaging.scaling == "fixed" else imaging.frame_scale(light, sensor)
        counts, _ = sensor.digitize(light, scale, 0, 0, NoiseKey(noise[0], noise[1] + index, 0))
        seconds["digitize"] += time.perf_counter() - started
        saturated.append(int(np.count_nonzero(counts >= sensor.full_scale)))
        # stored with row 0 at the top of the view (highest x3), as cameras and PIV codes
        # read images (rimcl.piv.imaging_config.frame_pixels); rendered with rows along +x3
        images.append(counts[::-1].astype(np.uint16))
        optics.append(mean_points)
        collected.append(count)
        scales.append(float(scale))
    ray_counts = {name: int(c) for name, c in zip(STATUS_NAMES, status, strict=True)}
    ray_counts.update(vignetted=int(vignetted), off_frame=int(off_frame))
    seconds["wall"] = time.perf_counter() - wall
    return PivFrames(
        images=np.stack(images),
        optics=np.stack(optics),
        collected=np.stack(collected),
        ray_counts=ray_counts,
        saturated_pixels=saturated,
        seconds=seconds,
        scales=scales,
        engine=engine,
    )

"""A PIV frame pair rendered with NumPy (:func:`image_pair`): every tracer's rays traced
through one field per exposure and deposited as pixel-integrated Gaussians into full
frames, scaled to camera counts (the imaging model of :mod:`rimcl.piv.render`).
"""

import dataclasses
import time

import numpy as np
from scipy.special import ndtr

from rimcl.core.errors import RimclError
from rimcl.imaging.render import quantize
from rimcl.optics.camera import LensCamera
from rimcl.optics.trace import STATUS_NAMES
from rimcl.optics.tracing import trace_rays
from rimcl.piv.imaging_config import sheet_intensity
from rimcl.scene.config import (
    DEFAULT_RAYS_PER_BATCH,
)

DEPOSIT_CHUNK = 1 << 15  # rays deposited at once: a few tens of MB of pixel stamps


@dataclasses.dataclass
class PivFrames:
    """A frame pair of one medium and what its rays did.

    Attributes
    ----------
    images : ndarray, uint16, shape (2, rows, columns)
        Camera counts of exposures A and B.
    optics : ndarray, float64, shape (2, N, 2)
        Per exposure and tracer, the light-weighted mean ``(x2, x3)`` of the image points
        of its collected rays (length units); NaN where none was collected.
    collected : ndarray, int, shape (2, N)
        Collected rays per exposure and tracer.
    ray_counts : dict of str to int
        Trace status counts of all rays of both exposures, plus ``vignetted`` and
        ``off_frame`` (collected rays imaged outside the frame, their light lost).
    saturated_pixels : list of int
        Pixels clipped at full scale, per exposure.
    seconds : dict of str to float
        Wall time of ``trace`` and ``render``.
    """

    images: np.ndarray
    optics: np.ndarray
    collected: np.ndarray
    ray_counts: dict
    saturated_pixels: list
    seconds: dict


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


def _rays_of(camera, positions):
    """Initial unit directions of each tracer's rays, shape (B, K, 3).

    Aimed from each tracer's own depth at the camera's aim points; a lens behind a window
    solves its directions from the sheet (:meth:`LensCamera.directions`), which moves the
    rays of a tracer a fraction of the sheet thickness off the pupil points it aims at:
    the pupil test after tracing still decides which are collected.
    """
    if isinstance(camera, LensCamera) and camera.window is not None:
        return camera.directions(positions[:, 1:])
    aim = camera.aim_points()[None, :, :] - positions[:, None, :]
    return aim / np.linalg.norm(aim, axis=-1, keepdims=True)


def _expose(field, positions, intensity, camera, scene, renderer, shape, options, batch, totals):
    """Light of one exposure: trace every tracer's rays, render them into one frame.

    Returns
    -------
    light : ndarray, float64, shape ``shape``
        Unscaled light per pixel.
    optics : ndarray, shape (N, 2)
    collected : ndarray of int, shape (N,)
    """
    rays = camera.rays_per_tracer
    light = np.zeros(shape)
    optics = np.full((len(positions), 2), np.nan)
    collected_count = np.zeros(len(positions), dtype=np.int64)
    for first in range(0, len(positions), batch):
        ids = np.arange(first, min(first + batch, len(positions)))
        start = time.perf_counter()
        result = trace_rays(
            field,
            np.repeat(positions[ids], rays, axis=0),
            _rays_of(camera, positions[ids]).reshape(-1, 3),
            x_end=scene.x_end,
            **options,
        )
        middle = time.perf_counter()
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir)
        totals["status"] += np.bincount(result.status, minlength=len(STATUS_NAMES))
        totals["vignetted"] += int(np.count_nonzero(ok & ~collected))
        if isinstance(camera, LensCamera):
            # a lens images every ray onto the plane it is focused on (through its window)
            points = camera.image_points(result.end_pos, result.end_dir)
        else:
            points = result.image_pos[:, 1:]
        lit = collected.reshape(len(ids), rays)
        counts = lit.sum(axis=1)
        collected_count[ids] = counts
        # every ray of a tracer carries the same light, so the light-weighted mean image
        # point is the plain mean of its collected rays
        sums = np.where(lit[..., None], points.reshape(len(ids), rays, 2), 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            optics[ids] = np.where(counts[:, None] > 0, sums / counts[:, None], np.nan)
        totals["off_frame"] += deposit_rays(
            light,
            renderer.to_pixels(points[collected]),
            np.repeat(intensity[ids], rays)[collected],
            renderer,
        )
        totals["seconds"]["trace"] += middle - start
        totals["seconds"]["render"] += time.perf_counter() - middle
    return light, optics, collected_count


def image_pair(
    fields,
    positions,
    scene,
    camera,
    imaging,
    trace_options=None,
    rays_per_batch=DEFAULT_RAYS_PER_BATCH,
):
    """Frames A and B of tracers seen through one field per exposure.

    Parameters
    ----------
    fields : sequence of 2 Field or AnalyticField
        The refractive-index field at exposures A and B.
    positions : ndarray, shape (2, N, 3)
        Tracer positions ``(x1, x2, x3)`` at A and B (length units).
    scene : rimcl.optics.camera.Scene
    camera : PlaneCamera, PupilCamera or LensCamera
        Built by :meth:`rimcl.scene.config.CameraConfig.build`.
    imaging : PivImaging
    trace_options : dict, optional
        ``step``, ``interp``, ``precision``, ``device`` for :func:`rimcl.trace_rays`.
    rays_per_batch : int
        Rays traced per batch; bounds the memory.

    Returns
    -------
    PivFrames
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[0] != 2 or positions.shape[2] != 3:
        raise RimclError(f"tracer positions must have shape (2, N, 3), got {positions.shape}")
    thickness = imaging.thickness(scene, camera)
    renderer = imaging.renderer(scene, camera)
    shape = imaging.frame_shape(scene, camera)
    batch = max(1, int(rays_per_batch) // camera.rays_per_tracer)
    totals = {
        "status": np.zeros(len(STATUS_NAMES), dtype=np.int64),
        "vignetted": 0,
        "off_frame": 0,
        "seconds": {"trace": 0.0, "render": 0.0},
    }
    scale = imaging.scale(camera.rays_per_tracer, renderer.psf_sigma)
    images, optics, collected, saturated = [], [], [], []
    for field, where in zip(fields, positions, strict=True):
        intensity = sheet_intensity(where[:, 0], scene.x_sheet, thickness)
        light, mean_points, count = _expose(
            field,
            where,
            intensity,
            camera,
            scene,
            renderer,
            shape,
            trace_options or {},
            batch,
            totals,
        )
        counts, _ = quantize(light, scale, renderer.full_scale)
        saturated.append(int(np.count_nonzero(np.rint(light * scale) > renderer.full_scale)))
        images.append(counts.astype(np.uint16))
        optics.append(mean_points)
        collected.append(count)
    ray_counts = {name: int(c) for name, c in zip(STATUS_NAMES, totals["status"], strict=True)}
    ray_counts.update(vignetted=totals["vignetted"], off_frame=totals["off_frame"])
    return PivFrames(
        images=np.stack(images),
        optics=np.stack(optics),
        collected=np.stack(collected),
        ray_counts=ray_counts,
        saturated_pixels=saturated,
        seconds=totals["seconds"],
    )

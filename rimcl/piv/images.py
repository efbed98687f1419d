"""PIV image pairs through a refractive-index field, with their ground truth (DESIGN §15).

A PIV camera records full frames of many tracers lit by a light sheet of finite thickness:

- **tracers**: uniform at random in a slab ``|x1 - x_sheet| <= thickness`` over the field
  of view and a band of ``band`` pixels around it (so tracers enter the frames as well as
  leave them); ``density`` counts the tracers per pixel inside the sheet's 1/e² thickness
  (``|x1 - x_sheet| <= thickness / 2``), so twice as many are seeded;
- **light sheet**: Gaussian along ``x1``, ``I = exp(-8 (x1 - x_sheet)² / thickness²)``
  (``thickness`` is the full 1/e² width), peak 1 at ``x_sheet``;
- **motion**: with the field's full 3-D velocity, each tracer is carried by it from the
  first exposure to the second (RK4, cubic B-spline in space, linear in time between
  stored frames), so it moves across the sheet, its brightness changes, and pairs are
  lost as in experiments. A field that stores only the in-plane velocity on the sheet
  (``velocity_sheet``, as the shipped sample) moves every tracer, at any depth, with the
  sheet's ``(u2, u3)`` at its ``(x2, x3)`` and keeps its ``x1``: **out-of-plane motion and
  the loss of pairs it causes are then not modelled** (the truth file's ``motion``
  attribute says which);
- **imaging**: each tracer's rays (aimed by any camera of :mod:`rimcl.optics.camera`, built by
  :meth:`rimcl.scene.config.CameraConfig.build`) are traced by :func:`rimcl.trace_rays` from the
  tracer's own position through the field to the exit plane. The plane and pupil cameras
  image each ray where its straight backward extension meets the tracer's own plane
  ``x1 = const`` (``image_pos``; their depth of field is taken to cover the sheet, so
  perspective of out-of-plane positions is not modelled); the lens camera images it on
  the plane it is focused on (:meth:`LensCamera.image_points`, through its window if any),
  which adds the perspective and defocus of tracers off that plane, and sets the pixel
  size, frame and point spread. Every collected ray deposits a pixel-integrated Gaussian
  of σ = d/4 pixels (``d`` the particle image diameter) with weight = the sheet intensity
  at its tracer, by the exact renderer of :mod:`rimcl.imaging.render`, into one full frame (no Mie
  weights);
- **camera counts**: one scale factor for all frames (an isolated tracer at the sheet
  centre, all rays collected, centred on a pixel, peaks at ``peak_fraction`` of full
  scale), rounded and clipped to ``bit_depth`` bits; no sensor noise.

Each pair is imaged twice by the same code: through the field, and through a uniform medium
(``n = 1``, where every ray returns to its tracer). Frame arrays are ``(rows, columns)``
with rows along ``x3`` and columns along ``x2``: pixel ``(i, j)`` covers
``x2 ∈ fov_lo2 + [j, j+1) p``, ``x3 ∈ fov_lo3 + [i, i+1) p`` with ``p`` the pixel size (the
convention of :mod:`rimcl.imaging.render` and :mod:`rimcl.piv.analysis`; row 0 is the lowest
``x3``, so most viewers show ``x3`` pointing down).

Files (:func:`write_piv_render`): ``<prefix>_field_A.tif``, ``<prefix>_field_B.tif``,
``<prefix>_uniform_A.tif``, ``<prefix>_uniform_B.tif`` (16-bit TIFF) and
``<prefix>_truth.h5`` (``rimcl_schema = "piv_truth"``): per tracer, positions at both
exposures (``x1, x2, x3``, length units, and ``col, row``, pixels), sheet intensities and
the light-weighted mean image points of its collected rays per medium; the true
displacement averaged over each interrogation window of the final PIV grid; the motion
model (root attribute ``motion``), the configuration and versions.
"""

import dataclasses
import math
import time
from contextlib import ExitStack
from pathlib import Path

import h5py
import numpy as np
from scipy.ndimage import map_coordinates, spline_filter
from scipy.special import ndtr

from rimcl.core.errors import RimclError
from rimcl.core.provenance import atomic_path, check_output, stamp_h5
from rimcl.fields.crop import CroppedSource
from rimcl.imaging.render import TRUNCATE_SIGMAS, Renderer, quantize
from rimcl.optics.camera import LensCamera, Scene, seed_tracers
from rimcl.optics.trace import STATUS_NAMES
from rimcl.optics.tracing import trace_rays
from rimcl.piv.analysis import PivSettings, WindowGrid, write_tiff
from rimcl.ptv.track import SheetVelocity, integrate_tracks
from rimcl.scene.config import (
    DEFAULT_RAYS_PER_BATCH,
    CameraConfig,
    FluidConfig,
    IntegratorConfig,
    RunConfig,
)

TRUTH_SCHEMA = "piv_truth"
TRUTH_SCHEMA_VERSION = 1
#: Tracers are seeded over ``|x1 - x_sheet| <= SEED_HALF_WIDTH * thickness``, where the
#: sheet intensity falls to exp(-8) = 3e-4: beyond, a tracer adds less than a count.
SEED_HALF_WIDTH = 1.0
MEDIA = ("field", "uniform")
DEPOSIT_CHUNK = 1 << 15  # rays deposited at once: a few tens of MB of pixel stamps


def sheet_intensity(x1, x_sheet, thickness):
    """Light-sheet intensity at depth ``x1``: ``exp(-8 (x1 - x_sheet)² / thickness²)``.

    Parameters
    ----------
    x1 : array_like
        Depth (length units).
    x_sheet : float
        Sheet centre.
    thickness : float
        Full thickness between the 1/e² intensity points (length units).

    Returns
    -------
    ndarray
        Intensity relative to the sheet centre (1 there).
    """
    offset = (np.asarray(x1, dtype=np.float64) - x_sheet) / thickness
    return np.exp(-8.0 * offset**2)


@dataclasses.dataclass(frozen=True)
class PivImaging:
    """How PIV frames are made (module docstring).

    Attributes
    ----------
    pixels : int
        Pixels across the wider side of the field of view.
    density : float
        Particle image density: tracers per pixel inside the 1/e² sheet thickness.
    diameter : float
        Particle image diameter ``d = 4 σ`` (pixels), σ of the Gaussian point spread.
    sheet_thickness : float, optional
        Full 1/e² thickness of the light sheet (length units); default 8 pixels.
    bit_depth : int
        Bits per pixel, 8 to 16.
    peak_fraction : float
        Peak of an isolated in-focus tracer image, fraction of full scale, in (0, 1].
    band : float
        Width of the band around the field of view also seeded with tracers (pixels).
    """

    pixels: int = 512
    density: float = 0.03
    diameter: float = 3.0
    sheet_thickness: float = None
    bit_depth: int = 16
    peak_fraction: float = 0.5
    band: float = 16.0

    def __post_init__(self):
        if int(self.pixels) != self.pixels or self.pixels < 16:
            raise RimclError(f"a PIV frame needs at least 16 pixels across, got {self.pixels}")
        if not (np.isfinite(self.density) and 0 < self.density <= 1):
            raise RimclError(
                f"the particle image density must be in (0, 1] per pixel, got {self.density}"
            )
        if not (np.isfinite(self.diameter) and self.diameter > 0):
            raise RimclError(f"the particle image diameter must be positive, got {self.diameter}")
        thickness = self.sheet_thickness
        if thickness is not None and not (np.isfinite(thickness) and thickness > 0):
            raise RimclError(f"the light-sheet thickness must be positive, got {thickness}")
        if not 0 < self.peak_fraction <= 1:
            raise RimclError(f"the peak fraction must be in (0, 1], got {self.peak_fraction}")
        if not (np.isfinite(self.band) and self.band >= 0):
            raise RimclError(f"the seeding band must be >= 0 pixels, got {self.band}")

    @property
    def psf_sigma(self):
        """σ of the point spread (pixels), ``d / 4``."""
        return self.diameter / 4.0

    def pixel_size(self, scene, camera=None):
        """Pixel side (length units): a lens camera's own, else the wider field-of-view side
        over ``pixels``."""
        if isinstance(camera, LensCamera):
            return float(camera.pixel_size)
        return float(np.max(scene.fov_size)) / int(self.pixels)

    def thickness(self, scene, camera=None):
        """The sheet's 1/e² thickness (length units); default 8 pixels."""
        if self.sheet_thickness is None:
            return 8.0 * self.pixel_size(scene, camera)
        return float(self.sheet_thickness)

    def frame_shape(self, scene, camera=None):
        """Frame ``(rows, columns)`` (rows along ``x3``): a lens camera's sensor, else the
        field of view."""
        if isinstance(camera, LensCamera):
            return int(camera.pixels[1]), int(camera.pixels[0])
        extent = np.ceil(scene.fov_size / self.pixel_size(scene) - 1e-9).astype(int)
        return int(extent[1]), int(extent[0])

    def renderer(self, scene, camera=None):
        """The exact renderer of these frames (:class:`rimcl.imaging.render.Renderer`).

        A lens camera sets the pixel size, the frame origin (its sensor centred on the
        field of view) and the point spread (its tracer image); otherwise the frame starts
        at the field of view's corner and σ = ``diameter / 4``.
        """
        if isinstance(camera, LensCamera):
            origin = scene.fov_centre - 0.5 * camera.sensor_fov
            psf_sigma = camera.psf_sigma_px
        else:
            origin, psf_sigma = scene.fov_lo, self.psf_sigma
        # the frame is the only window: every ray lands in it or off the sensor
        return Renderer(
            "exact",
            self.pixel_size(scene, camera),
            tuple(float(v) for v in origin),
            float(psf_sigma),
            max(self.frame_shape(scene, camera)) + 2 * int(TRUNCATE_SIGMAS * psf_sigma + 2),
            int(self.bit_depth),
        )

    def scale(self, rays_per_tracer, psf_sigma):
        """Counts per unit of light: an in-focus tracer centred on a pixel, its point
        spread of σ ``psf_sigma`` pixels, peaks at ``peak_fraction`` of full scale (each of
        its rays carrying light 1)."""
        centre_pixel = (ndtr(0.5 / psf_sigma) - ndtr(-0.5 / psf_sigma)) ** 2
        full_scale = 2 ** int(self.bit_depth) - 1
        return self.peak_fraction * full_scale / (rays_per_tracer * centre_pixel)

    def describe(self, scene=None, camera=None):
        record = {
            "pixels": int(self.pixels),
            "particle_image_density_ppp": float(self.density),
            "particle_image_diameter_px": float(self.diameter),
            "psf_sigma_px": self.psf_sigma,
            "sheet_profile": "Gaussian, I = exp(-8 (x1 - x_sheet)^2 / thickness^2)",
            "sheet_thickness": self.sheet_thickness,
            "bit_depth": int(self.bit_depth),
            "peak_fraction": float(self.peak_fraction),
            "band_px": float(self.band),
            "seed_half_width_thicknesses": SEED_HALF_WIDTH,
            "renderer": "exact: pixel-integrated Gaussian per ray, cut at the renderer's pad",
        }
        if scene is not None:
            record.update(
                sheet_thickness=self.thickness(scene, camera),
                pixel_size=self.pixel_size(scene, camera),
                frame_rows_columns=list(self.frame_shape(scene, camera)),
                psf_sigma_px=self.renderer(scene, camera).psf_sigma,
            )
        return record


def seed_particles(scene, imaging, rng, camera=None):
    """Tracers over the frame plus the band around it, across the sheet's thickness.

    Parameters
    ----------
    scene : rimcl.optics.camera.Scene
    imaging : PivImaging
    rng : numpy.random.Generator
    camera : optional
        The camera (a lens camera sets the frame; others take the field of view).

    Returns
    -------
    ndarray, float64, shape (N, 3)
        Positions ``(x1, x2, x3)``.
    """
    renderer = imaging.renderer(scene, camera)
    pixel = renderer.pixel_size
    rows, cols = imaging.frame_shape(scene, camera)
    band = imaging.band * pixel
    lo = np.asarray(renderer.origin, dtype=np.float64) - band
    hi = lo + pixel * np.array([cols, rows]) + 2 * band
    seeded = dataclasses.replace(scene, fov_lo=lo, fov_hi=hi)
    area_px = float(np.prod(seeded.fov_size)) / pixel**2
    # density counts the tracers within the 1/e² thickness; the slab seeded is wider
    count = max(1, round(imaging.density * area_px * 2 * SEED_HALF_WIDTH))
    in_plane = seed_tracers(count, seeded, rng, margin=0.0)
    half = SEED_HALF_WIDTH * imaging.thickness(scene, camera)
    depth = scene.x_sheet + rng.uniform(-half, half, count)
    return np.column_stack([depth, in_plane])


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


def window_means(grid, col, row, values, weights):
    """Weighted means of per-tracer values over each interrogation window.

    A tracer belongs to window ``(r, c)`` when ``cols[c] <= col < cols[c] + size`` and
    ``rows[r] <= row < rows[r] + size`` (overlapping windows share tracers).

    Parameters
    ----------
    grid : rimcl.piv.analysis.WindowGrid
    col, row : ndarray, shape (N,)
        Tracer positions in pixels (columns, rows).
    values : ndarray, shape (N, K)
    weights : ndarray, shape (N,)
        Non-negative; rows with a non-finite value or weight are left out.

    Returns
    -------
    means : ndarray, float64, shape (rows, columns, K)
        NaN for a window without weight.
    total : ndarray, float64, shape (rows, columns)
        Sum of the weights in each window.
    """
    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    usable = np.isfinite(col) & np.isfinite(row) & np.isfinite(weights)
    usable &= np.all(np.isfinite(values), axis=1)
    col, row, values, weights = col[usable], row[usable], values[usable], weights[usable]
    n_rows, n_cols = grid.shape
    spacing = grid.spacing
    sums = np.zeros((n_rows * n_cols, values.shape[1]))
    total = np.zeros(n_rows * n_cols)
    reach = math.ceil(grid.size / spacing)
    base_c = np.floor((col - grid.cols[0]) / spacing).astype(np.int64)
    base_r = np.floor((row - grid.rows[0]) / spacing).astype(np.int64)
    # a tracer lies in at most ceil(size / spacing) windows along each axis, the ones whose
    # corners are at most ``size`` before it
    for back_r in range(reach):
        r = base_r - back_r
        in_r = (r >= 0) & (r < n_rows)
        in_r &= row >= grid.rows[np.clip(r, 0, n_rows - 1)]
        in_r &= row < grid.rows[np.clip(r, 0, n_rows - 1)] + grid.size
        for back_c in range(reach):
            c = base_c - back_c
            inside = in_r & (c >= 0) & (c < n_cols)
            inside &= col >= grid.cols[np.clip(c, 0, n_cols - 1)]
            inside &= col < grid.cols[np.clip(c, 0, n_cols - 1)] + grid.size
            flat = (r * n_cols + c)[inside]
            total += np.bincount(flat, weights=weights[inside], minlength=total.size)
            for k in range(values.shape[1]):
                sums[:, k] += np.bincount(
                    flat, weights=weights[inside] * values[inside, k], minlength=total.size
                )
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(total[:, None] > 0, sums / total[:, None], np.nan)
    return means.reshape(n_rows, n_cols, -1), total.reshape(n_rows, n_cols)


def pair_weights(positions, x_sheet, thickness):
    """Weight of each tracer in a window average: ``I_A · I_B`` (its correlation share)."""
    intensity = sheet_intensity(positions[..., 0], x_sheet, thickness)
    return intensity[0] * intensity[1]


def true_displacement(positions, renderer, grid, weights):
    """The true in-plane displacement averaged over each interrogation window (pixels).

    Tracers are assigned to windows by the midpoint of their two true image positions (a
    deformed window measures the displacement at its centre, central-difference).

    Parameters
    ----------
    positions : ndarray, shape (2, N, 3)
    renderer : rimcl.imaging.render.Renderer
        Maps ``(x2, x3)`` to pixels.
    grid : rimcl.piv.analysis.WindowGrid
        The final-pass windows.
    weights : ndarray, shape (N,)

    Returns
    -------
    dict
        ``x, y`` (window centres, px, shape (rows, columns)), ``dx, dy`` (px; NaN for an
        empty window), ``weight`` (sum of the weights) and ``tracers`` (count of tracers
        with weight above 1e-3 whose midpoint is in the window).
    """
    pixels = renderer.to_pixels(positions[..., 1:])
    middle = 0.5 * (pixels[0] + pixels[1])
    motion = pixels[1] - pixels[0]
    means, total = window_means(grid, middle[:, 0], middle[:, 1], motion, weights)
    bright = (weights > 1e-3).astype(np.float64)
    _, count = window_means(grid, middle[:, 0], middle[:, 1], np.zeros((len(bright), 1)), bright)
    x, y = np.meshgrid(grid.x.astype(np.float64), grid.y.astype(np.float64))
    return {
        "x": x,
        "y": y,
        "dx": means[..., 0],
        "dy": means[..., 1],
        "weight": total,
        "tracers": count.astype(np.int64),
    }


class FlowVelocity:
    """The 3-D flow velocity of a field file, continuous in space and time.

    Cubic B-spline in space (periodic for a periodic box; edge-clamped otherwise),
    linear in time between stored frames.

    Parameters
    ----------
    source : rimcl.fields.fieldfile.FieldFile
    frames : sequence of int
        Consecutive stored frames covering the times asked for.
    """

    def __init__(self, source, frames):
        if not source.has_full_velocity:
            raise RimclError(f"{source.path} holds no full 3-D velocity")
        self.times = np.asarray(source.times, dtype=np.float64)[list(frames)]
        self.origin = np.asarray(source.origin, dtype=np.float64)
        self.spacing = np.asarray(source.spacing, dtype=np.float64)
        self.periodic = source.boundary == "periodic"
        self.counts = np.asarray(source.shape)[::-1]
        mode = "grid-wrap" if self.periodic else "nearest"
        self._mode = mode
        self._coefficients = []
        for frame in frames:
            velocity = source.velocity(frame).astype(np.float64)
            self._coefficients.append(
                [spline_filter(velocity[..., c], order=3, mode=mode) for c in range(3)]
            )

    def _in_frame(self, index, points):
        nodes = (points - self.origin) / self.spacing
        if not self.periodic:
            nodes = np.clip(nodes, 0, self.counts - 1)
        where = nodes[:, ::-1].T  # arrays are (n3, n2, n1)
        return np.stack(
            [
                map_coordinates(c, where, order=3, mode=self._mode, prefilter=False)
                for c in self._coefficients[index]
            ],
            axis=-1,
        )

    def __call__(self, points, time):
        """Velocity ``(u1, u2, u3)`` at points ``(N, 3)`` and ``time``, shape (N, 3)."""
        points = np.asarray(points, dtype=np.float64)
        if len(self.times) == 1:
            return self._in_frame(0, points)
        upper = int(
            np.clip(np.searchsorted(self.times, time, side="right"), 1, len(self.times) - 1)
        )
        weight = (time - self.times[upper - 1]) / (self.times[upper] - self.times[upper - 1])
        weight = min(max(weight, 0.0), 1.0)
        return (1 - weight) * self._in_frame(upper - 1, points) + weight * self._in_frame(
            upper, points
        )


#: RK4 steps between the two exposures at least, and at least this many per stored frame
#: interval (the rule of the PTV tracks, :mod:`rimcl.ptv.imaging_passes`).
TRACKING_SUBSTEPS = 8
#: Default time between exposures (time units): on the shipped sample (velocity rms 0.14
#: on the sheet, frames 0.02 apart) 0.1 moves tracers 1.5 px rms and up to 4.5 px at 512 px,
#: the few pixels PIV is made for, from stored frames only.
DEFAULT_DT = 0.1
MOTION_3D = "3-D: tracers carried by the full velocity (u1, u2, u3); out-of-plane loss modelled"
MOTION_SHEET = (
    "in-plane only: the field file stores the velocity on the sheet plane alone, so every "
    "tracer, at any depth across the sheet, moves with the sheet's (u2, u3) and keeps its x1; "
    "out-of-plane motion and the loss of pairs it causes are NOT modelled"
)


@dataclasses.dataclass(frozen=True)
class PivConfig:
    """One PIV measurement besides the field, the case and the camera.

    Attributes
    ----------
    imaging : PivImaging
        How frames are made.
    settings : rimcl.piv.analysis.PivSettings
        The correlation; its last window and overlap also set the truth's windows.
    dt : float, optional
        Time between exposures A and B (time units); None: the field's stored spacing
        after ``start_frame``. Exposure B's field is a stored frame where ``t_A + dt`` is
        one, else interpolated in time (:meth:`FieldFile.field_at`).
    start_frame : int
        Stored frame of exposure A.
    box : sequence of 3 (lo, hi) pairs, optional
        Measure in this box cut out of the field (as :class:`rimcl.scene.config.MeasureConfig`).
    x_sheet, depth : float, optional
        Sheet centre and traced depth. Defaults: :meth:`Scene.from_grid`; a clamped field
        with full velocity moves its default sheet one seeding half-width inside the grid;
        a field with only the sheet velocity keeps the sheet on its stored plane.
    seed : int
        Seeds the tracers; the same seed gives the same tracers in every case.
    """

    imaging: PivImaging = PivImaging()
    settings: PivSettings = dataclasses.field(default_factory=PivSettings)
    dt: float = DEFAULT_DT
    start_frame: int = 0
    box: tuple = None
    x_sheet: float = None
    depth: float = None
    seed: int = 0

    def describe(self):
        return {
            "dt": self.dt,
            "start_frame": int(self.start_frame),
            "box": None if self.box is None else [list(pair) for pair in self.box],
            "x_sheet": self.x_sheet,
            "depth": self.depth,
            "seed": int(self.seed),
            "piv": self.settings.describe(),
        }


#: The camera of ``rimcl piv render`` and :func:`run_piv_render` unless one is given: the
#: paper's plane camera with 8 x 8 rays per tracer (a PIV frame holds thousands of tracers).
PIV_CAMERA = CameraConfig(kind="plane", fan=8)


def move_tracers(source, scene, start, times, frames):
    """True tracer positions at both exposures, and how they were moved.

    With the full velocity, tracers move in 3-D (:class:`FlowVelocity`), across the sheet
    too; with only the sheet velocity (``velocity_sheet``), every tracer moves with the
    sheet's in-plane velocity at its ``(x2, x3)`` and keeps its depth (module docstring).
    RK4 with at least :data:`TRACKING_SUBSTEPS` steps per stored frame interval.

    Parameters
    ----------
    source : FieldFile or CroppedSource
    scene : rimcl.optics.camera.Scene
    start : ndarray, shape (N, 3)
        Positions at exposure A.
    times : (float, float)
        Times of exposures A and B.
    frames : list of int
        The stored frames spanning them.

    Returns
    -------
    positions : ndarray, float64, shape (2, N, 3)
    motion : str
        :data:`MOTION_3D` or :data:`MOTION_SHEET`.
    """
    if not source.has_velocity:
        raise RimclError(f"{source.path} holds no velocity, which moving PIV tracers needs")
    stored = np.asarray(source.times, dtype=np.float64)[frames]
    spacing = float(np.min(np.diff(stored))) if len(stored) > 1 else 0.0
    substeps = TRACKING_SUBSTEPS
    if spacing > 0:
        substeps = max(substeps, math.ceil(TRACKING_SUBSTEPS * (times[1] - times[0]) / spacing))
    if getattr(source, "has_full_velocity", False):
        positions = integrate_tracks(FlowVelocity(source, frames), start, times, substeps)
        return positions, MOTION_3D
    velocity = SheetVelocity.from_source(source, scene.x_sheet, times[0], times[1])
    in_plane = integrate_tracks(velocity, start[:, 1:], times, substeps)
    depth = np.broadcast_to(start[None, :, :1], (2, len(start), 1))
    return np.concatenate([depth, in_plane], axis=-1), MOTION_SHEET


@dataclasses.dataclass
class PivReference:
    """The case-independent part of a PIV render: tracers, truth and uniform-medium frames.

    Attributes
    ----------
    key : dict
        The configuration it was made for (compared when it is reused).
    positions : ndarray, shape (2, N, 3)
        True tracer positions at exposures A and B.
    weights : ndarray, shape (N,)
        ``I_A · I_B`` per tracer.
    truth : dict
        :func:`true_displacement` on the final window grid.
    uniform : PivFrames
        The pair imaged through a uniform medium.
    """

    key: dict
    positions: np.ndarray
    weights: np.ndarray
    truth: dict
    uniform: PivFrames


@dataclasses.dataclass
class PivRender:
    """Everything :func:`write_piv_render` writes.

    Attributes
    ----------
    field : PivFrames
        The pair imaged through the refractive-index field.
    reference : PivReference
        Tracers, truth and uniform-medium pair; pass it to later cases to reuse it.
    config : dict
    case : str
    k_rho : float
        NaN for a fluid case (``dT=…``) or a file of δn.
    delta_n_max : float
        Largest ``max δn - min δn`` of the two exposures' fields.
    dt : float
        Time between exposures (time units).
    motion : str
        :data:`MOTION_3D` or :data:`MOTION_SHEET`.
    scene : rimcl.optics.camera.Scene
    camera : PlaneCamera, PupilCamera or LensCamera
    imaging : PivImaging
    renderer : rimcl.imaging.render.Renderer
        Pixel size, frame origin and point spread of the frames.
    device : pyopencl.Device
    """

    field: PivFrames
    reference: PivReference
    config: dict
    case: str
    k_rho: float
    delta_n_max: float
    dt: float
    motion: str
    scene: Scene
    camera: object
    imaging: PivImaging
    renderer: Renderer
    device: object

    @property
    def uniform(self):
        """The uniform-medium pair (from the reference)."""
        return self.reference.uniform

    @property
    def pixel_size(self):
        """Length units per pixel."""
        return self.renderer.pixel_size


def _exposure_times(source, start_frame, dt):
    """Times of exposures A and B, Δt, the stored frames spanning them, and B's stored
    frame (None where B falls between stored frames)."""
    times = np.asarray(source.times, dtype=np.float64)
    if not 0 <= start_frame < len(times):
        raise RimclError(
            f"start frame {start_frame} does not exist: the field has frames 0..{len(times) - 1}"
        )
    t_a = float(times[start_frame])
    if dt is None:
        if start_frame + 1 >= len(times):
            raise RimclError(
                f"frame {start_frame} is the last stored frame: give the time between exposures"
            )
        dt = float(times[start_frame + 1] - t_a)
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise RimclError(f"the time between exposures must be positive, got {dt}")
    t_b = t_a + dt
    slack = 1e-9 * max(1.0, abs(times[-1]))
    if t_b > times[-1] + slack:
        raise RimclError(
            f"the second exposure at t = {t_b:g} lies beyond the last stored frame "
            f"(t = {times[-1]:g}); use a shorter time between exposures (at most "
            f"{times[-1] - t_a:g} from frame {start_frame})"
        )
    last = int(np.searchsorted(times, t_b - slack, side="left"))
    stored_b = np.flatnonzero(np.abs(times - t_b) <= slack)
    frame_b = int(stored_b[0]) if stored_b.size else None
    t_b = min(t_b, float(times[-1]))
    return t_a, t_b, dt, list(range(start_frame, max(last, start_frame) + 1)), frame_b


def _piv_scene(source, piv):
    """The scene: as :meth:`Scene.from_grid`; the sheet of a field with only a sheet
    velocity sits on that plane; a clamped field's default sheet moves one seeding
    half-width inside it."""
    sheet_plane = None if getattr(source, "has_full_velocity", False) else _sheet_plane(source)
    x_sheet = piv.x_sheet if piv.x_sheet is not None else sheet_plane
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, x_sheet, piv.depth
    )
    if scene.periodic or sheet_plane is not None:
        # tracers below a clamped grid see its edge values (the clamped boundary)
        return scene
    half = SEED_HALF_WIDTH * piv.imaging.thickness(scene)
    low = float(source.origin[0])
    if x_sheet is None:
        return Scene.from_grid(
            source.origin, source.spacing, source.shape, source.boundary, low + half, piv.depth
        )
    if scene.x_sheet - half < low:
        raise RimclError(
            f"the tracers around the sheet x1 = {scene.x_sheet:g} (± {half:g}) reach below "
            f"the field (x1 >= {low:g}); move the sheet inside or make it thinner"
        )
    return scene


def _sheet_plane(source):
    """The ``x1`` of a stored sheet velocity, or None."""
    inner = getattr(source, "source", source)  # a CroppedSource reads its file's plane
    return getattr(inner, "velocity_sheet_x1", None)


def run_piv_render(
    field=None,
    *,
    case=None,
    k_rho=None,
    piv=None,
    camera=None,
    integrator=None,
    fluid=None,
    run=None,
    reference=None,
):
    """PIV frame pairs of one refractive-index case, through the field and a uniform medium.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file with velocity, full or on the sheet only (default: the
        shipped sample, which stores the sheet velocity only).
    case, k_rho :
        The case: ``"C0"`` … ``"C4"``, ``"G=…"``, ``"dT=…"``/``"dS=…"`` (with ``fluid``),
        or the Gladstone–Dale product ``k_rho`` (as :func:`rimcl.ptv.measure.run_render`).
    piv : PivConfig, optional
    camera : rimcl.scene.config.CameraConfig, optional
        Default :data:`PIV_CAMERA`. A lens camera sets the frame (its sensor, pixel size
        and tracer image); ``imaging.pixels`` and ``imaging.diameter`` then do not apply.
    integrator : rimcl.scene.config.IntegratorConfig, optional
        Interpolation, precision and step of :func:`rimcl.trace_rays` (not ``auto``).
    fluid : rimcl.scene.config.FluidConfig, optional
        The fluid of ``dT=…``/``dS=…`` cases.
    run : rimcl.scene.config.RunConfig, optional
        Device and rays per batch.
    reference : PivReference, optional
        From an earlier case with the same configuration: skips tracers, truth and the
        uniform-medium pair.

    Returns
    -------
    PivRender
    """
    from rimcl.core.device import describe_device, select_device
    from rimcl.ptv.field_source import case_of, open_source, reference_step, uniform_like

    piv = PivConfig() if piv is None else piv
    camera_config = PIV_CAMERA if camera is None else camera
    integrator = IntegratorConfig() if integrator is None else integrator
    run = RunConfig() if run is None else run
    if integrator.interp == "auto":
        raise RimclError("PIV frames take a fixed interpolation (not auto)")
    imaging, settings = piv.imaging, piv.settings
    with ExitStack() as stack:
        source, source_name = open_source(field, stack)
        if piv.box is not None:
            source = CroppedSource(source, piv.box)
        case_index = case_of(source, case, k_rho, FluidConfig() if fluid is None else fluid)
        t_a, t_b, dt, frames, frame_b = _exposure_times(source, int(piv.start_frame), piv.dt)
        scene = _piv_scene(source, piv)
        cam = camera_config.build(scene)
        device = select_device(run.device)
        renderer = imaging.renderer(scene, cam)
        grid = WindowGrid.for_image(
            imaging.frame_shape(scene, cam), int(settings.window), float(settings.overlap)
        )
        key = {
            "field": source_name,
            "box": piv.describe()["box"],
            "times": [t_a, t_b],
            "scene": scene.describe(),
            "camera": cam.describe(),
            "imaging": imaging.describe(scene, cam),
            "truth_windows": {"window": int(settings.window), "overlap": float(settings.overlap)},
            "seed": int(piv.seed),
            "trace": {
                "interp": integrator.interp,
                "precision": integrator.precision,
                "step": None if integrator.step is None else float(integrator.step),
                "device": describe_device(device),
            },
        }
        options = {"interp": integrator.interp, "precision": integrator.precision}
        options["device"] = device
        if reference is None:
            rng = np.random.default_rng(np.random.SeedSequence(int(piv.seed)))
            start = seed_particles(scene, imaging, rng, cam)
            positions, motion = move_tracers(source, scene, start, (t_a, t_b), frames)
            weights = pair_weights(positions, scene.x_sheet, imaging.thickness(scene, cam))
            uniform = uniform_like(source)
            uniform_frames = image_pair(
                (uniform, uniform),
                positions,
                scene,
                cam,
                imaging,
                {**options, "step": reference_step(integrator.step, source)},
                run.rays_per_batch,
            )
            reference = PivReference(
                key={**key, "motion": motion},
                positions=positions,
                weights=weights,
                truth=true_displacement(positions, renderer, grid, weights),
                uniform=uniform_frames,
            )
        elif {k: v for k, v in reference.key.items() if k != "motion"} != key:
            changed = sorted(k for k in key if reference.key.get(k) != key[k])
            raise RimclError(
                "the PIV reference was made for another configuration (differs in: "
                f"{', '.join(changed)})"
            )
        fields = (
            case_index.field(source, int(piv.start_frame), t_a),
            case_index.field(source, frame_b, t_b),
        )
        delta_n_max = max(f.delta_n_range for f in fields)
        measured = image_pair(
            fields,
            reference.positions,
            scene,
            cam,
            imaging,
            {**options, "step": integrator.step},
            run.rays_per_batch,
        )
    config = {
        **reference.key,
        "case": case_index.name,
        "k_rho": case_index.g,
        "dt": dt,
        "start_frame": int(piv.start_frame),
        "velocity_frames": frames,
        "n_tracers": int(reference.positions.shape[1]),
        "rays_per_batch": int(run.rays_per_batch),
        "image_rows": "rows along x3 (row 0 lowest), columns along x2",
    }
    return PivRender(
        field=measured,
        reference=reference,
        config=config,
        case=case_index.name,
        k_rho=case_index.g,
        delta_n_max=delta_n_max,
        dt=dt,
        motion=reference.key["motion"],
        scene=scene,
        camera=cam,
        imaging=imaging,
        renderer=renderer,
        device=device,
    )


def output_paths(prefix):
    """The files :func:`write_piv_render` writes for ``prefix``, by role.

    Returns
    -------
    dict of str to Path
        ``field_A``, ``field_B``, ``uniform_A``, ``uniform_B`` (TIFF) and ``truth`` (HDF5).
    """
    prefix = Path(prefix)
    paths = {
        f"{medium}_{frame}": prefix.with_name(f"{prefix.name}_{medium}_{frame}.tif")
        for medium in MEDIA
        for frame in "AB"
    }
    paths["truth"] = prefix.with_name(f"{prefix.name}_truth.h5")
    return paths


def check_outputs(prefix, overwrite=False):
    """Refuse, before any work, outputs that exist (unless ``overwrite``) or cannot be written."""
    for path in output_paths(prefix).values():
        check_output(path, overwrite)


def write_piv_render(prefix, result, overwrite=True):
    """Write the four TIFF frames and the ground-truth HDF5 file of a :class:`PivRender`.

    Parameters
    ----------
    prefix : str or Path
        Path prefix; see :func:`output_paths`.
    result : PivRender
    overwrite : bool

    Returns
    -------
    dict of str to Path
    """
    paths = output_paths(prefix)
    check_outputs(prefix, overwrite)
    frames = {"field": result.field, "uniform": result.uniform}
    for medium, pair in frames.items():
        for index, frame in enumerate("AB"):
            write_tiff(paths[f"{medium}_{frame}"], pair.images[index], result.config, overwrite)
    reference = result.reference
    pixels = result.renderer.to_pixels(reference.positions[..., 1:])
    thickness = result.imaging.thickness(result.scene, result.camera)
    with atomic_path(paths["truth"], overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = TRUTH_SCHEMA
        h5.attrs["schema_version"] = TRUTH_SCHEMA_VERSION
        h5.attrs["case"] = result.case
        h5.attrs["k_rho"] = result.k_rho
        h5.attrs["delta_n_max"] = result.delta_n_max
        h5.attrs["dt"] = result.dt
        h5.attrs["pixel_size"] = result.pixel_size
        h5.attrs["motion"] = result.motion
        h5.attrs["coordinates"] = (
            "positions x1, x2, x3 in field length units; col, row in pixels: pixel (row i, "
            "column j) covers x2 in fov_lo2 + [j, j+1) * pixel_size, x3 in fov_lo3 + [i, i+1) "
            "* pixel_size; TIFF rows follow x3 (row 0 lowest)"
        )
        particles = h5.create_group("particles")
        for index, frame in enumerate("AB"):
            particles[f"position_{frame}"] = reference.positions[index]
            particles[f"col_{frame}"] = pixels[index, :, 0]
            particles[f"row_{frame}"] = pixels[index, :, 1]
            particles[f"intensity_{frame}"] = sheet_intensity(
                reference.positions[index, :, 0], result.scene.x_sheet, thickness
            )
            for medium, pair in frames.items():
                particles[f"image_point_{medium}_{frame}"] = pair.optics[index]
                particles[f"rays_collected_{medium}_{frame}"] = pair.collected[index]
        truth = h5.create_group("truth")
        for name, values in reference.truth.items():
            truth[name] = values
        truth.attrs["definition"] = (
            "true in-plane displacement B - A (px), weighted by I_A * I_B, averaged over the "
            "tracers whose midpoint image position lies in the final interrogation window"
        )
        for medium, pair in frames.items():
            group = h5.create_group(f"rays_{medium}")
            for name, value in pair.ray_counts.items():
                group.attrs[name] = value
            group.attrs["saturated_pixels"] = np.asarray(pair.saturated_pixels)
        stamp_h5(h5, result.config, result.device)
    return paths

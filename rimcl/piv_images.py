"""PIV image pairs through a refractive-index field, with their ground truth (DESIGN §15).

A PIV camera records full frames of many tracers lit by a light sheet of finite thickness:

- **tracers**: uniform at random in a slab ``|x1 - x_sheet| <= thickness`` over the field
  of view and a band of ``band`` pixels around it (so tracers enter the frames as well as
  leave them); ``density`` counts the tracers per pixel inside the sheet's 1/e² thickness
  (``|x1 - x_sheet| <= thickness / 2``), so twice as many are seeded;
- **light sheet**: Gaussian along ``x1``, ``I = exp(-8 (x1 - x_sheet)² / thickness²)``
  (``thickness`` is the full 1/e² width), peak 1 at ``x_sheet``;
- **motion**: each tracer is carried by the 3-D flow velocity from the first exposure
  to the second (RK4, cubic B-spline in space, linear in time between stored frames), so
  it moves across the sheet and its brightness changes, and pairs are lost as in
  experiments;
- **imaging**: each tracer's rays (aimed by any camera of :mod:`rimcl.camera`) are traced
  by :func:`rimcl.trace_rays` through the field to the exit plane; the lens's depth of
  field is taken to cover the sheet, so each ray is imaged where its straight backward
  extension meets the tracer's own plane ``x1 = const`` (what ``trace_rays`` returns as
  ``image_pos``; perspective of out-of-plane positions is not modelled). Every collected ray
  deposits a pixel-integrated Gaussian of σ = d/4 pixels (``d`` the particle image
  diameter) with weight = the sheet intensity at its tracer, by the exact renderer of
  :mod:`rimcl.render`, into one full frame;
- **camera counts**: one scale factor for all frames (an isolated tracer at the sheet
  centre, all rays collected, centred on a pixel, peaks at ``peak_fraction`` of full
  scale), rounded and clipped to ``bit_depth`` bits; no sensor noise.

Each pair is imaged twice by the same code: through the field, and through a uniform medium
(``n = 1``, where every ray returns to its tracer). Frame arrays are ``(rows, columns)``
with rows along ``x3`` and columns along ``x2``: pixel ``(i, j)`` covers
``x2 ∈ fov_lo2 + [j, j+1) p``, ``x3 ∈ fov_lo3 + [i, i+1) p`` with ``p`` the pixel size (the
convention of :mod:`rimcl.render` and :mod:`rimcl.piv`; row 0 is the lowest ``x3``, so most
viewers show ``x3`` pointing down).

Files (:func:`write_piv_render`): ``<prefix>_field_A.tif``, ``<prefix>_field_B.tif``,
``<prefix>_uniform_A.tif``, ``<prefix>_uniform_B.tif`` (16-bit TIFF) and
``<prefix>_truth.h5`` (``rimcl_schema = "piv_truth"``): per tracer, positions at both
exposures (``x1, x2, x3``, length units, and ``col, row``, pixels), sheet intensities and
the light-weighted mean image points of its collected rays per medium; the true
displacement averaged over each interrogation window of the final PIV grid; the
configuration and versions.
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

from rimcl.camera import Scene, seed_tracers
from rimcl.errors import RimclError
from rimcl.piv import WindowGrid, write_tiff
from rimcl.provenance import atomic_path, check_output, stamp_h5
from rimcl.render import Renderer, quantize
from rimcl.trace import STATUS_NAMES, trace_rays
from rimcl.track import integrate_tracks

TRUTH_SCHEMA = "piv_truth"
TRUTH_SCHEMA_VERSION = 1
#: Tracers are seeded over ``|x1 - x_sheet| <= SEED_HALF_WIDTH * thickness``, where the
#: sheet intensity falls to exp(-8) = 3e-4: beyond, a tracer adds less than a count.
SEED_HALF_WIDTH = 1.0
MEDIA = ("field", "uniform")
DEFAULT_RAYS_PER_BATCH = 1 << 17  # rays traced per batch: ~40 MB of host memory


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
    max_window : int
        Largest per-tracer render window (pixels); rays beyond it are lost and counted.
    """

    pixels: int = 512
    density: float = 0.03
    diameter: float = 3.0
    sheet_thickness: float = None
    bit_depth: int = 16
    peak_fraction: float = 0.5
    band: float = 16.0
    max_window: int = 512

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

    def pixel_size(self, scene):
        """Pixel side (length units): the wider field-of-view side over ``pixels``."""
        return float(np.max(scene.fov_size)) / int(self.pixels)

    def thickness(self, scene):
        """The sheet's 1/e² thickness (length units); default 8 pixels."""
        if self.sheet_thickness is None:
            return 8.0 * self.pixel_size(scene)
        return float(self.sheet_thickness)

    def frame_shape(self, scene):
        """Frame ``(rows, columns)`` covering the field of view (rows along ``x3``)."""
        extent = np.ceil(scene.fov_size / self.pixel_size(scene) - 1e-9).astype(int)
        return int(extent[1]), int(extent[0])

    def renderer(self, scene):
        """The exact renderer of these frames (:class:`rimcl.render.Renderer`)."""
        return Renderer(
            "exact",
            self.pixel_size(scene),
            tuple(scene.fov_lo),
            self.psf_sigma,
            int(self.max_window),
            int(self.bit_depth),
        )

    def scale(self, rays_per_tracer):
        """Counts per unit of light: an in-focus tracer centred on a pixel peaks at
        ``peak_fraction`` of full scale (each of its rays carrying light 1)."""
        centre_pixel = (ndtr(0.5 / self.psf_sigma) - ndtr(-0.5 / self.psf_sigma)) ** 2
        full_scale = 2 ** int(self.bit_depth) - 1
        return self.peak_fraction * full_scale / (rays_per_tracer * centre_pixel)

    def describe(self, scene=None):
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
            "max_window_px": int(self.max_window),
            "seed_half_width_thicknesses": SEED_HALF_WIDTH,
            "renderer": "exact (pixel-integrated Gaussian per ray)",
        }
        if scene is not None:
            record.update(
                sheet_thickness=self.thickness(scene),
                pixel_size=self.pixel_size(scene),
                frame_rows_columns=list(self.frame_shape(scene)),
            )
        return record


def seed_particles(scene, imaging, rng):
    """Tracers over the field of view plus the band, across the sheet's thickness.

    Parameters
    ----------
    scene : rimcl.camera.Scene
    imaging : PivImaging
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, float64, shape (N, 3)
        Positions ``(x1, x2, x3)``.
    """
    pixel = imaging.pixel_size(scene)
    band = imaging.band * pixel
    seeded = dataclasses.replace(scene, fov_lo=scene.fov_lo - band, fov_hi=scene.fov_hi + band)
    area_px = float(np.prod(seeded.fov_size)) / pixel**2
    # density counts the tracers within the 1/e² thickness; the slab seeded is wider
    count = max(1, round(imaging.density * area_px * 2 * SEED_HALF_WIDTH))
    in_plane = seed_tracers(count, seeded, rng, margin=0.0)
    half = SEED_HALF_WIDTH * imaging.thickness(scene)
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
        ``outside_window`` (collected rays lost beyond the render window).
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


def _add_window(frame, window, image):
    """Add a window image into a frame, dropping what falls outside the frame."""
    rows, cols = frame.shape
    r0, r1 = max(window.row0, 0), min(window.row0 + window.height, rows)
    c0, c1 = max(window.col0, 0), min(window.col0 + window.width, cols)
    if r0 < r1 and c0 < c1:
        frame[r0:r1, c0:c1] += image[
            r0 - window.row0 : r1 - window.row0, c0 - window.col0 : c1 - window.col0
        ]


def _expose(field, positions, intensity, scene, camera, renderer, shape, options, batch, totals):
    """Light of one exposure: trace every tracer's rays, render them into one frame.

    Returns
    -------
    light : ndarray, float64, shape ``shape``
        Unscaled light per pixel.
    optics : ndarray, shape (N, 2)
    collected : ndarray of int, shape (N,)
    """
    aims = camera.aim_points()
    rays = len(aims)
    light = np.zeros(shape)
    optics = np.full((len(positions), 2), np.nan)
    collected_count = np.zeros(len(positions), dtype=np.int64)
    for first in range(0, len(positions), batch):
        ids = np.arange(first, min(first + batch, len(positions)))
        # the camera aims from each tracer's own depth, not from the sheet centre
        aim = aims[None, :, :] - positions[ids, None, :]
        aim /= np.linalg.norm(aim, axis=-1, keepdims=True)
        start = time.perf_counter()
        result = trace_rays(
            field,
            np.repeat(positions[ids], rays, axis=0),
            aim.reshape(-1, 3),
            x_end=scene.x_end,
            **options,
        )
        middle = time.perf_counter()
        ok = result.status == 0
        collected = ok & camera.collected(result.end_pos, result.end_dir)
        totals["status"] += np.bincount(result.status, minlength=len(STATUS_NAMES))
        totals["vignetted"] += int(np.count_nonzero(ok & ~collected))
        points = result.image_pos[:, 1:].reshape(len(ids), rays, 2)
        collected = collected.reshape(len(ids), rays)
        for k, tracer in enumerate(ids):
            kept = points[k][collected[k]]
            collected_count[tracer] = len(kept)
            if len(kept) == 0:
                continue
            # every ray of a tracer carries the same light, so the light-weighted mean
            # image point is the plain mean
            optics[tracer] = kept.mean(axis=0)
            pixels = renderer.to_pixels(kept)
            window = renderer.window_for(pixels)
            image, outside = renderer.render(pixels, np.full(len(kept), intensity[tracer]), window)
            totals["outside_window"] += outside
            _add_window(light, window, image)
        totals["seconds"]["trace"] += middle - start
        totals["seconds"]["render"] += time.perf_counter() - middle
    return light, optics, collected_count


def image_pair(
    fields,
    positions,
    scene,
    camera,
    imaging,
    thickness=None,
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
    scene : rimcl.camera.Scene
    camera : rimcl.camera.PlaneCamera or PupilCamera
    imaging : PivImaging
    thickness : float, optional
        Sheet thickness (default ``imaging.thickness(scene)``).
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
    thickness = imaging.thickness(scene) if thickness is None else float(thickness)
    renderer = imaging.renderer(scene)
    shape = imaging.frame_shape(scene)
    batch = max(1, int(rays_per_batch) // camera.rays_per_tracer)
    totals = {
        "status": np.zeros(len(STATUS_NAMES), dtype=np.int64),
        "vignetted": 0,
        "outside_window": 0,
        "seconds": {"trace": 0.0, "render": 0.0},
    }
    scale = imaging.scale(camera.rays_per_tracer)
    images, optics, collected, saturated = [], [], [], []
    for field, where in zip(fields, positions, strict=True):
        intensity = sheet_intensity(where[:, 0], scene.x_sheet, thickness)
        light, mean_points, count = _expose(
            field,
            where,
            intensity,
            scene,
            camera,
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
    ray_counts.update(vignetted=totals["vignetted"], outside_window=totals["outside_window"])
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
    grid : rimcl.piv.WindowGrid
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
    renderer : rimcl.render.Renderer
        Maps ``(x2, x3)`` to pixels.
    grid : rimcl.piv.WindowGrid
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
    source : rimcl.flow.fieldfile.FieldFile
    frames : sequence of int
        Consecutive stored frames covering the times asked for.
    """

    def __init__(self, source, frames):
        if not source.has_velocity:
            raise RimclError(f"{source.path} holds no velocity, which moving PIV tracers needs")
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


#: RK4 steps between the two exposures (the PTV tracks use as many per frame interval).
TRACKING_SUBSTEPS = 8


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
    delta_n_max : float
        Largest ``max δn - min δn`` of the two exposures' fields.
    dt : float
        Time between exposures (time units).
    pixel_size : float
        Length units per pixel.
    scene : rimcl.camera.Scene
    camera : rimcl.camera.PlaneCamera or PupilCamera
    imaging : PivImaging
    device : pyopencl.Device
    """

    field: PivFrames
    reference: PivReference
    config: dict
    case: str
    k_rho: float
    delta_n_max: float
    dt: float
    pixel_size: float
    scene: Scene
    camera: object
    imaging: PivImaging
    device: object

    @property
    def uniform(self):
        """The uniform-medium pair (from the reference)."""
        return self.reference.uniform


def _exposure_times(source, start_frame, dt):
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
    return t_a, min(t_b, float(times[-1])), dt, list(range(start_frame, max(last, start_frame) + 1))


def _piv_scene(source, imaging, x_sheet, depth):
    """The scene; a clamped field's default sheet sits one seeding half-width inside it."""
    scene = Scene.from_grid(
        source.origin, source.spacing, source.shape, source.boundary, x_sheet, depth
    )
    if x_sheet is None and not scene.periodic:
        half = SEED_HALF_WIDTH * imaging.thickness(scene)
        return Scene.from_grid(
            source.origin,
            source.spacing,
            source.shape,
            source.boundary,
            scene.x_sheet + half,
            depth,
        )
    if not scene.periodic:
        half = SEED_HALF_WIDTH * imaging.thickness(scene)
        low = float(source.origin[0])
        if scene.x_sheet - half < low:
            raise RimclError(
                f"the tracers around the sheet x1 = {scene.x_sheet:g} (± {half:g}) reach below "
                f"the field (x1 >= {low:g}); move the sheet inside or make it thinner"
            )
    return scene


def run_piv_render(
    field=None,
    *,
    case=None,
    k_rho=None,
    imaging=None,
    window=32,
    overlap=0.5,
    camera="plane",
    fan=8,
    pupil_rays=64,
    aperture_diameter=None,
    focal_length=None,
    f_number=None,
    camera_distance=None,
    view_angle=0.0,
    start_frame=0,
    dt=None,
    x_sheet=None,
    depth=None,
    interp="trilinear",
    precision="f32c",
    step=None,
    seed=0,
    rays_per_batch=DEFAULT_RAYS_PER_BATCH,
    reference=None,
    device=None,
):
    """PIV frame pairs of one refractive-index case, through the field and a uniform medium.

    Parameters
    ----------
    field : str, Path or FieldFile, optional
        A rimcl field file with velocity (default: the shipped sample).
    case, k_rho :
        The Gladstone–Dale case (as :func:`rimcl.measure.run_render`).
    imaging : PivImaging, optional
    window, overlap :
        The final interrogation windows (pixels, fraction) the truth is averaged over.
    camera, fan, pupil_rays, aperture_diameter, focal_length, f_number, camera_distance,
    view_angle :
        The camera, as :func:`rimcl.measure.run_render` (fewer rays by default: a PIV
        frame holds thousands of tracers).
    start_frame : int
        Stored frame of exposure A.
    dt : float, optional
        Time between exposures; default the time to the next stored frame. Exposure B's
        field is interpolated in time between stored frames.
    x_sheet, depth : float, optional
        Sheet centre and traced depth (defaults: :meth:`Scene.from_grid`; for a clamped
        field the sheet moves one seeding half-width inside the grid).
    interp, precision, step :
        Passed to :func:`rimcl.trace_rays` (``auto`` choices are not offered here).
    seed : int
        Seeds the tracers; the same seed gives the same tracers in every case.
    rays_per_batch : int
    reference : PivReference, optional
        From an earlier case with the same configuration: skips tracers, truth and the
        uniform-medium pair.
    device : str or pyopencl.Device, optional

    Returns
    -------
    PivRender
    """
    from rimcl.device import describe_device, select_device
    from rimcl.measure import (
        _case_of,
        _load_frame,
        _make_camera,
        _open_source,
        _reference_step,
        _uniform_like,
    )

    imaging = PivImaging() if imaging is None else imaging
    if interp == "auto" or step in ("auto", "adaptive"):
        raise RimclError("PIV frames take a fixed interpolation and step (not auto/adaptive)")
    with ExitStack() as stack:
        source, source_name = _open_source(field, stack)
        case_name, g = _case_of(source, case, k_rho)
        t_a, t_b, dt, frames = _exposure_times(source, int(start_frame), dt)
        scene = _piv_scene(source, imaging, x_sheet, depth)
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
        device = select_device(device)
        renderer = imaging.renderer(scene)
        grid = WindowGrid.for_image(imaging.frame_shape(scene), int(window), float(overlap))
        thickness = imaging.thickness(scene)
        key = {
            "field": source_name,
            "times": [t_a, t_b],
            "scene": scene.describe(),
            "camera": cam.describe(),
            "imaging": imaging.describe(scene),
            "truth_windows": {"window": int(window), "overlap": float(overlap)},
            "seed": int(seed),
            "trace": {
                "interp": interp,
                "precision": precision,
                "step": None if step is None else float(step),
                "device": describe_device(device),
            },
        }
        options = {"interp": interp, "precision": precision, "device": device}
        if reference is None:
            rng = np.random.default_rng(np.random.SeedSequence(int(seed)))
            start = seed_particles(scene, imaging, rng)
            motion = FlowVelocity(source, frames)
            positions = integrate_tracks(motion, start, [t_a, t_b], TRACKING_SUBSTEPS)
            weights = pair_weights(positions, scene.x_sheet, thickness)
            uniform = _uniform_like(source)
            uniform_frames = image_pair(
                (uniform, uniform),
                positions,
                scene,
                cam,
                imaging,
                thickness,
                {**options, "step": _reference_step(step, source)},
                rays_per_batch,
            )
            reference = PivReference(
                key=key,
                positions=positions,
                weights=weights,
                truth=true_displacement(positions, renderer, grid, weights),
                uniform=uniform_frames,
            )
        elif reference.key != key:
            changed = sorted(k for k in key if reference.key.get(k) != key[k])
            raise RimclError(
                "the PIV reference was made for another configuration (differs in: "
                f"{', '.join(changed)})"
            )
        fields = (_load_frame(source, frames[0], g), _field_at(source, t_b, g))
        delta_n_max = max(f.delta_n_range for f in fields)
        measured = image_pair(
            fields,
            reference.positions,
            scene,
            cam,
            imaging,
            thickness,
            {**options, "step": step},
            rays_per_batch,
        )
    config = {
        **key,
        "case": case_name,
        "k_rho": g,
        "dt": dt,
        "start_frame": int(start_frame),
        "velocity_frames": frames,
        "tracking_substeps": TRACKING_SUBSTEPS,
        "n_tracers": int(reference.positions.shape[1]),
        "rays_per_batch": int(rays_per_batch),
        "image_rows": "rows along x3 (row 0 lowest), columns along x2",
    }
    return PivRender(
        field=measured,
        reference=reference,
        config=config,
        case=case_name,
        k_rho=g,
        delta_n_max=delta_n_max,
        dt=dt,
        pixel_size=imaging.pixel_size(scene),
        scene=scene,
        camera=cam,
        imaging=imaging,
        device=device,
    )


def _field_at(source, time, k_rho):
    if math.isnan(k_rho):
        return source.field_at(time)
    return source.field_at(time, k_rho)


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
    renderer = result.imaging.renderer(result.scene)
    pixels = renderer.to_pixels(reference.positions[..., 1:])
    thickness = result.imaging.thickness(result.scene)
    with atomic_path(paths["truth"], overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = TRUTH_SCHEMA
        h5.attrs["schema_version"] = TRUTH_SCHEMA_VERSION
        h5.attrs["case"] = result.case
        h5.attrs["k_rho"] = result.k_rho
        h5.attrs["delta_n_max"] = result.delta_n_max
        h5.attrs["dt"] = result.dt
        h5.attrs["pixel_size"] = result.pixel_size
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

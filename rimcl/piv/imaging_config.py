"""How PIV frames are made (:class:`PivImaging`): the light sheet and the seeding of its
tracers; the model as a whole is described in :mod:`rimcl.piv.render`.
"""

import dataclasses

import numpy as np
from scipy.special import ndtr

from rimcl.core.errors import RimclError
from rimcl.imaging.render import TRUNCATE_SIGMAS, Renderer
from rimcl.optics.camera import LensCamera, seed_tracers

#: Tracers are seeded over ``|x1 - x_sheet| <= SEED_HALF_WIDTH * thickness``, where the
#: sheet intensity falls to exp(-8) = 3e-4: beyond, a tracer adds less than a count.
SEED_HALF_WIDTH = 1.0
#: How the frames are scaled to counts (:attr:`PivImaging.scaling`).
PIV_SCALINGS = ("fixed", "per_image")


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
    """How PIV frames are made (:mod:`rimcl.piv.render`).

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
    scaling : {"fixed", "per_image"}
        ``fixed``: one scale for every frame (an isolated in-focus tracer at the sheet
        centre peaks at ``peak_fraction`` of full scale; with sensor noise at the sensor's
        ``peak_electrons``); ``per_image``: each frame's brightest pixel is set there (a
        camera whose exposure is adjusted per image).
    """

    pixels: int = 512
    density: float = 0.03
    diameter: float = 3.0
    sheet_thickness: float = None
    bit_depth: int = 16
    peak_fraction: float = 0.5
    band: float = 16.0
    scaling: str = "fixed"

    def __post_init__(self):
        if int(self.pixels) != self.pixels or self.pixels < 16:
            raise RimclError(f"a PIV frame needs at least 16 pixels across, got {self.pixels}")
        if not (np.isfinite(self.density) and 0 < self.density <= 1):
            raise RimclError(
                f"the particle image density must be in (0, 1] per pixel, got {self.density}"
            )
        if not (np.isfinite(self.diameter) and self.diameter >= 1):
            raise RimclError(
                "the particle image diameter must be at least 1 pixel (no lens images a "
                f"particle smaller than a pixel), got {self.diameter}"
            )
        if int(self.bit_depth) != self.bit_depth or not 8 <= self.bit_depth <= 16:
            raise RimclError(f"the PIV frames' bit depth must be 8 to 16, got {self.bit_depth}")
        thickness = self.sheet_thickness
        if thickness is not None and not (np.isfinite(thickness) and thickness > 0):
            raise RimclError(f"the light-sheet thickness must be positive, got {thickness}")
        if not 0 < self.peak_fraction <= 1:
            raise RimclError(f"the peak fraction must be in (0, 1], got {self.peak_fraction}")
        if not (np.isfinite(self.band) and self.band >= 0):
            raise RimclError(f"the seeding band must be >= 0 pixels, got {self.band}")
        if self.scaling not in PIV_SCALINGS:
            raise RimclError(
                f"unknown PIV frame scaling {self.scaling!r}; choose from {PIV_SCALINGS}"
            )

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

    def peak_target(self, sensor=None):
        """The peak of the scaling: ``peak_fraction`` of full scale (counts), or with a
        noisy sensor its ``peak_electrons`` (e⁻)."""
        if sensor is not None and sensor.noise:
            return float(sensor.peak_electrons)
        return self.peak_fraction * (2 ** int(self.bit_depth) - 1)

    def scale(self, tracer_light, psf_sigma, sensor=None):
        """The ``fixed`` scale, counts (with sensor noise e⁻) per unit of light: an
        in-focus tracer at the sheet centre, centred on a pixel, its point spread of σ
        ``psf_sigma`` pixels and its rays carrying ``tracer_light`` in all (the ray count,
        or the sum of their Mie weights), peaks at :meth:`peak_target`."""
        centre_pixel = (ndtr(0.5 / psf_sigma) - ndtr(-0.5 / psf_sigma)) ** 2
        return self.peak_target(sensor) / (tracer_light * centre_pixel)

    def frame_scale(self, light, sensor=None):
        """The ``per_image`` scale of one frame: its brightest pixel at :meth:`peak_target`
        (NaN for a dark frame)."""
        peak = float(np.max(light)) if np.size(light) else 0.0
        return self.peak_target(sensor) / peak if peak > 0 else float("nan")

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
            "scaling": self.scaling,
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


#: Image axes of the PIV frames in sheet axes: x (columns) along +x2, y (rows) along -x3.
IMAGE_AXES = np.array([1.0, -1.0])


def frame_pixels(renderer, shape, points):
    """Sheet points ``(x2, x3)`` → PIV frame pixel coordinates ``(x, y)`` = (column, row).

    The convention of every PIV output of rimcl (frames, truth, vectors, exports): row 0
    at the top of the camera's view (the highest ``x3``), columns along ``x2``, pixel
    centres at integer coordinates (pixel ``(row i, column j)`` at ``(j, i)``), as
    scikit-image, trackpy and OpenPIV's image coordinates. The renderer's own grid
    (:meth:`rimcl.imaging.render.Renderer.to_pixels`: pixel ``j`` spans ``[j, j + 1)``, rows
    along ``+x3``) is flipped and shifted by half a pixel.

    Parameters
    ----------
    renderer : rimcl.imaging.render.Renderer
    shape : (int, int)
        Frame ``(rows, columns)``.
    points : ndarray, shape (..., 2)

    Returns
    -------
    ndarray, float64, shape (..., 2)
    """
    grid = renderer.to_pixels(points)
    return np.stack([grid[..., 0] - 0.5, shape[0] - 0.5 - grid[..., 1]], axis=-1)


def frame_points(renderer, shape, pixels):
    """The inverse of :func:`frame_pixels`: frame pixel coordinates → sheet ``(x2, x3)``."""
    pixels = np.asarray(pixels, dtype=np.float64)
    grid = np.stack([pixels[..., 0] + 0.5, shape[0] - 0.5 - pixels[..., 1]], axis=-1)
    return renderer.to_sheet(grid)

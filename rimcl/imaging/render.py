"""Tracer images on the image plane (the light sheet), one small window per tracer.

The image plane is the sheet, tiled by square pixels of side ``pixel_size`` (field
length units) starting at ``origin = (x2, x3)`` of the corner of pixel ``(0, 0)``. Pixel
coordinates ``e = (x - origin) / pixel_size`` put pixel ``i`` at ``[i, i + 1)``, its
centre at ``i + 0.5``. Window images are arrays ``(rows, columns) = (x3, x2)``, the
order of the field's ``(n3, n2)`` planes.

Two renderers, both producing a grey image of the camera's bit depth
(10 bits by default, as in the paper):

- ``paper``: each ray adds its weight to the pixel holding its image point ``r'``; the
  sum is Gaussian-filtered (σ pixels). Binning to pixels makes the image of an undistorted
  tracer (every ray in one pixel) sit exactly on a pixel centre: *pixel locking*.
- ``exact``: each ray deposits a Gaussian (σ pixels) integrated over every pixel. The
  Gaussian separates, so a window image is ``Gy.T @ Gx`` with ``Gx[k, i]`` the erf
  difference of ray ``k`` over column ``i``: one BLAS product per tracer.

A camera records integers: the image is scaled by one factor per tracer (set so the
reference image of that tracer, seen through a uniform field, peaks at full scale),
rounded and clipped to ``[0, 2**bits - 1]`` (``[0, 1023]`` for 10 bits). The same factor is
used for the distorted image, so the two images are comparable (never a per-image maximum).
The rounding moves centroids by a few 1e-4 pixel at 10 bits; a deeper camera lowers that
floor.
"""

import dataclasses

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.special import ndtr

from rimcl.core.errors import RimclError

RENDERERS = ("paper", "exact")
BIT_DEPTHS = range(8, 17)  # 8- to 16-bit cameras
FULL_SCALE = 1023  # the default 10-bit camera
# the Gaussian is cut at this many σ (scipy's gaussian_filter ``truncate``); windows are
# padded by as much so that no tracer image is cut by its window
TRUNCATE_SIGMAS = 4.0
_EXACT_CHUNK = 2048  # rays per BLAS product of the exact renderer


@dataclasses.dataclass(frozen=True)
class Window:
    """A rectangle of pixels: columns ``[col0, col0 + width)``, rows ``[row0, row0 + height)``."""

    col0: int
    row0: int
    width: int
    height: int

    @property
    def shape(self):
        return (self.height, self.width)


@dataclasses.dataclass(frozen=True)
class Renderer:
    """How tracer images are made.

    Attributes
    ----------
    kind : {"paper", "exact"}
    pixel_size : float
        Pixel side (field length units).
    origin : tuple of 2 float
        ``(x2, x3)`` of the outer corner of pixel ``(0, 0)``.
    psf_sigma : float
        Standard deviation of the Gaussian point-spread function (pixels).
    max_window : int
        Largest window side (pixels). A tracer whose rays spread wider is rendered in a
        window of this size centred on the median image point; rays outside it are lost
        and counted.
    bit_depth : int
        Bits per pixel of the camera (8 to 16); counts run to ``2**bit_depth - 1``.
    """

    kind: str
    pixel_size: float
    origin: tuple
    psf_sigma: float = 2.3
    max_window: int = 512
    bit_depth: int = 10

    def __post_init__(self):
        if self.kind not in RENDERERS:
            raise RimclError(f"unknown renderer {self.kind!r}; choose from {RENDERERS}")
        if not (np.isfinite(self.pixel_size) and self.pixel_size > 0):
            raise RimclError(f"the pixel size must be positive, got {self.pixel_size}")
        if not (np.isfinite(self.psf_sigma) and self.psf_sigma > 0):
            raise RimclError(f"the PSF sigma must be positive (pixels), got {self.psf_sigma}")
        if int(self.bit_depth) not in BIT_DEPTHS:
            raise RimclError(f"the camera bit depth must be 8 to 16, got {self.bit_depth}")
        if int(self.max_window) < 2 * self.pad + 1:
            raise RimclError(
                f"the largest window ({self.max_window} px) cannot hold one tracer image "
                f"of PSF sigma {self.psf_sigma} px"
            )

    @property
    def full_scale(self):
        """Largest count the camera records, ``2**bit_depth - 1``."""
        return 2 ** int(self.bit_depth) - 1

    @property
    def pad(self):
        """Pixels added around the image points: the PSF's cut-off radius, rounded up."""
        # scipy's gaussian_filter uses a kernel radius of int(truncate * sigma + 0.5)
        return int(TRUNCATE_SIGMAS * self.psf_sigma + 0.5) + 1

    def to_pixels(self, points):
        """Pixel coordinates of sheet points ``(x2, x3)``, shape (K, 2) → (K, 2)."""
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.origin)) / self.pixel_size

    def to_sheet(self, pixels):
        """Sheet positions ``(x2, x3)`` of pixel coordinates, shape (..., 2)."""
        return np.asarray(self.origin) + np.asarray(pixels) * self.pixel_size

    def window_for(self, pixels):
        """The window holding every image point plus the PSF, capped at ``max_window``.

        Parameters
        ----------
        pixels : ndarray, shape (K, 2), K >= 1
            Finite image points in pixel coordinates.

        Returns
        -------
        Window
        """
        lo = np.floor(pixels.min(axis=0)).astype(np.int64) - self.pad
        hi = np.floor(pixels.max(axis=0)).astype(np.int64) + self.pad + 1
        size = hi - lo
        limit = int(self.max_window)
        if np.any(size > limit):
            centre = np.floor(np.median(pixels, axis=0)).astype(np.int64)
            capped = size > limit
            lo = np.where(capped, centre - limit // 2, lo)
            size = np.where(capped, limit, size)
        return Window(int(lo[0]), int(lo[1]), int(size[0]), int(size[1]))

    def render(self, pixels, weights, window):
        """Unscaled image of rays in a window.

        Parameters
        ----------
        pixels : ndarray, shape (K, 2)
            Image points in pixel coordinates (columns along ``x2``, rows along ``x3``).
        weights : ndarray, shape (K,)
            Ray weights (light per ray).
        window : Window

        Returns
        -------
        image : ndarray, float64, shape (window.height, window.width)
            Light per pixel (same units as ``weights``).
        outside : int
            Rays whose image point lies outside the window (their light is lost).
        """
        local = pixels - np.array([window.col0, window.row0])
        inside = (
            (local[:, 0] >= 0)
            & (local[:, 0] < window.width)
            & (local[:, 1] >= 0)
            & (local[:, 1] < window.height)
        )
        outside = int(np.count_nonzero(~inside))
        local, weights = local[inside], weights[inside]
        if self.kind == "exact":
            return self._render_exact(local, weights, window), outside
        return self._render_paper(local, weights, window), outside

    def _render_exact(self, local, weights, window):
        def pixel_integrals(coords, count):
            edges = np.arange(count + 1, dtype=np.float64)
            cumulative = ndtr((edges[None, :] - coords[:, None]) / self.psf_sigma)
            return np.diff(cumulative, axis=1)

        image = np.zeros(window.shape)
        # rays in chunks: the erf tables of a chunk stay a few MB even in the largest window
        for start in range(0, len(local), _EXACT_CHUNK):
            part = slice(start, start + _EXACT_CHUNK)
            columns = pixel_integrals(local[part, 0], window.width)
            rows = pixel_integrals(local[part, 1], window.height)
            image += (rows * weights[part, None]).T @ columns
        return image

    def _render_paper(self, local, weights, window):
        cells = np.floor(local).astype(np.int64)
        flat = cells[:, 1] * window.width + cells[:, 0]
        binned = np.bincount(flat, weights=weights, minlength=window.width * window.height)
        binned = binned.reshape(window.shape)
        return gaussian_filter(binned, self.psf_sigma, mode="constant", truncate=TRUNCATE_SIGMAS)

    def describe(self):
        return {
            "renderer": self.kind,
            "pixel_size": self.pixel_size,
            "image_origin_x2_x3": list(self.origin),
            "psf_sigma_px": self.psf_sigma,
            "max_window_px": int(self.max_window),
            "bit_depth": int(self.bit_depth),
            "full_scale": self.full_scale,
        }


def scale_for(reference_image, full_scale=FULL_SCALE):
    """The scale factor set by a tracer's reference image (its peak → ``full_scale``).

    Returns
    -------
    float
        Counts per unit of light; NaN when the reference image is empty.
    """
    peak = float(np.max(reference_image)) if reference_image.size else 0.0
    return full_scale / peak if peak > 0 else float("nan")


def quantize(image, scale, full_scale=FULL_SCALE):
    """Counts the camera records: scaled, rounded, clipped to ``[0, full_scale]``.

    Returns
    -------
    counts : ndarray, float64, same shape as ``image``
    saturated : bool
        True if some pixel was clipped at full scale.
    """
    counts = np.rint(image * scale)
    saturated = bool(np.any(counts > full_scale))
    return np.clip(counts, 0, full_scale), saturated


class FrameImage:
    """A full-frame picture of all tracers, for looking at (never used for measuring).

    Window images are added in and clipped to full scale, like light on a sensor.

    Parameters
    ----------
    width, height : int
        Frame size (pixels along ``x2`` and ``x3``).
    full_scale : int
        The camera's largest count.
    """

    def __init__(self, width, height, full_scale=FULL_SCALE):
        self.counts = np.zeros((int(height), int(width)), dtype=np.uint16)
        self.full_scale = int(full_scale)

    def add(self, window, counts):
        """Add a window's counts (pixels outside the frame are dropped)."""
        height, width = self.counts.shape
        r0, r1 = max(window.row0, 0), min(window.row0 + window.height, height)
        c0, c1 = max(window.col0, 0), min(window.col0 + window.width, width)
        if r0 >= r1 or c0 >= c1:
            return
        part = counts[r0 - window.row0 : r1 - window.row0, c0 - window.col0 : c1 - window.col0]
        target = self.counts[r0:r1, c0:c1]
        target[...] = np.minimum(target + part, self.full_scale).astype(np.uint16)

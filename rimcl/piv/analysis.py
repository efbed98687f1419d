"""PIV: cross-correlation of an image pair into a displacement field.

Usable on any image pair (``rimcl piv analyze A.tif B.tif``). The algorithm:

- the background removed from both frames first: a local minimum (over squares of the
  first pass's window) smoothed by a box of the same side, so a constant or slowly
  varying background moves no vector (a constant one changes nothing at all);
- interrogation windows of ``window`` pixels on a regular grid with ``overlap``, all
  windows of a pass extracted at once (strided views) and correlated by batched real FFTs
  (circular correlation of the mean-subtracted windows, ``scipy.fft``);
- a window is a vector only where both frames hold particle signal in it, judged on the
  frames themselves (never on the deformed ones, whose interpolation spreads light into
  empty windows): a particle image's peak (a pixel no darker than its 8 neighbours) lies
  in the window and stands more than ``SIGNAL_THRESHOLD`` noise standard deviations above
  the window's median (:mod:`rimcl.piv.validity`); the tail of a particle centred outside does
  not count. A window without signal is invalid in every pass, whatever its correlation;
- the integer peak refined by a 3-point Gaussian fit per axis (a parabola where a
  neighbour of the peak is not positive), and the peak ratio (highest peak over the
  highest value outside a 5 x 5 neighbourhood of it) per vector;
- 2 or more passes with window deformation: both images are deformed by the previous
  displacement field (smoothed by a (1, 2, 1) filter, interpolated to every pixel by cubic
  splines) in the symmetric (central-difference) scheme ``A'(p) = A(p - d(p)/2)``,
  ``B'(p) = B(p + d(p)/2)``, the images interpolated by quintic B-splines (cubic ones left
  a bias of 0.01 px at quarter-pixel shifts of d = 3 px images); the next pass measures
  the residual at the window centre. Pixels whose sample in either image falls within
  ``EDGE_MARGIN`` pixels of its edge are blanked in both, so edges cut particle images at
  the same place in A' and B';
- after every pass, the normalized median test (Westerweel & Scarano 2005, 3 x 3
  neighbourhood, ``eps`` 0.2 px, threshold 2 on the magnitude of the two normalized
  component residuals): outliers are flagged (``valid`` False) and replaced by the median
  of their valid neighbours (``replaced`` True).

Coordinates (pixels): ``x`` runs along image columns, ``y`` along image rows (row 0 first
in the file: the top of rimcl's PIV frames); pixel centres lie at integer coordinates,
pixel ``(row i, column j)`` at ``(x, y) = (j, i)``, covering ``[j - 1/2, j + 1/2) x
[i - 1/2, i + 1/2)`` (as scikit-image, trackpy and OpenPIV before its
``transform_coordinates``). ``dx > 0`` is motion towards higher column indices, ``dy > 0``
towards higher row indices (down the image). A vector is the displacement of image B
relative to image A at its window centre.

Output file (``rimcl_schema = "piv"``, ``schema_version = 2``), :func:`write_piv`:
datasets ``x, y, dx, dy, peak_ratio`` (float64) and ``valid, replaced`` (bool), all of
shape ``(rows, columns)`` of the vector grid, with named dimensions ``row`` and ``column``
(the window centres' ``y`` and ``x``, px) and ``units``, for ``xarray.open_dataset``; root
attributes ``settings``, ``config``, ``versions`` (JSON), ``image_shape``, ``coordinates``.
"""

import dataclasses
import time
from pathlib import Path

import h5py
import numpy as np
import scipy.fft
from numpy.lib.stride_tricks import sliding_window_view
from scipy.interpolate import CubicSpline
from scipy.ndimage import (
    map_coordinates,
    minimum_filter,
    spline_filter,
    uniform_filter,
)

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.provenance import stamp_h5, to_json, versions
from rimcl.core.tables_h5 import label_grid
from rimcl.piv.validity import (
    noise_sigma,
    normalized_median_test,
    replace_outliers,
    window_signal,
)

SCHEMA = "piv"
SCHEMA_VERSION = 2  # 2: pixel centres at integer coordinates (1: at half-integers)
COORDINATES = (
    "x along image columns, y along image rows, row 0 first (pixels); pixel centres at "
    "integer coordinates: pixel (row i, column j) at (x, y) = (j, i), covering "
    "[j - 1/2, j + 1/2) x [i - 1/2, i + 1/2); dx, dy: displacement of image B relative to "
    "image A at the window centre (pixels), dy > 0 down the image"
)
#: Half-width of the neighbourhood of the highest correlation peak left out when looking
#: for the second peak (pixels): a particle image of d ≈ 3 px spreads the peak over ±2 px.
SECOND_PEAK_EXCLUSION = 2
#: B-spline order of the image deformation (quintic).
DEFORM_ORDER = 5
#: Samples closer than this to an image edge (pixels) are blanked in both deformed images:
#: the B-spline there depends on the zeros assumed beyond the edge. With 0, windows at the
#: edges of a 2 px shift kept a bias of 0.01–0.02 px; with 2, below 1e-3 px.
EDGE_MARGIN = 2


#: Peak host bytes per image pixel of a PIV analysis: the frames in float64, their
#: backgrounds, B-spline coefficients, deformed frames, masks and displacement fields
#: (tracemalloc: 32 for one pass, 86-90 with deformation).
PIV_BYTES_PER_PIXEL = 128
#: Peak host bytes per pixel of all windows of a pass (windows overlap, so this is
#: windows x side²): extracted windows of both frames, float64 copies, spectra,
#: correlation planes and the signal test (tracemalloc: 56-57).
PIV_BYTES_PER_WINDOW_PIXEL = 64


@dataclasses.dataclass(frozen=True)
class PivSettings:
    """How an image pair is correlated.

    Attributes
    ----------
    window : int
        Interrogation window side of the last pass (pixels, even, >= 8).
    overlap : float
        Overlap of neighbouring windows, fraction of the window in ``[0, 1)``.
    passes : int
        Correlation passes, 1 to 5; passes after the first deform the images.
    first_window : int, optional
        Window side of the first pass (pixels, >= ``window``); the sides shrink
        geometrically to ``window`` over the passes. Default ``window``.
    outlier_eps : float
        ``eps`` of the normalized median test (pixels), the noise floor of the residuals.
        0.2 (the upper end of Westerweel & Scarano's 0.1–0.2): with 0.1, rendered pairs of
        the sample's flow (gradients of ~0.05 px/px at 32 px windows) had 4 % of their
        valid vectors replaced, mostly at the edges, and 0.102/0.105 px rms against the
        truth instead of 0.060/0.089.
    outlier_threshold : float
        Normalized residual above which a vector is an outlier.
    """

    window: int = 32
    overlap: float = 0.5
    passes: int = 3
    first_window: int = None
    outlier_eps: float = 0.2
    outlier_threshold: float = 2.0

    def __post_init__(self):
        if int(self.window) != self.window or self.window < 8 or self.window % 2:
            raise RimclError(
                f"the PIV window must be an even number of pixels >= 8, got {self.window}"
            )
        if not 0 <= self.overlap < 1:
            raise RimclError(f"the window overlap must be in [0, 1), got {self.overlap}")
        if int(self.passes) != self.passes or not 1 <= self.passes <= 5:
            raise RimclError(f"the number of PIV passes must be 1 to 5, got {self.passes}")
        first = self.window if self.first_window is None else self.first_window
        if int(first) != first or first < self.window or first % 2:
            raise RimclError(
                f"the first window must be an even number of pixels >= the window "
                f"({self.window}), got {self.first_window}"
            )
        if self.passes == 1 and first != self.window:
            raise RimclError(
                f"a first window ({self.first_window} px) needs 2 or more passes: one pass "
                f"correlates the {self.window} px windows only"
            )
        if not (np.isfinite(self.outlier_eps) and self.outlier_eps > 0):
            raise RimclError(f"the outlier eps must be positive (pixels), got {self.outlier_eps}")
        if not (np.isfinite(self.outlier_threshold) and self.outlier_threshold > 0):
            raise RimclError(
                f"the outlier threshold must be positive, got {self.outlier_threshold}"
            )

    def window_sizes(self):
        """Window side of each pass (pixels): geometric from ``first_window`` to ``window``."""
        first = self.window if self.first_window is None else int(self.first_window)
        if self.passes == 1:
            return [int(self.window)]
        ratios = np.linspace(0.0, 1.0, int(self.passes))
        sizes = first * (self.window / first) ** ratios
        return [int(2 * round(size / 2)) for size in sizes]

    def describe(self):
        return {
            "window": int(self.window),
            "overlap": float(self.overlap),
            "passes": int(self.passes),
            "window_sizes": self.window_sizes(),
            "outlier_test": "normalized median (Westerweel & Scarano 2005), 3x3",
            "outlier_eps_px": float(self.outlier_eps),
            "outlier_threshold": float(self.outlier_threshold),
            "subpixel": "3-point Gaussian (parabola where a neighbour is not positive)",
            "deformation": f"symmetric, B-spline images of order {DEFORM_ORDER}, "
            "cubic-spline displacement",
            "peak_ratio_exclusion_px": SECOND_PEAK_EXCLUSION,
        }


@dataclasses.dataclass(frozen=True)
class WindowGrid:
    """Interrogation windows of one pass: the corners and the shared side.

    Window ``(r, c)`` covers rows ``[rows[r], rows[r] + size)`` and columns
    ``[cols[c], cols[c] + size)``; its centre is at ``(cols[c] + (size - 1)/2,
    rows[r] + (size - 1)/2)`` (pixel centres at integer coordinates).
    """

    rows: np.ndarray
    cols: np.ndarray
    size: int

    @classmethod
    def for_image(cls, shape, size, overlap):
        """Windows of side ``size`` with ``overlap``, centred in an image of ``shape``.

        Parameters
        ----------
        shape : tuple of 2 int
            Image ``(rows, columns)``.
        size : int
        overlap : float

        Returns
        -------
        WindowGrid
        """
        height, width = shape
        if size > min(height, width):
            raise RimclError(
                f"the {size} px interrogation window does not fit the {width} x {height} image"
            )
        spacing = max(1, round(size * (1 - overlap)))

        def corners(extent):
            last = (extent - size) // spacing * spacing
            return np.arange(0, last + 1, spacing) + (extent - size - last) // 2

        return cls(corners(height), corners(width), int(size))

    @property
    def spacing(self):
        """Distance between neighbouring window centres (pixels)."""
        if len(self.cols) > 1:
            return int(self.cols[1] - self.cols[0])
        return int(self.rows[1] - self.rows[0]) if len(self.rows) > 1 else self.size

    @property
    def x(self):
        """Window centres along columns, shape (columns,) (pixels)."""
        return self.cols + 0.5 * (self.size - 1)

    @property
    def y(self):
        """Window centres along rows, shape (rows,) (pixels)."""
        return self.rows + 0.5 * (self.size - 1)

    @property
    def shape(self):
        return (len(self.rows), len(self.cols))

    def extract(self, image):
        """Every window of ``image``, shape ``(rows, columns, size, size)`` (a copy)."""
        view = sliding_window_view(image, (self.size, self.size))
        return view[np.ix_(self.rows, self.cols)]


@dataclasses.dataclass
class PivResult:
    """A displacement field on a grid of window centres (pixels).

    Attributes
    ----------
    x, y : ndarray, float64, shape (rows, columns)
        Window centres along image columns and rows (module docstring).
    dx, dy : ndarray, float64, shape (rows, columns)
        Displacement of image B relative to A; NaN where nothing could replace an outlier.
    peak_ratio : ndarray, float64, shape (rows, columns)
        Highest correlation peak over the second highest, last pass (inf: no second peak).
    valid : ndarray, bool, shape (rows, columns)
        False for outliers of the last pass's normalized median test, windows without
        particle signal and failed peaks.
    replaced : ndarray, bool, shape (rows, columns)
        True where ``dx, dy`` were replaced by the median of valid neighbours.
    settings : PivSettings
    image_shape : tuple of 2 int
        ``(rows, columns)`` of the images.
    window : int
        Window side of the last pass (pixels).
    pass_seconds : list of float
        Wall time of each pass.
    """

    x: np.ndarray
    y: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    peak_ratio: np.ndarray
    valid: np.ndarray
    replaced: np.ndarray
    settings: PivSettings
    image_shape: tuple
    window: int
    pass_seconds: list


def _gaussian_offset(minus, centre, plus):
    """Sub-pixel offset of a peak from three samples (3-point Gaussian, else parabola)."""
    positive = (minus > 0) & (centre > 0) & (plus > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lm, lc, lp = (np.log(np.where(positive, v, 1.0)) for v in (minus, centre, plus))
        gauss = (lm - lp) / (2 * lm - 4 * lc + 2 * lp)
        parabola = (minus - plus) / (2 * minus - 4 * centre + 2 * plus)
    offset = np.where(positive, gauss, parabola)
    return np.where(np.isfinite(offset), np.clip(offset, -0.5, 0.5), 0.0)


def correlate_windows(windows_a, windows_b):
    """Displacement of each window of B relative to A, by FFT cross-correlation.

    Parameters
    ----------
    windows_a, windows_b : ndarray, shape (..., size, size)
        Window images (any real dtype).

    Returns
    -------
    dx, dy : ndarray, float64, shape (...)
        Peak position along columns and rows (pixels, in ``[-size/2, size/2)``).
    peak_ratio : ndarray, float64, shape (...)
    found : ndarray, bool, shape (...)
        False where the correlation has no positive peak (an empty or flat window).
    """
    size = windows_a.shape[-1]
    batch = windows_a.shape[:-2]
    a = windows_a.reshape(-1, size, size).astype(np.float64)
    b = windows_b.reshape(-1, size, size).astype(np.float64)
    a -= a.mean(axis=(1, 2), keepdims=True)
    b -= b.mean(axis=(1, 2), keepdims=True)
    spectrum = np.conj(scipy.fft.rfft2(a)) * scipy.fft.rfft2(b)
    # corr[k] = sum_p a(p) b(p + k): B moved by d peaks at k = d (indices wrap circularly)
    corr = scipy.fft.irfft2(spectrum, s=(size, size))
    count = corr.shape[0]
    flat = corr.reshape(count, -1)
    top = np.argmax(flat, axis=1)
    row, col = np.divmod(top, size)
    ids = np.arange(count)
    peak = corr[ids, row, col]
    sub_row = _gaussian_offset(
        corr[ids, (row - 1) % size, col], peak, corr[ids, (row + 1) % size, col]
    )
    sub_col = _gaussian_offset(
        corr[ids, row, (col - 1) % size], peak, corr[ids, row, (col + 1) % size]
    )
    # signed integer peak position: indices >= size/2 are negative shifts
    dy = np.where(row >= size // 2, row - size, row) + sub_row
    dx = np.where(col >= size // 2, col - size, col) + sub_col
    reach = np.arange(-SECOND_PEAK_EXCLUSION, SECOND_PEAK_EXCLUSION + 1)
    masked = corr.copy()
    near_rows = (row[:, None, None] + reach[None, :, None]) % size
    near_cols = (col[:, None, None] + reach[None, None, :]) % size
    masked[ids[:, None, None], near_rows, near_cols] = -np.inf
    second = masked.reshape(count, -1).max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(second > 0, peak / second, np.inf)
    found = peak > 0
    ratio = np.where(found, ratio, np.nan)
    shape = batch
    return dx.reshape(shape), dy.reshape(shape), ratio.reshape(shape), found.reshape(shape)


def _spline_1d(nodes, values, points, axis):
    """Cubic spline through ``values`` along ``axis``, continued by its end tangents.

    A cubic continued beyond the outermost window centres can swing; the tangent line
    keeps linear fields (shear) exact up to the image edges.
    """
    if len(nodes) == 1:
        return np.repeat(values, len(points), axis=axis)
    spline = CubicSpline(nodes, values, axis=axis)
    slope = spline.derivative()
    inside = np.clip(points, nodes[0], nodes[-1])
    result = spline(inside)
    beyond = points - inside
    shape = [1] * result.ndim
    shape[axis] = len(points)
    edge_slope = np.where(
        (beyond < 0).reshape(shape),
        np.expand_dims(slope(nodes[0]), axis),
        np.expand_dims(slope(nodes[-1]), axis),
    )
    return result + beyond.reshape(shape) * edge_slope


def interpolate_grid(grid, values, x, y):
    """A field on window centres, evaluated on the tensor grid ``y x x`` (pixels).

    Parameters
    ----------
    grid : WindowGrid
    values : ndarray, shape grid.shape
    x, y : ndarray, 1-D
        Column and row coordinates of the points.

    Returns
    -------
    ndarray, shape (len(y), len(x))
    """
    along_x = _spline_1d(grid.x, values, np.asarray(x, dtype=np.float64), axis=1)
    return _spline_1d(grid.y, along_x, np.asarray(y, dtype=np.float64), axis=0)


def smooth_predictor(values):
    """A displacement field filtered by (1, 2, 1)/4 along both grid axes, linear fields kept.

    Deforming by a predictor whose noise varies within a window feeds that noise back
    into the next pass (Schrijer & Scarano 2008); the filter damps it. The edges are
    padded by odd reflection, so a linear field passes unchanged everywhere.
    """
    if min(values.shape) < 2:
        return values
    padded = np.pad(values, 1, mode="reflect", reflect_type="odd")
    along_x = 0.25 * padded[:, :-2] + 0.5 * padded[:, 1:-1] + 0.25 * padded[:, 2:]
    return 0.25 * along_x[:-2] + 0.5 * along_x[1:-1] + 0.25 * along_x[2:]


def _deform(coefficients, shift_x, shift_y):
    """Image sampled at ``p + shift`` for every pixel centre ``p`` (B-spline coefficients).

    Returns
    -------
    image : ndarray, float64
    inside : ndarray, bool
        Where the sampled point lies on the image (its pixels span ``[-0.5, n - 0.5]`` in
        index coordinates).
    """
    rows, cols = np.indices(coefficients.shape, dtype=np.float64)
    rows += shift_y
    cols += shift_x
    height, width = coefficients.shape
    low, high = EDGE_MARGIN - 0.5, EDGE_MARGIN + 0.5
    inside = (rows >= low) & (rows <= height - high) & (cols >= low) & (cols <= width - high)
    image = map_coordinates(
        coefficients, [rows, cols], order=DEFORM_ORDER, mode="grid-constant", prefilter=False
    )
    return image, inside


def remove_background(image, size):
    """``image`` less its background: the local minimum over ``size`` px squares, boxed.

    A constant added to a frame cancels exactly; the box filter spreads the minimum's
    steps, so what is subtracted varies slowly across a window.
    """
    background = uniform_filter(minimum_filter(image, size=size, mode="nearest"), size=size)
    return image - background


def check_piv_memory(shape, settings, what="PIV"):
    """Refuse, before anything is allocated, an analysis that cannot fit in host memory.

    Parameters
    ----------
    shape : tuple of 2 int
        Frame ``(rows, columns)``.
    settings : PivSettings
    what : str
        For the message.

    Raises
    ------
    RimclError
        The size needed and available, and which settings need less.
    """
    from rimcl.core.memory import check_host

    pixels = int(shape[0]) * int(shape[1])
    window_pixels = 0
    for size in settings.window_sizes():
        grid = WindowGrid.for_image(shape, size, settings.overlap)
        window_pixels = max(window_pixels, len(grid.rows) * len(grid.cols) * size * size)
    needed = PIV_BYTES_PER_PIXEL * pixels + PIV_BYTES_PER_WINDOW_PIXEL * window_pixels
    check_host(
        needed,
        f"{what} of {shape[1]} x {shape[0]} px frames with {settings.window} px windows "
        f"at overlap {settings.overlap:g} ({window_pixels / pixels:.3g} window pixels per "
        "frame pixel)",
        "use a smaller --overlap, a larger --window or smaller frames",
    )


def tiff_shape(path):
    """``(rows, columns)`` and dtype of the first image of a TIFF file, from its header.

    Returns
    -------
    shape : tuple of int
    dtype : numpy.dtype
    """
    import tifffile

    path = Path(path)
    if not path.is_file():
        raise RimclError(f"image {path} does not exist")
    try:
        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            return tuple(int(n) for n in series.shape), np.dtype(series.dtype)
    except Exception as exc:  # tifffile raises many types for a bad file
        raise RimclError(f"{path} is not a readable TIFF image ({exc})") from None


def _read_pair(image_a, image_b, settings):
    a = np.asarray(image_a)
    b = np.asarray(image_b)
    if a.ndim != 2 or b.ndim != 2:
        raise RimclError(f"PIV needs two grey images (2-D), got shapes {a.shape} and {b.shape}")
    if a.shape != b.shape:
        raise RimclError(f"the two PIV images differ in shape: {a.shape} and {b.shape}")
    check_piv_memory(a.shape, settings)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise RimclError("a PIV image holds NaN or infinite values")
    return a.astype(np.float64), b.astype(np.float64)


def analyze_pair(image_a, image_b, settings=None):
    """Correlate an image pair into a displacement field (module docstring).

    Parameters
    ----------
    image_a, image_b : array_like, shape (rows, columns)
        Grey images at the first and second exposure (any real dtype).
    settings : PivSettings, optional

    Returns
    -------
    PivResult
    """
    settings = PivSettings() if settings is None else settings
    a, b = _read_pair(image_a, image_b, settings)
    sigma_a, sigma_b = noise_sigma(np.asarray(image_a)), noise_sigma(np.asarray(image_b))
    signal_a, signal_b = a, b
    first = max(settings.window_sizes())
    a, b = remove_background(a, first), remove_background(b, first)
    coefficients = None
    previous = None
    seconds = []
    for size in settings.window_sizes():
        start = time.perf_counter()
        grid = WindowGrid.for_image(a.shape, size, settings.overlap)
        if previous is None:
            deformed_a, deformed_b = a, b
            predictor_x = predictor_y = np.zeros(grid.shape)
        else:
            if coefficients is None:
                coefficients = [
                    spline_filter(image, DEFORM_ORDER, mode="grid-constant") for image in (a, b)
                ]
            old_grid, old_x, old_y = previous
            centres_x = np.arange(a.shape[1], dtype=np.float64)
            centres_y = np.arange(a.shape[0], dtype=np.float64)
            field_x = interpolate_grid(old_grid, old_x, centres_x, centres_y)
            field_y = interpolate_grid(old_grid, old_y, centres_x, centres_y)
            deformed_a, inside_a = _deform(coefficients[0], -0.5 * field_x, -0.5 * field_y)
            deformed_b, inside_b = _deform(coefficients[1], 0.5 * field_x, 0.5 * field_y)
            # where either image was sampled beyond its edge, blank both: the edge then cuts
            # particle images at the same place in A' and B' and biases nothing
            both = inside_a & inside_b
            deformed_a *= both
            deformed_b *= both
            predictor_x = interpolate_grid(old_grid, old_x, grid.x, grid.y)
            predictor_y = interpolate_grid(old_grid, old_y, grid.x, grid.y)
        res_x, res_y, ratio, found = correlate_windows(
            grid.extract(deformed_a), grid.extract(deformed_b)
        )
        signal = window_signal(signal_a, grid, sigma_a) & window_signal(signal_b, grid, sigma_b)
        found &= signal
        ratio = np.where(found, ratio, np.nan)
        dx = np.where(found, predictor_x + res_x, np.nan)
        dy = np.where(found, predictor_y + res_y, np.nan)
        outliers = normalized_median_test(dx, dy, settings.outlier_eps, settings.outlier_threshold)
        dx, dy = replace_outliers(dx, dy, outliers)
        # a vector nothing could replace deforms nothing (predictor 0 there)
        previous = (grid, smooth_predictor(np.nan_to_num(dx)), smooth_predictor(np.nan_to_num(dy)))
        seconds.append(time.perf_counter() - start)
    centre_x, centre_y = np.meshgrid(grid.x.astype(np.float64), grid.y.astype(np.float64))
    return PivResult(
        x=centre_x,
        y=centre_y,
        dx=dx,
        dy=dy,
        peak_ratio=ratio,
        valid=~outliers,
        replaced=outliers & np.isfinite(dx) & np.isfinite(dy),
        settings=settings,
        image_shape=tuple(a.shape),
        window=grid.size,
        pass_seconds=seconds,
    )


def vector_unit(name):
    """Units of a dataset of a PIV vector grid, from its name: positions and displacements
    in pixels, ``*_ms`` in m/s, the rest dimensionless."""
    if name.endswith("_ms"):
        return "m/s"
    if name in ("x", "y", "dx", "dy", "row", "column") or name.startswith(("dx_", "dy_")):
        return "px"
    return "1"


def write_piv(path, result, config=None, overwrite=True):
    """Write a :class:`PivResult` to HDF5 (module docstring), atomically.

    Parameters
    ----------
    path : str or Path
    result : PivResult
    config : dict, optional
        What produced the images and the vectors (input files...), recorded with versions.
    overwrite : bool
    """
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["rimcl_schema"] = SCHEMA
        h5.attrs["schema_version"] = SCHEMA_VERSION
        h5.attrs["coordinates"] = COORDINATES
        h5.attrs["image_shape"] = np.asarray(result.image_shape, dtype=np.int64)
        h5.attrs["settings"] = to_json(result.settings.describe())
        for name in ("x", "y", "dx", "dy", "peak_ratio"):
            h5.create_dataset(name, data=np.asarray(getattr(result, name), dtype=np.float64))
        for name in ("valid", "replaced"):
            h5.create_dataset(name, data=np.asarray(getattr(result, name), dtype=bool))
        # named dimensions (row along the image rows, column along the columns; window
        # centres in pixels) and units, for xarray.open_dataset(path)
        label_grid(h5, np.asarray(result.y)[:, 0], np.asarray(result.x)[0, :], vector_unit)
        stamp_h5(h5, {"piv": result.settings.describe(), **(config or {})})


def read_tiff(path):
    """A grey image from a TIFF file (8- or 16-bit integers, or floats).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    ndarray, shape (rows, columns)
    """
    import tifffile

    path = Path(path)
    if not path.is_file():
        raise RimclError(f"image {path} does not exist")
    try:
        image = tifffile.imread(path)
    except Exception as exc:  # tifffile raises many types for a bad file
        raise RimclError(f"{path} is not a readable TIFF image ({exc})") from None
    if image.ndim != 2:
        raise RimclError(
            f"{path} must hold one grey image (2-D), got an array of shape {image.shape}"
        )
    if image.dtype.kind not in "uif":
        raise RimclError(f"{path} holds {image.dtype} pixels; expected integers or floats")
    return image


def write_tiff(path, counts, config=None, overwrite=True):
    """Write camera counts as a 16-bit grey TIFF, atomically, with config and versions.

    Parameters
    ----------
    path : str or Path
    counts : ndarray, shape (rows, columns)
        Values in ``[0, 65535]``; row 0 is written first.
    config : dict, optional
        Recorded, with the versions, in the TIFF's ImageDescription (JSON).
    overwrite : bool
    """
    import tifffile

    counts = np.asarray(counts)
    if counts.ndim != 2 or counts.min(initial=0) < 0 or counts.max(initial=0) > 65535:
        raise RimclError(f"{path}: a 16-bit frame needs 2-D counts in [0, 65535]")
    note = to_json({"config": config or {}, "versions": versions()})
    with atomic_path(path, overwrite=overwrite) as tmp:
        tifffile.imwrite(tmp, counts.astype(np.uint16), photometric="minisblack", description=note)


def analyze_files(path_a, path_b, output, settings=None, overwrite=False):
    """What ``rimcl piv analyze`` does: read two TIFF frames, correlate, write HDF5.

    Parameters
    ----------
    path_a, path_b : str or Path
        Frames A and B.
    output : str or Path
        The HDF5 file of :func:`write_piv`.
    settings : PivSettings, optional
    overwrite : bool

    Returns
    -------
    PivResult
    """
    from rimcl.core.atomic import check_output
    from rimcl.core.memory import check_host

    check_output(output, overwrite, inputs=[path_a, path_b])
    settings = PivSettings() if settings is None else settings
    headers = [tiff_shape(path) for path in (path_a, path_b)]
    for path, (shape, dtype) in zip((path_a, path_b), headers, strict=True):
        if len(shape) != 2:
            raise RimclError(
                f"{path} must hold one grey image (2-D), got an array of shape {shape}"
            )
        # a compressed file may expand to far more than its size on disk
        check_host(2 * np.prod(shape, dtype=float) * dtype.itemsize, f"reading {path} {shape}")
    if headers[0][0] != headers[1][0]:
        raise RimclError(f"the two PIV images differ in shape: {headers[0][0]} and {headers[1][0]}")
    check_piv_memory(headers[0][0], settings)
    image_a, image_b = read_tiff(path_a), read_tiff(path_b)
    result = analyze_pair(image_a, image_b, settings)
    inputs = {"image_a": str(Path(path_a).resolve()), "image_b": str(Path(path_b).resolve())}
    write_piv(output, result, {"inputs": inputs}, overwrite=overwrite)
    return result

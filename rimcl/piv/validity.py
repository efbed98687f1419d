"""Which PIV vectors stand: the particle-signal test and the normalized median test.

:func:`window_signal` says which interrogation windows hold a particle image at all
(judged on the recorded frames, :mod:`rimcl.piv.analysis`); :func:`normalized_median_test`
flags outliers among the vectors (Westerweel & Scarano 2005) and :func:`replace_outliers`
fills them from their valid neighbours. Grids are ``(rows, columns)`` of window centres.
"""

import contextlib
import warnings

import numpy as np
from scipy.ndimage import convolve, maximum_filter

#: A window holds particle signal when a particle image's peak in it exceeds the window's
#: median by more than this many noise standard deviations, in both frames. The largest of
#: 4096 independent Gaussian noise pixels (a 64 px window) exceeds the mean by 6 sigma with
#: probability 4e-6.
SIGNAL_THRESHOLD = 6.0


def noise_sigma(image):
    """Standard deviation of an image's pixel noise (counts), robust to particle images.

    The median absolute response to the second-difference kernel
    ``[[1, -2, 1], [-2, 4, -2], [1, -2, 1]]`` (which cancels any locally linear
    background and has gain 6 on white noise), over 0.6745 x 6. Particle images inflate
    it at high densities (at 0.03 particles per pixel of d = 3 px it is 1.3 % of an
    in-focus particle's peak), which only makes the signal test stricter. It is never
    below the rounding noise of the samples: 1/sqrt(12) count for integer frames, the
    float precision of the largest value otherwise.

    Parameters
    ----------
    image : ndarray, shape (rows, columns)
        A frame in its own dtype.

    Returns
    -------
    float
    """
    values = np.asarray(image, dtype=np.float64)
    if np.issubdtype(np.asarray(image).dtype, np.integer):
        floor = 1 / np.sqrt(12)
    else:
        floor = np.finfo(np.asarray(image).dtype).eps * float(np.max(np.abs(values), initial=0))
    kernel = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    response = convolve(values, kernel, mode="nearest")[1:-1, 1:-1]
    estimate = float(np.median(np.abs(response))) / (0.6745 * 6) if response.size else 0.0
    return max(estimate, floor)


def window_signal(image, grid, sigma):
    """Which windows of ``grid`` hold particle signal in ``image`` (module docstring).

    Parameters
    ----------
    image : ndarray, shape (rows, columns)
    grid : WindowGrid
    sigma : float
        Noise standard deviation of ``image`` (:func:`noise_sigma`).

    Returns
    -------
    ndarray, bool, shape grid.shape
    """
    peaks = np.where(image == maximum_filter(image, size=3, mode="nearest"), image, -np.inf)
    contrast = grid.extract(peaks).max(axis=(-2, -1)) - np.median(
        grid.extract(image), axis=(-2, -1)
    )
    return (contrast > SIGNAL_THRESHOLD * sigma) & (contrast > 0)


def _neighbours(values):
    """The 8 neighbours of every grid point, shape (8, rows, columns).

    Beyond the edges, neighbours are extrapolated linearly from the next two rows (or
    columns) inside, leaving out the edge vector itself: a linear field then has a
    symmetric neighbourhood everywhere, so its edge vectors are neither flagged nor
    pulled inwards when replaced. With fewer than 3 rows (columns) they are NaN.
    """
    rows, cols = values.shape
    padded = np.full((rows + 2, cols + 2), np.nan)
    padded[1:-1, 1:-1] = values
    if rows >= 3:
        padded[0, 1:-1] = 3 * values[1] - 2 * values[2]
        padded[-1, 1:-1] = 3 * values[-2] - 2 * values[-3]
    if cols >= 3:
        padded[:, 0] = 3 * padded[:, 2] - 2 * padded[:, 3]
        padded[:, -1] = 3 * padded[:, -3] - 2 * padded[:, -4]
    return np.stack(
        [
            padded[1 + i : 1 + i + rows, 1 + j : 1 + j + cols]
            for i in (-1, 0, 1)
            for j in (-1, 0, 1)
            if (i, j) != (0, 0)
        ]
    )


def normalized_median_test(dx, dy, eps=0.1, threshold=2.0):
    """Outliers by the normalized median test (Westerweel & Scarano 2005).

    For each component ``u`` and its 3 x 3 neighbours ``u_i`` (the vector itself left out;
    extrapolated beyond the edges, see :func:`_neighbours`):
    ``r = |u - median(u_i)| / (median(|u_i - median(u_i)|) + eps)``;
    a vector is an outlier if ``sqrt(r_x² + r_y²) > threshold`` or it is not finite.

    Parameters
    ----------
    dx, dy : ndarray, shape (rows, columns)
        Displacements (pixels); NaN for failed vectors.
    eps : float
        Noise floor of the residuals (pixels).
    threshold : float

    Returns
    -------
    ndarray, bool, shape (rows, columns)
        True for outliers.
    """
    residuals = []
    for component in (dx, dy):
        near = _neighbours(component)
        with np.errstate(invalid="ignore"), _quiet_all_nan():
            median = np.nanmedian(near, axis=0)
            spread = np.nanmedian(np.abs(near - median), axis=0)
        residuals.append(np.abs(component - median) / (spread + eps))
    with np.errstate(invalid="ignore"):
        normalized = np.hypot(*residuals)
        # a vector with no finite neighbour cannot be tested: it stands
        return ~(np.isfinite(dx) & np.isfinite(dy)) | (normalized > threshold)


@contextlib.contextmanager
def _quiet_all_nan():
    """Silence NumPy's warning for medians of all-NaN neighbourhoods (they give NaN)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
        yield


def replace_outliers(dx, dy, outliers):
    """Replace outliers by the median of their valid (or already replaced) neighbours.

    Sweeps until every outlier with a finite neighbour is filled; one with none stays NaN.

    Returns
    -------
    dx, dy : ndarray, float64, shape (rows, columns)
    """
    dx = np.where(outliers, np.nan, dx)
    dy = np.where(outliers, np.nan, dy)
    missing = np.isnan(dx) | np.isnan(dy)
    for _ in range(sum(dx.shape)):
        if not missing.any():
            break
        with _quiet_all_nan():
            fill_x = np.nanmedian(_neighbours(dx), axis=0)
            fill_y = np.nanmedian(_neighbours(dy), axis=0)
        fillable = missing & np.isfinite(fill_x) & np.isfinite(fill_y)
        if not fillable.any():
            break
        dx = np.where(fillable, fill_x, dx)
        dy = np.where(fillable, fill_y, dy)
        missing &= ~fillable
    return dx, dy

"""Peaks (modes) of sample PDFs: binned Gaussian kernel density estimates and histograms.

:func:`pdf_peak` (Scott's bandwidth, optionally of ``log10``), :func:`kde_modes` (the mode for
each column of bootstrap weights) and :func:`discrete_mode` (samples that come in steps, such
as the area change of a tracer image in whole pixels).
"""

import math

import numpy as np

#: Grid points of the binned kernel density estimates whose peaks are reported.
PEAK_BINS = 512


def scott_bandwidth(sample):
    """Scott's bandwidth of a Gaussian KDE of a 1-D sample (as ``scipy.stats.gaussian_kde``)."""
    return float(np.std(sample, ddof=1)) * sample.size ** (-0.2)


def kde_modes(sample, bandwidth, weights):
    """Mode of a Gaussian kernel density estimate, for each column of weights.

    The sample is binned linearly onto :data:`PEAK_BINS` points spanning it plus three
    bandwidths on each side, smoothed with the Gaussian (by FFT), and the mode refined by
    a parabola through the highest point and its neighbours: the binning moves it by well
    under 1 % of a bandwidth. The grid follows the sample, so the mode of ``sample + c``
    is the mode of ``sample`` plus ``c``, to rounding.

    Parameters
    ----------
    sample : ndarray, shape (m,)
        Finite values, not all equal.
    bandwidth : float
        Kernel standard deviation (``sample`` units), the same for every column.
    weights : ndarray, shape (m, B)
        Weight of each value in each of ``B`` estimates.

    Returns
    -------
    ndarray, shape (B,)
    """
    from scipy.signal import fftconvolve
    from scipy.sparse import csr_matrix

    low = sample.min() - 3.0 * bandwidth
    spacing = (sample.max() + 3.0 * bandwidth - low) / (PEAK_BINS - 1)
    position = (sample - low) / spacing
    left = np.minimum(np.floor(position).astype(np.int64), PEAK_BINS - 2)
    share = position - left
    rows = np.arange(sample.size)
    binning = csr_matrix(
        (
            np.concatenate([1.0 - share, share]),
            (np.tile(rows, 2), np.concatenate([left, left + 1])),
        ),
        shape=(sample.size, PEAK_BINS),
    )
    counts = np.asarray(binning.T @ weights.astype(np.float64))
    sigma = bandwidth / spacing
    offsets = np.arange(-math.ceil(4.0 * sigma), math.ceil(4.0 * sigma) + 1)
    kernel = np.exp(-0.5 * (offsets / sigma) ** 2)
    density = fftconvolve(counts, kernel[:, None], mode="same", axes=0)
    top = np.clip(np.argmax(density, axis=0), 1, PEAK_BINS - 2)
    copies = np.arange(density.shape[1])
    below, at, above = (density[top + k, copies] for k in (-1, 0, 1))
    curvature = below - 2.0 * at + above
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where(curvature < 0, 0.5 * (below - above) / curvature, 0.0)
    return low + (top + offset) * spacing


def pdf_peak(values, log=False):
    """Position of the peak (mode) of the PDF of a sample, by kernel density estimation.

    Gaussian kernel of Scott's bandwidth, binned (:func:`kde_modes`).

    Parameters
    ----------
    values : array_like, 1-D
    log : bool
        Peak of the PDF of ``log10(values)`` (positive values only): the peak of
        ``c * values`` is then ``c`` times the peak of ``values``.

    Returns
    -------
    float or None
        The mode, in ``values`` units; with ``log``, ``0.0`` for a sample with no positive
        value (the position errors of a uniform medium are all exactly zero); ``None``
        for a sample with no finite value at all.
    """
    sample = np.asarray(values, dtype=np.float64).ravel()
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        return None
    if log:
        sample = np.log10(sample[sample > 0])
        if sample.size == 0:
            return 0.0
    if np.ptp(sample) == 0:
        mode = sample[0]
    else:
        mode = kde_modes(sample, scott_bandwidth(sample), np.ones((sample.size, 1)))[0]
    return float(10.0**mode if log else mode)


def discrete_mode(values, resolution):
    """Mode of a sample of values that come in steps of ``resolution`` (e.g. ΔA / A).

    The histogram's bins are whole multiples of the step, at least as wide as the
    Freedman–Diaconis width, centred on multiples of their width: a kernel estimate
    would put peaks between the only values the sample can take.

    Parameters
    ----------
    values : array_like, 1-D
    resolution : float
        The step of the values (> 0).

    Returns
    -------
    float or None
        Centre of the fullest bin; ``None`` for a sample with no finite value.
    """
    sample = np.asarray(values, dtype=np.float64)
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        return None
    q25, q75 = np.percentile(sample, [25, 75])
    width = resolution * max(
        1.0, np.round(2.0 * (q75 - q25) * sample.size ** (-1 / 3) / resolution)
    )
    bins = np.round(sample / width).astype(np.int64)
    found, counts = np.unique(bins, return_counts=True)
    return float(found[np.argmax(counts)] * width)


#: A second local maximum of a PDF competes with the highest from this share of its height
#: on (the bootstrap of the peak then jumps between the two: C4 of the default study,
#: whose two modes stand at 0.83 of each other's height with a dip of 7 % between).
SECOND_MODE_SHARE = 0.5


def pdf_modes(grid, density):
    """The modes of a PDF that compete with its highest: ``[highest, others...]``.

    A local maximum competes when its height is at least :data:`SECOND_MODE_SHARE` of the
    highest. With more than one, a single "peak" is not defined: its bootstrap jumps
    between them.

    Parameters
    ----------
    grid, density : ndarray, 1-D
        :func:`rimcl.stats.tables.density_estimate` (ascending grid).

    Returns
    -------
    list of float
        Grid positions, the highest first; empty for fewer than 3 points.
    """
    density = np.asarray(density, dtype=np.float64)
    if density.size < 3:
        return []
    inner = np.flatnonzero((density[1:-1] > density[:-2]) & (density[1:-1] >= density[2:])) + 1
    top = int(np.argmax(density))
    others = [
        int(i)
        for i in inner[np.argsort(density[inner])[::-1]]
        if i != top and density[i] >= SECOND_MODE_SHARE * density[top]
    ]
    return [float(grid[i]) for i in (top, *others)]

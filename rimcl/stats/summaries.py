"""Summaries of one error sample: relative errors and position errors with their intervals.

:func:`error_summary` gives the paper's systematic and random errors of ``error / truth`` and
their robust companions (median, IQR, ``rms(error) / rms(truth)``), also over the rows of
strong truth; :func:`position_summary` gives the peak and median of ``|ε_x| / L``. Every
statistic carries its bootstrap 95 % interval (:mod:`rimcl.stats.bootstrap`); a statistic of
an empty sample is ``None``.
"""

import math

import numpy as np

from rimcl.stats.bootstrap import bootstrap_intervals, own_bootstrap, weighted_quantiles
from rimcl.stats.peaks import kde_modes, pdf_modes, pdf_peak, scott_bandwidth
from rimcl.stats.tables import density_estimate

#: The statistics of one error summary (besides ``n``), in the order they are printed.
SUMMARY_KEYS = ("systematic", "random", "median", "iqr", "rms_normalized")

#: Conditioned summaries keep the rows with ``|truth| ≥ CONDITION_FRACTION · rms(truth)``:
#: there ``ε / truth`` has bounded denominators and its mean and spread converge.
CONDITION_FRACTION = 0.5

#: The influence of a ratio statistic: the share of ``Σ (ε / truth)²`` carried by its
#: INFLUENCE_ROWS largest rows. Over INFLUENCE_LIMIT the paper's systematic and random
#: errors are those few rows' (a truth near zero), not the sample's: flagged. A normal
#: sample of 2000 rows gives about 0.02; one row of truth 1e-4 rms gives 1.0.
INFLUENCE_ROWS = 3
INFLUENCE_LIMIT = 0.5


def influence(error, truth):
    """Share of ``Σ (error / truth)²`` carried by the :data:`INFLUENCE_ROWS` largest rows.

    Parameters
    ----------
    error, truth : ndarray, 1-D
        Finite, ``truth != 0``.

    Returns
    -------
    float or None
        In ``(0, 1]``; None for an empty sample or one of zero ratios.
    """
    squares = np.sort((np.asarray(error) / np.asarray(truth)) ** 2)
    total = float(np.sum(squares))
    if squares.size == 0 or not total > 0:
        return None
    return float(np.sum(squares[-INFLUENCE_ROWS:]) / total)


def finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


def _ratio_statistics(error, truth, weights):
    """The :data:`SUMMARY_KEYS` statistics of ``error / truth`` for each column of weights.

    The rows must be sorted by ``error / truth``. Mean and spread are taken about the
    plain sample mean, so the spread of a sample of identical ratios is exactly 0.
    """
    ratio = error / truth
    centre = np.mean(ratio)
    shifted = ratio - centre
    rows = np.stack([np.ones_like(ratio), shifted, shifted**2, error**2, truth**2])
    # einsum: no threaded BLAS, whose start-up costs more than this product on busy cores
    total, first, second, error_squares, truth_squares = np.einsum(
        "ij,jk->ik", rows.astype(weights.dtype), weights
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        first, second = first / total, second / total
        variance = (second - first**2) * total / (total - 1.0)
        rms = np.sqrt(error_squares / truth_squares)
    q25, q50, q75 = weighted_quantiles(ratio, weights, (0.25, 0.5, 0.75))
    return {
        "systematic": centre + first,
        "random": np.where(total > 1, np.sqrt(np.maximum(variance, 0.0)), np.nan),
        "median": q50,
        "iqr": q75 - q25,
        "rms_normalized": rms,
    }


def error_summary(error, truth, ids=None, bootstrap=None, condition=True):
    """Summary ``S`` of the relative error ``error / truth`` (fractions, not percent).

    Parameters
    ----------
    error, truth : array_like, 1-D, same shape
        Absolute error and true value; rows whose truth is zero or whose error is not
        finite are left out of the ratios (``n`` says how many remain).
    ids : array_like of int, optional
        Tracer of each row: the rows of a tracer are resampled together. Default: every
        row is its own tracer.
    bootstrap : TracerBootstrap, optional
        The resamples (over a superset of ``ids``); default: new ones over ``ids``.
    condition : bool
        Also summarise the rows with ``|truth| ≥ CONDITION_FRACTION · rms(truth)``.

    Returns
    -------
    dict
        ``systematic`` (mean of ``error/truth``, the paper's), ``random`` (its standard
        deviation, ``ddof=1``, the paper's), ``median``, ``iqr`` (75th minus 25th
        percentile), ``rms_normalized`` (``rms(error) / rms(truth)``, robust where
        ``truth ≈ 0``), ``n``, ``influence`` (the share of ``Σ (error/truth)²`` carried
        by the :data:`INFLUENCE_ROWS` largest rows, :func:`influence`), ``ci95`` (the
        bootstrap 95 % interval ``[lo, hi]`` of each statistic) and, with ``condition``,
        ``conditioned``: the same over the rows with ``|truth| ≥ truth_floor`` plus
        ``truth_floor`` and ``truth_floor_over_rms``.
        ``None`` where the sample is too small.
    """
    error = np.asarray(error, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    ids = np.arange(error.size) if ids is None else np.asarray(ids, dtype=np.int64)
    usable = np.isfinite(error) & np.isfinite(truth) & (truth != 0)
    # sorted by ratio, as the quantiles of the resamples need
    order = np.argsort(error[usable] / truth[usable], kind="stable")
    error, truth, ids = error[usable][order], truth[usable][order], ids[usable][order]
    summary = {key: None for key in SUMMARY_KEYS}
    summary["n"] = int(error.size)
    summary["influence"] = influence(error, truth)
    summary["ci95"] = dict.fromkeys(SUMMARY_KEYS)
    if error.size:
        bootstrap = own_bootstrap(ids, bootstrap)
        values = _ratio_statistics(error, truth, np.ones((error.size, 1)))
        summary.update({key: finite_or_none(values[key][0]) for key in SUMMARY_KEYS})
        summary["ci95"] = bootstrap_intervals(
            lambda weights: _ratio_statistics(error, truth, weights),
            bootstrap,
            ids,
            SUMMARY_KEYS,
        )
        if summary["random"] is None:
            summary["ci95"]["random"] = None
    if condition:
        floor = CONDITION_FRACTION * math.sqrt(np.mean(truth**2)) if truth.size else None
        strong = np.abs(truth) >= floor if floor is not None else np.zeros(0, dtype=bool)
        summary["conditioned"] = {
            "truth_floor": floor,
            "truth_floor_over_rms": CONDITION_FRACTION,
            **error_summary(error[strong], truth[strong], ids[strong], bootstrap, False),
        }
    return summary


def position_summary(vectors, ids, length, pixel_size, bootstrap=None):
    """Peak and median of ``|ε_x| / L``, with their bootstrap 95 % intervals.

    Parameters
    ----------
    vectors : tuple of two ndarray, shape (rows,)
        Position errors ``(ε_2, ε_3)`` (field length units), one row per tracer and frame.
    ids : ndarray of int, shape (rows,)
        Tracer of each row.
    length, pixel_size : float
        ``L`` and the pixel size (field length units).
    bootstrap : TracerBootstrap, optional

    Returns
    -------
    dict
        ``position_error_peak_over_L`` (mode of a Gaussian KDE of ``log10(|ε_x| / L)``;
        0 when every error is exactly 0; ``None`` for no finite error),
        ``position_error_peak_px``, ``position_error_median_over_L``, and for each of
        them ``<key>_ci95`` (``[lo, hi]`` or ``None``). The peak's bootstrap keeps the
        full sample's bandwidth. ``position_error_modes_over_L``: the PDF's competing
        modes (:func:`rimcl.stats.peaks.pdf_modes`), ``position_error_peak_ambiguous``:
        more than one (the peak is then not one number).
    """
    values = np.hypot(*vectors) / length
    finite = np.isfinite(values)
    order = np.argsort(values[finite], kind="stable")  # the median's resamples need it
    values, ids = values[finite][order], np.asarray(ids, dtype=np.int64)[finite][order]
    peak = pdf_peak(values, log=True)
    modes = pdf_modes(*density_estimate(values, log=True))
    median = finite_or_none(np.median(values)) if values.size else None
    peak_ci = median_ci = None
    if values.size:
        bootstrap = own_bootstrap(ids, bootstrap)
        median_ci = bootstrap_intervals(
            lambda weights: {"median": weighted_quantiles(values, weights, (0.5,))[0]},
            bootstrap,
            ids,
            ("median",),
        )["median"]
        positive = values > 0
        logs = np.log10(values[positive])
        if logs.size > 1 and np.ptp(logs) > 0:
            bandwidth = scott_bandwidth(logs)
            log_ci = bootstrap_intervals(
                lambda weights: {"peak": kde_modes(logs, bandwidth, weights)},
                bootstrap,
                ids[positive],
                ("peak",),
            )["peak"]
            peak_ci = None if log_ci is None else [10.0 ** log_ci[0], 10.0 ** log_ci[1]]
        elif peak is not None:
            peak_ci = [peak, peak]
    to_px = length / pixel_size
    return {
        "position_error_peak_over_L": peak,
        "position_error_peak_over_L_ci95": peak_ci,
        "position_error_peak_px": None if peak is None else peak * to_px,
        "position_error_peak_px_ci95": None if peak_ci is None else [v * to_px for v in peak_ci],
        "position_error_median_over_L": median,
        "position_error_median_over_L_ci95": median_ci,
        # a PDF with two modes of comparable height has no one peak: its value and
        # interval jump between them (the figure and summary say so; the median holds)
        "position_error_modes_over_L": modes,
        "position_error_peak_ambiguous": len(modes) > 1,
    }

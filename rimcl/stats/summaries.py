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

#: The tail share of an rms: the share of ``Σ ε²`` carried by the TOP_FRACTION of tracers
#: with the largest ``Σ ε²`` (at least one tracer). Over TOP_SHARE_LIMIT the rms ratio is
#: those few tracers', and whether a sample holds one of them is chance: its bootstrap
#: interval then under-covers, so the rms is not a headline. Normal errors of 250 tracers
#: (4 rows each) give 0.04–0.06; C4 of the default study 0.5–0.8.
TOP_FRACTION = 0.01
TOP_SHARE_LIMIT = 0.2

#: The tail index of the errors: Hill's estimate over the TAIL_FRACTION of tracers with the
#: largest root-sum-square error (at least TAIL_MIN_ROWS of them, from TAIL_MIN_TRACERS
#: tracers on; fewer cannot tell a tail). Errors with a power-law tail ``P(|ε| > x) ∝ x^-α``
#: have no variance where ``α < 2`` (the rms grows with the sample) and an rms whose own
#: spread is infinite where ``α < 4``; the bootstrap interval of a sample that happens to
#: hold no extreme tracer then lies below the rms of a larger one. Below TAIL_INDEX_LIMIT
#: the rms is not a headline. Over 200 seeds of 250 tracers, 4 rows each: normal errors
#: give 6.7–10 (10th–90th percentile), the product of two normals (exponential tails)
#: 3.3–5.6, Student-t errors of 3 and 2 degrees of freedom 2.5–4.1 and 1.7–2.7; C4 of the
#: default study 1.2–2.2 (0.8–1.2 with 1600 tracers). With the top share, t 2.2 samples
#: are covered or marked 94 % of the time (covered 26 %); the rules cannot split t3 from
#: the product of normals at this size: they mark 53 % of the t3 samples (covered 85 %,
#: covered or marked 86 %) and 2 % of the products (covered 93 %).
TAIL_FRACTION = 0.1
TAIL_MIN_ROWS = 10
TAIL_MIN_TRACERS = 100
TAIL_INDEX_LIMIT = 3.0


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


def top_share(error, ids):
    """Share of ``Σ error²`` carried by the :data:`TOP_FRACTION` of tracers of largest
    ``Σ error²`` (rows of a tracer summed; at least one tracer).

    Parameters
    ----------
    error : ndarray, 1-D
        Finite errors, one per row.
    ids : ndarray of int, same shape
        Tracer of each row.

    Returns
    -------
    share : float or None
        In ``(0, 1]``; None under :data:`TAIL_MIN_TRACERS` tracers or for zero errors.
    tracers : int
        How many tracers the share is of (0 for an empty sample).
    """
    _, tracer = np.unique(np.asarray(ids), return_inverse=True)
    sums = np.sort(np.bincount(tracer.ravel(), weights=np.asarray(error) ** 2))
    count = max(1, math.ceil(TOP_FRACTION * sums.size)) if sums.size else 0
    total = float(np.sum(sums))
    # under TAIL_MIN_TRACERS one tracer is more than 1 %, and the largest of a few normal
    # errors carries a fifth of them by chance: no tail to tell
    if sums.size < TAIL_MIN_TRACERS or not total > 0:
        return None, count
    return float(np.sum(sums[-count:]) / total), count


def tail_index(error, ids):
    """Hill's estimate of the tail index ``α`` of the tracers' root-sum-square errors.

    Parameters
    ----------
    error : ndarray, 1-D
        Finite errors, one per row.
    ids : ndarray of int, same shape
        Tracer of each row.

    Returns
    -------
    float or None
        ``α̂ = 1 / mean(log(r_i / r_(k+1)))`` over the ``k`` largest root-sum-square errors
        ``r_i`` (``k``: :data:`TAIL_FRACTION` of the tracers, at least
        :data:`TAIL_MIN_ROWS`); None under :data:`TAIL_MIN_TRACERS` tracers or where the
        errors past the threshold are all equal (no tail to measure).
    """
    _, tracer = np.unique(np.asarray(ids), return_inverse=True)
    sums = np.sort(np.sqrt(np.bincount(tracer.ravel(), weights=np.asarray(error) ** 2)))
    if sums.size < TAIL_MIN_TRACERS:
        return None
    count = max(TAIL_MIN_ROWS, math.ceil(TAIL_FRACTION * sums.size))
    threshold = sums[-count - 1]
    if not threshold > 0:
        return None
    spread = float(np.mean(np.log(sums[-count:] / threshold)))
    return 1.0 / spread if spread > 0 else None


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
        by the :data:`INFLUENCE_ROWS` largest rows, :func:`influence`), ``top_share`` and
        ``top_tracers`` (the share of ``Σ error²`` the :data:`TOP_FRACTION` of tracers of
        largest errors carry, and how many they are: :func:`top_share`), ``tail_index``
        (Hill's estimate of the errors' tail index, :func:`tail_index`), ``ci95`` (the
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
    summary["top_share"], summary["top_tracers"] = top_share(error, ids)
    summary["tail_index"] = tail_index(error, ids)
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

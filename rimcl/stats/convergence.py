"""Convergence of the headline statistics with the number of tracers.

The refraction errors of a case are recomputed on nested random subsamples of its tracers
(``N/16 ... N``); :func:`not_converged` names the statistics that keep growing.
"""

import numpy as np

from rimcl.stats.bootstrap import TracerBootstrap
from rimcl.stats.error_blocks import refraction_errors
from rimcl.stats.summaries import SUMMARY_KEYS
from rimcl.stats.tables import rows_of

#: Nested subsamples of the convergence check: N / d tracers for each divisor d.
CONVERGENCE_DIVISORS = (16, 8, 4, 2, 1)
#: Seed of the order in which tracers enter the nested subsamples.
CONVERGENCE_SEED = 7

#: Position statistics followed for convergence, besides the kinematic ones.
POSITION_HEADLINES = ("position_error_peak_over_L", "position_error_median_over_L")


def _headlines(errors, blocks):
    """``{path: (value, ci95)}`` of the statistics followed for convergence."""
    pairs = {(key,): (errors[key], errors[f"{key}_ci95"]) for key in POSITION_HEADLINES}
    for group, (symbol, _) in blocks.items():
        for component in (f"{symbol}2", f"{symbol}3", "magnitude"):
            summary = errors[group][component]
            for prefix, part in (("", summary), ("conditioned_", summary["conditioned"])):
                for key in SUMMARY_KEYS:
                    pairs[(group, component, prefix + key)] = (part[key], part["ci95"][key])
    return pairs


def not_converged(values, intervals):
    """Whether a statistic keeps growing with the number of tracers.

    Criterion: its magnitude grows over the last three nested subsamples
    (``|v(N/4)| < |v(N/2)| < |v(N)|``) and the full-sample value lies outside the 95 %
    interval of the ``N/4`` subsample. A statistic that converges fails the first test
    about as often as not and the second only rarely.

    Parameters
    ----------
    values : list of float or None
        The statistic at ``N/16, N/8, N/4, N/2, N`` tracers (the last three are used).
    intervals : list of [lo, hi] or None
        Their bootstrap 95 % intervals.
    """
    if len(values) < 3 or any(v is None for v in values[-3:]) or intervals[-3] is None:
        return False
    quarter, half, full = (abs(v) for v in values[-3:])
    low, high = intervals[-3]
    return quarter < half < full and not low <= values[-1] <= high


def convergence(tables, kept, blocks, full):
    """The headline statistics of the refraction errors against nested tracer subsamples.

    Parameters
    ----------
    tables : RenderTables
    kept : ndarray of int
        Ids of the tracers used (``N``).
    blocks : dict
        ``{group: (symbol, kept rows)}`` (:func:`kinematic_blocks`).
    full : dict
        The refraction errors of all ``N`` tracers (:func:`refraction_errors`).

    Returns
    -------
    dict
        ``n_tracers`` (the subsample sizes, ``N/16 … N``, each holding the previous
        ones), ``seed``; per kinematic group and component ``{statistic: {"value": [...],
        "ci95": [...]}}`` for the :data:`SUMMARY_KEYS` and their ``conditioned_`` versions;
        the :data:`POSITION_HEADLINES` likewise; ``not_converged``: the dotted names
        (``velocity.u3.random``) of the statistics :func:`not_converged` marks.
    """
    order = np.random.default_rng(CONVERGENCE_SEED).permutation(kept)
    sizes = sorted({kept.size // d for d in CONVERGENCE_DIVISORS if kept.size // d >= 2})
    levels = []
    for size in sizes:
        if size == kept.size:
            levels.append(_headlines(full, blocks))
            continue
        subset = np.sort(order[:size])
        subset_blocks = {g: (symbol, rows_of(t, subset)) for g, (symbol, t) in blocks.items()}
        errors = refraction_errors(
            tables, rows_of(tables.tracers, subset), subset_blocks, TracerBootstrap(subset)
        )
        levels.append(_headlines(errors, blocks))
    result = {"n_tracers": sizes, "seed": CONVERGENCE_SEED, "not_converged": []}
    for path in levels[0] if levels else ():
        values = [level[path][0] for level in levels]
        intervals = [level[path][1] for level in levels]
        node = result
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = {"value": values, "ci95": intervals}
        if not_converged(values, intervals):
            result["not_converged"].append(".".join(path))
    return result

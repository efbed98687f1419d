"""Convergence of the headline statistics with the number of tracers.

The refraction errors of a case are recomputed on nested random subsamples of its tracers
(``N/16 ... N``); :func:`not_converged` names the statistics whose full-sample value jumps
away from the smaller samples', :func:`carried_by_few` the ratio statistics that a few
rows carry, and :func:`rms_reasons` the rms ratios that a few tracers or a heavy tail carry
(their intervals cannot cover the value of a larger sample).
"""

import numpy as np

from rimcl.stats.bootstrap import TracerBootstrap
from rimcl.stats.error_blocks import refraction_errors
from rimcl.stats.summaries import (
    INFLUENCE_LIMIT,
    INFLUENCE_ROWS,
    SUMMARY_KEYS,
    TAIL_INDEX_LIMIT,
    TOP_FRACTION,
    TOP_SHARE_LIMIT,
)
from rimcl.stats.tables import rows_of

#: Nested subsamples of the convergence check: N / d tracers for each divisor d.
CONVERGENCE_DIVISORS = (16, 8, 4, 2, 1)
#: Seed of the order in which tracers enter the nested subsamples.
CONVERGENCE_SEED = 7

#: Position statistics followed for convergence, besides the kinematic ones.
POSITION_HEADLINES = ("position_error_peak_over_L", "position_error_median_over_L")
#: The paper's ratio statistics: a mean and a spread of ``ε / truth``, which one row of a
#: truth near zero can carry.
RATIO_KEYS = ("systematic", "random")


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
    """Whether a statistic's full-sample value jumps away from its smaller samples.

    Criterion: the value at ``N`` lies outside the bootstrap 95 % interval of the ``N/4``
    or of the ``N/2`` subsample, in either direction (a jump up, as one row of a truth
    near zero entering the sample, or down). For a statistic that converges the nested
    differences are ``√3 σ`` and ``σ`` (``σ`` its spread at ``N``) against interval
    half-widths of ``3.9 σ`` and ``2.8 σ``: a false mark about 3 % of the time.

    Parameters
    ----------
    values : list of float or None
        The statistic at ``N/16, N/8, N/4, N/2, N`` tracers (the last three are used).
    intervals : list of [lo, hi] or None
        Their bootstrap 95 % intervals.
    """
    if len(values) < 3 or values[-1] is None:
        return False
    for interval in intervals[-3:-1]:
        if interval is not None and not interval[0] <= values[-1] <= interval[1]:
            return True
    return False


def carried_by_few(summary):
    """Whether a few rows carry a ratio statistic: the :data:`INFLUENCE_ROWS` largest rows
    hold more than :data:`INFLUENCE_LIMIT` of ``Σ (ε / truth)²`` (:func:`influence`)."""
    share = summary.get("influence")
    return share is not None and share > INFLUENCE_LIMIT


def rms_reasons(summary):
    """Why an rms ratio cannot be a headline, from its summary's tail (empty: it can).

    ``"few tracers"``: the :data:`TOP_FRACTION` of tracers of largest errors carry more
    than :data:`TOP_SHARE_LIMIT` of ``Σ ε²``; ``"heavy tail"``: the errors' tail index
    is below :data:`TAIL_INDEX_LIMIT` (the rms's own spread is infinite, so its bootstrap
    interval under-covers even where the sample happens to hold no extreme tracer).
    """
    share, index = summary.get("top_share"), summary.get("tail_index")
    return [
        reason
        for reason, marked in (
            ("few tracers", share is not None and share > TOP_SHARE_LIMIT),
            ("heavy tail", index is not None and index < TAIL_INDEX_LIMIT),
        )
        if marked
    ]


def _tails(errors, blocks):
    """``{path: reasons}`` of the rms ratios of the full sample (:func:`rms_reasons`)."""
    reasons = {}
    for group, (symbol, _) in blocks.items():
        for component in (f"{symbol}2", f"{symbol}3", "magnitude"):
            summary = errors[group][component]
            for prefix, part in (("", summary), ("conditioned_", summary["conditioned"])):
                found = rms_reasons(part)
                if found:
                    reasons[(group, component, prefix + "rms_normalized")] = found
    return reasons


def _influences(errors, blocks):
    """``{path: influence}`` of the ratio statistics of the full sample."""
    shares = {}
    for group, (symbol, _) in blocks.items():
        for component in (f"{symbol}2", f"{symbol}3", "magnitude"):
            summary = errors[group][component]
            for prefix, part in (("", summary), ("conditioned_", summary["conditioned"])):
                for key in RATIO_KEYS:
                    shares[(group, component, prefix + key)] = part
    return shares


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
        (``velocity.u3.random``) of the statistics :func:`not_converged` or
        :func:`carried_by_few` marks; ``reasons``: for each of them, why (``"jump"``: the
        value at N outside the N/4 or N/2 interval; ``"few rows"``: the largest
        ``influence_rows`` rows carry more than ``influence_limit`` of ``Σ (ε/truth)²``;
        for the rms ratios ``"few tracers"`` and ``"heavy tail"``, :func:`rms_reasons`).
        ``top_fraction``, ``top_share_limit``, ``tail_index_limit``: the limits of these.
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
    result = {
        "n_tracers": sizes,
        "seed": CONVERGENCE_SEED,
        "influence_rows": INFLUENCE_ROWS,
        "influence_limit": INFLUENCE_LIMIT,
        "top_fraction": TOP_FRACTION,
        "top_share_limit": TOP_SHARE_LIMIT,
        "tail_index_limit": TAIL_INDEX_LIMIT,
        "not_converged": [],
        "reasons": {},
    }
    few = {path for path, part in _influences(full, blocks).items() if carried_by_few(part)}
    tails = _tails(full, blocks)
    for path in levels[0] if levels else ():
        values = [level[path][0] for level in levels]
        intervals = [level[path][1] for level in levels]
        node = result
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = {"value": values, "ci95": intervals}
        reasons = [
            reason
            for reason, marked in (
                ("jump", not_converged(values, intervals)),
                ("few rows", path in few),
            )
            if marked
        ] + tails.get(path, [])
        if reasons:
            result["not_converged"].append(".".join(path))
            result["reasons"][".".join(path)] = reasons
    return result

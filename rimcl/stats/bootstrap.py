"""Tracer bootstrap: resamples of the tracers of a case and the 95 % intervals they give.

:class:`TracerBootstrap` draws tracers with replacement (all rows of a tracer together) and
gives each table row its resample weights; :func:`weighted_quantiles` takes quantiles of the
weighted copies at once; :func:`bootstrap_intervals` turns a statistic of the weights into
percentile 95 % intervals.
"""

import numpy as np

#: Bootstrap resamples per interval. Measured on 400 tracers: the ends of the rms interval
#: move by 1 % of its width between seeds (2 % for the median), so 2 digits are stable.
BOOTSTRAP_RESAMPLES = 2000
#: Seed of the tracer resampling; the same resamples serve every statistic of a case.
BOOTSTRAP_SEED = 20240611
#: Elements of one block of resample weights (resamples x rows): bounds memory to ~32 MB.
BOOTSTRAP_BLOCK = 4_000_000


class TracerBootstrap:
    """Resamples of a set of tracers, drawn with replacement, the same for every statistic.

    Resample ``b`` draws ``n`` tracers out of the ``n`` given; a statistic of the resample
    weighs each row by how often its tracer was drawn, so all rows (frames) of one tracer
    go together and a statistic of many tables is resampled consistently. The draws are
    seeded per block of resamples, so they do not depend on the tables resampled.

    Parameters
    ----------
    tracer_ids : array_like of int
        The tracers to resample (duplicates are ignored).
    resamples : int
        Number of resamples ``B``.
    seed : int
    """

    def __init__(self, tracer_ids, resamples=BOOTSTRAP_RESAMPLES, seed=BOOTSTRAP_SEED):
        self.tracer_ids = np.unique(np.asarray(tracer_ids, dtype=np.int64))
        self.resamples = int(resamples)
        self.seed = seed
        count = max(self.tracer_ids.size, 1)
        self._block = max(1, min(self.resamples, BOOTSTRAP_BLOCK // count))
        # small sets (the usual study) keep their counts: drawn once, used by every statistic
        self._counts = (
            list(self._draw_counts()) if self.resamples * count <= BOOTSTRAP_BLOCK else None
        )

    def _draw_counts(self):
        """Blocks of ``(n, resamples)`` draw counts, reproducibly seeded per block.

        Rows are tracers and columns resamples: gathering the rows of a table, the
        products and the running sums over rows all then work on contiguous memory.
        float32 holds whole counts exactly and halves the memory traffic.
        """
        n = self.tracer_ids.size
        for index, start in enumerate(range(0, self.resamples, self._block)):
            columns = min(self._block, self.resamples - start)
            rng = np.random.default_rng([self.seed, index])
            draws = rng.integers(0, n, size=(columns, n)) * columns + np.arange(columns)[:, None]
            counts = np.bincount(draws.ravel(), minlength=n * columns)
            yield counts.reshape(n, columns).astype(np.float32)

    def weight_blocks(self, row_ids):
        """Resample weights of table rows, in blocks of resamples.

        Parameters
        ----------
        row_ids : ndarray of int, shape (rows,)
            Tracer id of each row; every id must be one of ``tracer_ids``.

        Yields
        ------
        ndarray of float32, shape (rows, block)
            How often each row's tracer was drawn in each resample of the block.
        """
        index = np.searchsorted(self.tracer_ids, np.asarray(row_ids, dtype=np.int64))
        if self.tracer_ids.size == 0 or index.size == 0:
            return
        step = max(1, BOOTSTRAP_BLOCK // index.size)
        for counts in self._counts if self._counts is not None else self._draw_counts():
            for start in range(0, counts.shape[1], step):
                yield counts[index, start : start + step]


def _running_sums(rows):
    """Cumulative sums over the rows of a ``(rows, copies)`` array (a new array).

    A Python loop of whole-row additions beats ``np.cumsum`` (one element at a time)
    several times over while the rows are few and the copies many, as here. Whole
    counts stay exact in float32 up to 2**24.
    """
    cumulative = np.array(rows)
    for row in range(1, cumulative.shape[0]):
        cumulative[row] += cumulative[row - 1]
    return cumulative


def weighted_quantiles(ordered, weights, probabilities):
    """Quantiles of weighted copies of a sample, as ``np.percentile`` (linear) of each copy.

    The value of rank ``r`` of a copy is the first row whose running weight exceeds ``r``,
    found by one bisection run on all copies and ranks at once.

    Parameters
    ----------
    ordered : ndarray, shape (m,)
        The sample, finite and sorted ascending.
    weights : ndarray, shape (m, B)
        Whole-number repetition counts of each value in each of ``B`` copies.
    probabilities : sequence of float
        In ``[0, 1)``.

    Returns
    -------
    list of ndarray, shape (B,)
        One array per probability; NaN for a copy with no values.
    """
    width, copies = weights.shape
    running = _running_sums(weights)
    total = running[-1].astype(np.float64)
    # every rank of every probability in one bisection: (2 * len(probabilities), B)
    positions = np.outer(probabilities, total - 1.0)
    below = np.floor(positions)
    ranks = np.concatenate([below, below + 1.0])
    columns = np.broadcast_to(np.arange(copies), ranks.shape)
    low, high = np.zeros(ranks.shape, dtype=np.int64), np.full(ranks.shape, width, dtype=np.int64)
    for _ in range(width.bit_length()):
        middle = (low + high) // 2
        right = running[np.minimum(middle, width - 1), columns] <= ranks
        low, high = np.where(right, middle + 1, low), np.where(right, high, middle)
    values = ordered[np.minimum(low, width - 1)]
    first, second = values[: len(probabilities)], values[len(probabilities) :]
    quantiles = first + (positions - below) * (second - first)
    return list(np.where(total > 0, quantiles, np.nan))


def _interval(resampled):
    """Percentile 95 % interval of bootstrap values, ``None`` when most are undefined."""
    finite = resampled[np.isfinite(resampled)]
    if finite.size == 0 or finite.size < 0.5 * resampled.size:
        return None
    low, high = np.percentile(finite, [2.5, 97.5])
    return [float(low), float(high)]


def bootstrap_intervals(statistic, bootstrap, row_ids, keys):
    """Intervals of the statistics ``statistic(weights)`` returns, keyed as ``keys``."""
    blocks = [statistic(weights) for weights in bootstrap.weight_blocks(row_ids)]
    if not blocks:
        return dict.fromkeys(keys)
    return {key: _interval(np.concatenate([block[key] for block in blocks])) for key in keys}


def own_bootstrap(ids, bootstrap):
    return bootstrap if bootstrap is not None else TracerBootstrap(ids)

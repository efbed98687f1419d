"""Cubic B-spline coefficients of ``δn`` for the ``bspline3`` interpolation.

The kernel (``cl/rimcl_bspline.h``) evaluates ``δn`` and its analytic gradient from one
float32 coefficient per node, so ``n`` and ``∇n`` are consistent (one C² spline) and the
field takes a quarter of the memory of the ``trilinear`` nodes (``δn`` and ``∇n``).

Coefficients are found on the host by the exact prefilter of
:func:`scipy.ndimage.spline_filter1d`, one axis after the other:

- ``periodic`` fields: mode ``grid-wrap`` (the grid holds one period), coefficient array
  ``(n3, n2, n1)``.
- ``clamp`` fields: rays start and end on the grid's faces, so the spline must be
  accurate up to the edge. A mirror boundary would force ``∂n/∂x = 0`` there (an O(1)
  gradient error in the edge cells), and scipy's ``nearest`` mode flattens the field the
  same way. Each axis is therefore extended by :data:`EDGE_PAD` nodes continuing the
  cubic through its last 4 nodes, filtered with mode ``mirror`` (whose effect has decayed
  by ``0.268**12 ≈ 1e-7`` at the real edge), and cut to the coefficients of nodes
  ``-1 … n+1`` that the kernel reads: array ``(n3+3, n2+3, n1+3)``, node ``i`` at index
  ``i+1``. On a sine sampled with 64 nodes this gives ``∇n`` errors of 3e-5 at the edge
  against 3e-0 with a plain mirror boundary.
"""

import numpy as np
from scipy.ndimage import spline_filter1d

#: Nodes added beyond each clamped edge before prefiltering.
EDGE_PAD = 12

#: Coefficients stored beyond the first and last node of a clamped axis (the kernel
#: reads taps ``i-1 … i+2`` around cell ``i``).
STORED_BEFORE, STORED_AFTER = 1, 2


def _extend_cubic(values, axis, pad):
    """``values`` with ``pad`` nodes added at both ends of ``axis``, continuing the
    polynomial (degree ≤ 3) through the 4 nodes nearest each end."""
    values = np.moveaxis(values, axis, 0)
    count = values.shape[0]
    degree = min(3, count - 1)
    fit_nodes = np.arange(degree + 1, dtype=np.float64)
    beyond = -np.arange(1, pad + 1, dtype=np.float64)
    # Lagrange weights mapping the edge nodes 0..degree to the positions -1, -2, ...
    weights = np.ones((pad, degree + 1))
    for j in range(degree + 1):
        for m in range(degree + 1):
            if m != j:
                weights[:, j] *= (beyond - fit_nodes[m]) / (fit_nodes[j] - fit_nodes[m])
    edge_lo = values[: degree + 1].astype(np.float64)
    edge_hi = values[::-1][: degree + 1].astype(np.float64)
    below = np.tensordot(weights, edge_lo, axes=(1, 0))[::-1]
    above = np.tensordot(weights, edge_hi, axes=(1, 0))
    extended = np.concatenate([below, values, above], axis=0)
    return np.moveaxis(extended, 0, axis)


def bspline_coefficients(delta_n, periodic):
    """Prefiltered cubic B-spline coefficients of ``δn`` (see the module text).

    Parameters
    ----------
    delta_n : ndarray, shape (n3, n2, n1)
        ``n - n_ref`` on the nodes.
    periodic : bool
        True for a periodic grid (one period, endpoint excluded), False for ``clamp``.

    Returns
    -------
    ndarray, float32
        Shape ``(n3, n2, n1)`` if periodic, else ``(n3+3, n2+3, n1+3)`` with node ``i``
        at index ``i+1`` along every axis; C-contiguous.
    """
    coefficients = np.asarray(delta_n, dtype=np.float32)
    for axis in range(3):
        if periodic:
            coefficients = spline_filter1d(
                coefficients, 3, axis=axis, mode="grid-wrap", output=np.float32
            )
            continue
        count = coefficients.shape[axis]
        extended = _extend_cubic(coefficients, axis, EDGE_PAD).astype(np.float32)
        filtered = spline_filter1d(extended, 3, axis=axis, mode="mirror", output=np.float32)
        keep = slice(EDGE_PAD - STORED_BEFORE, EDGE_PAD + count + STORED_AFTER)
        coefficients = np.take(filtered, np.arange(keep.start, keep.stop), axis=axis)
    return np.ascontiguousarray(coefficients, dtype=np.float32)


def bspline_weights(fraction):
    """Cubic B-spline weights of the taps ``i-1, i, i+1, i+2`` and their derivatives.

    Parameters
    ----------
    fraction : ndarray, shape (M,)
        Position inside the cell, in ``[0, 1]``.

    Returns
    -------
    weights, derivatives : ndarray, shape (4, M)
        Derivatives with respect to the position in cells.
    """
    t = np.asarray(fraction, dtype=np.float64)
    s = 1.0 - t
    weights = np.stack(
        [s**3 / 6, 2 / 3 - t**2 + 0.5 * t**3, 1 / 6 + 0.5 * (t + t**2 - t**3), t**3 / 6]
    )
    derivatives = np.stack([-0.5 * s**2, 1.5 * t**2 - 2 * t, 0.5 + t - 1.5 * t**2, 0.5 * t**2])
    return weights, derivatives

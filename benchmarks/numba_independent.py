"""A second float64 numba implementation of rimcl's trace, written apart from the package.

It checks the baseline that ``benchmarks/speed.py`` divides by: ``rimcl.optics.baseline``
should trace as fast as plain numba code of the same method does (issue 26: "× numba"
ratios mean what they say only then). Written from the method, not from the package's
code: the interpolation is the weighted sum of a cell's eight corners (the package blends
along x1, then x2, then x3), the ray state is a pair of 3-tuples, and the force
``n ∇n`` is evaluated once per sample point.

The method (as ``cl/trace.cl`` with trilinear interpolation and a fixed step):
d²r/dt² = n ∇n, t = dr/dt (|t| = n), Sharma's RKN step

    a = h f(r),  b = h f(r + h t/2 + h a/8),  c = h f(r + h t + h b/2),
    r' = r + h (t + (a + 2b)/6),  t' = t + (a + 4b + c)/6,

and on the step that crosses the exit plane x1 = x_end, Newton's method on the step length
so that the ray ends on the plane. A ray stops ``ok`` there, ``exit_side`` outside the
box, ``turned_back`` when it stops moving towards the plane, ``max_steps``, or
``non_finite``.

Only the benchmark and ``tests/test_speed_parity.py`` use it.
"""

import math

import numba
import numpy as np
from numba import prange

_OK, _EXIT_SIDE, _TURNED_BACK, _MAX_STEPS, _NON_FINITE = range(5)


@numba.njit(cache=True)
def _corner(u, count, periodic):
    """Lower node, upper node and weight of the upper node along one axis."""
    if periodic:
        base = math.floor(u)
        lower = int(base) % count
        return lower, (lower + 1) % count, u - base
    u = min(max(u, 0.0), count - 1.0)
    lower = min(int(u), max(count - 2, 0))
    return lower, min(lower + 1, count - 1), u - lower


@numba.njit(cache=True)
def _force(nodes, lo, inv_h, n_ref, periodic, p):
    """``n ∇n`` at ``p`` as a 3-tuple, from trilinear ``δn`` and ``∇n``."""
    n3, n2, n1, _ = nodes.shape
    x0, x1, wx = _corner((p[0] - lo[0]) * inv_h[0], n1, periodic)
    y0, y1, wy = _corner((p[1] - lo[1]) * inv_h[1], n2, periodic)
    z0, z1, wz = _corner((p[2] - lo[2]) * inv_h[2], n3, periodic)
    dn = gx = gy = gz = 0.0
    for kz in range(2):
        z, fz = (z1, wz) if kz else (z0, 1.0 - wz)
        for ky in range(2):
            y, fy = (y1, wy) if ky else (y0, 1.0 - wy)
            for kx in range(2):
                x, fx = (x1, wx) if kx else (x0, 1.0 - wx)
                weight = fz * fy * fx
                dn += weight * nodes[z, y, x, 0]
                gx += weight * nodes[z, y, x, 1]
                gy += weight * nodes[z, y, x, 2]
                gz += weight * nodes[z, y, x, 3]
    n = n_ref + dn
    return (n * gx, n * gy, n * gz)


@numba.njit(cache=True)
def _index(nodes, lo, inv_h, n_ref, periodic, p):
    """The refractive index ``n`` at ``p``, trilinear."""
    n3, n2, n1, _ = nodes.shape
    x0, x1, wx = _corner((p[0] - lo[0]) * inv_h[0], n1, periodic)
    y0, y1, wy = _corner((p[1] - lo[1]) * inv_h[1], n2, periodic)
    z0, z1, wz = _corner((p[2] - lo[2]) * inv_h[2], n3, periodic)
    dn = 0.0
    for kz in range(2):
        z, fz = (z1, wz) if kz else (z0, 1.0 - wz)
        for ky in range(2):
            y, fy = (y1, wy) if ky else (y0, 1.0 - wy)
            for kx in range(2):
                x, fx = (x1, wx) if kx else (x0, 1.0 - wx)
                dn += fz * fy * fx * nodes[z, y, x, 0]
    return n_ref + dn


@numba.njit(cache=True)
def _rkn(nodes, lo, inv_h, n_ref, periodic, r, t, f, h):
    """One Sharma RKN step of length ``h`` from ``(r, t)`` with ``f = n ∇n`` at ``r``."""
    a = (h * f[0], h * f[1], h * f[2])
    p = (
        r[0] + h * (0.5 * t[0] + 0.125 * a[0]),
        r[1] + h * (0.5 * t[1] + 0.125 * a[1]),
        r[2] + h * (0.5 * t[2] + 0.125 * a[2]),
    )
    fb = _force(nodes, lo, inv_h, n_ref, periodic, p)
    b = (h * fb[0], h * fb[1], h * fb[2])
    p = (
        r[0] + h * (t[0] + 0.5 * b[0]),
        r[1] + h * (t[1] + 0.5 * b[1]),
        r[2] + h * (t[2] + 0.5 * b[2]),
    )
    fc = _force(nodes, lo, inv_h, n_ref, periodic, p)
    c = (h * fc[0], h * fc[1], h * fc[2])
    r_new = (
        r[0] + h * (t[0] + (a[0] + 2.0 * b[0]) / 6.0),
        r[1] + h * (t[1] + (a[1] + 2.0 * b[1]) / 6.0),
        r[2] + h * (t[2] + (a[2] + 2.0 * b[2]) / 6.0),
    )
    t_new = (
        t[0] + (a[0] + 4.0 * b[0] + c[0]) / 6.0,
        t[1] + (a[1] + 4.0 * b[1] + c[1]) / 6.0,
        t[2] + (a[2] + 4.0 * b[2] + c[2]) / 6.0,
    )
    return r_new, t_new


def trace(nodes, lo, inv_h, n_ref, periodic, box_lo, box_hi, origins, directions, x_end, h, limit):
    """Trace every ray; parallel over rays.

    Parameters
    ----------
    nodes : ndarray, float32, shape (n3, n2, n1, 4)
        ``(δn, ∂n/∂x1, ∂n/∂x2, ∂n/∂x3)`` at the grid nodes.
    lo, inv_h : ndarray, float64, shape (3,)
        Grid origin and inverse spacing.
    n_ref : float
    periodic : bool
    box_lo, box_hi : ndarray, float64, shape (3,)
    origins, directions : ndarray, float64, shape (N, 3)
        Unit directions.
    x_end, h : float
        Exit plane and step in ``t``.
    limit : int
        Most steps per ray.

    Returns
    -------
    end : ndarray, float64, shape (N, 6)
        Exit ``r`` and ``t``.
    steps, status : ndarray of int64, shape (N,)
    """
    count = origins.shape[0]
    end = np.empty((count, 6))
    steps = np.zeros(count, dtype=np.int64)
    status = np.zeros(count, dtype=np.int64)
    tiny = 4.0 * np.finfo(np.float64).eps
    for i in prange(count):
        rx, ry, rz = origins[i, 0], origins[i, 1], origins[i, 2]
        n = _index(nodes, lo, inv_h, n_ref, periodic, (rx, ry, rz))
        tx, ty, tz = n * directions[i, 0], n * directions[i, 1], n * directions[i, 2]
        gap = rx - x_end
        start_on_plane = gap == 0.0
        sign = (1.0 if tx >= 0.0 else -1.0) if start_on_plane else math.copysign(1.0, gap)
        done = -1
        taken = 0
        while done < 0:
            if taken >= limit:
                done = _MAX_STEPS
                break
            r, t = (rx, ry, rz), (tx, ty, tz)
            f = _force(nodes, lo, inv_h, n_ref, periodic, r)
            r_new, t_new = _rkn(nodes, lo, inv_h, n_ref, periodic, r, t, f, h)
            taken += 1
            new_gap = r_new[0] - x_end
            finite = True
            for k in range(3):
                finite = finite and np.isfinite(r_new[k]) and np.isfinite(t_new[k])
            if not finite:
                done = _NON_FINITE
            elif sign * new_gap <= 0.0:
                # Newton on the length of the last step: x1(h_k) = x_end
                hk = h * gap / (gap - new_gap)
                for _ in range(6):
                    r_new, t_new = _rkn(nodes, lo, inv_h, n_ref, periodic, r, t, f, hk)
                    dh = (r_new[0] - x_end) / t_new[0]
                    if not abs(dh) > tiny * hk:
                        break
                    hk = min(max(hk - dh, 0.0), h)
                done = _OK
            rx, ry, rz = r_new
            tx, ty, tz = t_new
            gap = new_gap
            if done >= 0:
                break
            if not (box_lo[0] <= rx <= box_hi[0]):
                done = _EXIT_SIDE
            elif not (box_lo[1] <= ry <= box_hi[1] and box_lo[2] <= rz <= box_hi[2]):
                done = _EXIT_SIDE
            elif not start_on_plane and sign * tx >= 0.0:
                done = _TURNED_BACK
        end[i, 0], end[i, 1], end[i, 2] = rx, ry, rz
        end[i, 3], end[i, 4], end[i, 5] = tx, ty, tz
        steps[i] = taken
        status[i] = done
    return end, steps, status


_parallel = numba.njit(parallel=True, cache=True)(trace)
# a serial build for the test (numba caches by name and types, not by `parallel`)
_serial = numba.njit(cache=False)(trace)


def trace_field(field, origins, directions, *, x_end, step, max_steps, parallel=True):
    """:func:`trace` on a ``rimcl.Field`` (trilinear nodes ``field.packed``); ``parallel``
    False compiles faster (tests)."""
    return (_parallel if parallel else _serial)(
        field.packed,
        np.asarray(field.origin, dtype=np.float64),
        1.0 / np.asarray(field.spacing, dtype=np.float64),
        float(field.n_ref),
        bool(field.periodic),
        np.asarray(field.box_lo, dtype=np.float64),
        np.asarray(field.box_hi, dtype=np.float64),
        np.ascontiguousarray(origins, dtype=np.float64),
        np.ascontiguousarray(directions, dtype=np.float64),
        float(x_end),
        float(step),
        int(max_steps),
    )

"""A straightforward float64 numba implementation of the trace, the speed baseline.

The same method as ``cl/trace.cl`` with ``trilinear`` interpolation and a fixed step:
Sharma's RKN step, Newton on the last step length so that the ray ends on the exit
plane, the same status rules; one ray per loop iteration, parallel over rays
(``numba.prange``), everything in float64 except the float32 field nodes (as in the
kernel). It computes no path integrals, so it does less work per step than the kernel.

:func:`trace_rays_numba` is what ``benchmarks/speed.py`` times against
:func:`rimcl.trace_rays` (only same-run ratios mean anything). numba is an
optional dependency (``pip install "rimcl[test]"``).
"""

import math

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import Field
from rimcl.optics.reference import rescale_to_exit_index
from rimcl.optics.trace import (
    _default_max_steps,
    _finish,
    _validate_rays,
    default_step,
    split_pairs,
)

_NEWTON_ITERATIONS = 6


try:
    import numba
    from numba import prange
except ImportError:  # optional: only the benchmark and its tests need it
    numba = None
    prange = range


def _jit(cache=True, **options):
    """numba.njit with an on-disk cache (the first compile takes ~20 s), or nothing."""
    if numba is None:
        return lambda function: function
    return numba.njit(cache=cache, error_model="numpy", **options)


@_jit(inline="always")
def _cell(u, count, periodic):
    if periodic:
        lower = math.floor(u)
        index = int(lower) % count
        upper = index + 1 if index + 1 < count else 0
        return index, upper, u - lower
    u = min(max(u, 0.0), count - 1.0)
    index = min(int(u), max(count - 2, 0))
    return index, min(index + 1, count - 1), u - index


@_jit(inline="always")
def _blend(nodes, c, i1, j1, w1, i2, j2, w2, i3, j3, w3):
    """Component ``c`` of the nodes, trilinear in float64: along x1, then x2, then x3."""
    # each float32 node to float64 first: their differences are not rounded to float32
    v000, v001 = np.float64(nodes[i3, i2, i1, c]), np.float64(nodes[i3, i2, j1, c])
    v010, v011 = np.float64(nodes[i3, j2, i1, c]), np.float64(nodes[i3, j2, j1, c])
    v100, v101 = np.float64(nodes[j3, i2, i1, c]), np.float64(nodes[j3, i2, j1, c])
    v110, v111 = np.float64(nodes[j3, j2, i1, c]), np.float64(nodes[j3, j2, j1, c])
    a00 = v000 + w1 * (v001 - v000)
    a01 = v010 + w1 * (v011 - v010)
    a10 = v100 + w1 * (v101 - v100)
    a11 = v110 + w1 * (v111 - v110)
    a0 = a00 + w2 * (a01 - a00)
    a1 = a10 + w2 * (a11 - a10)
    return a0 + w3 * (a1 - a0)


@_jit(inline="always")
def _sample(nodes, origin, inv_h, n_ref, periodic, x1, x2, x3):
    """``(n, ∂n/∂x1, ∂n/∂x2, ∂n/∂x3)`` at a point, trilinear, as four scalars: the loop
    over rays keeps its state in registers and allocates nothing."""
    n3, n2, n1, _ = nodes.shape
    i1, j1, w1 = _cell((x1 - origin[0]) * inv_h[0], n1, periodic)
    i2, j2, w2 = _cell((x2 - origin[1]) * inv_h[1], n2, periodic)
    i3, j3, w3 = _cell((x3 - origin[2]) * inv_h[2], n3, periodic)
    return (
        _blend(nodes, 0, i1, j1, w1, i2, j2, w2, i3, j3, w3) + n_ref,
        _blend(nodes, 1, i1, j1, w1, i2, j2, w2, i3, j3, w3),
        _blend(nodes, 2, i1, j1, w1, i2, j2, w2, i3, j3, w3),
        _blend(nodes, 3, i1, j1, w1, i2, j2, w2, i3, j3, w3),
    )


@_jit(inline="always")
def _step(nodes, origin, inv_h, n_ref, periodic, r1, r2, r3, t1, t2, t3, n, g1, g2, g3, h):
    """One RKN step of length ``h`` from ``(r, t)``, with ``(n, ∇n)`` sampled at ``r``:
    the new ``(r, t)`` and ``(n, ∇n)`` at the step's last sample point."""
    a1, a2, a3 = h * (n * g1), h * (n * g2), h * (n * g3)
    n, g1, g2, g3 = _sample(
        nodes, origin, inv_h, n_ref, periodic,
        r1 + 0.5 * h * t1 + 0.125 * h * a1,
        r2 + 0.5 * h * t2 + 0.125 * h * a2,
        r3 + 0.5 * h * t3 + 0.125 * h * a3,
    )  # fmt: skip
    b1, b2, b3 = h * n * g1, h * n * g2, h * n * g3
    n, g1, g2, g3 = _sample(
        nodes, origin, inv_h, n_ref, periodic,
        r1 + h * t1 + 0.5 * h * b1,
        r2 + h * t2 + 0.5 * h * b2,
        r3 + h * t3 + 0.5 * h * b3,
    )  # fmt: skip
    c1, c2, c3 = h * n * g1, h * n * g2, h * n * g3
    return (
        r1 + h * (t1 + (a1 + 2.0 * b1) / 6.0),
        r2 + h * (t2 + (a2 + 2.0 * b2) / 6.0),
        r3 + h * (t3 + (a3 + 2.0 * b3) / 6.0),
        t1 + (a1 + 4.0 * b1 + c1) / 6.0,
        t2 + (a2 + 4.0 * b2 + c2) / 6.0,
        t3 + (a3 + 4.0 * b3 + c3) / 6.0,
    )


def _trace(nodes, origin, inv_h, n_ref, periodic, box_lo, box_hi, r0, d0, x_end, h, limit):
    count = r0.shape[0]
    end = np.empty((count, 6))
    info = np.zeros((count, 2), dtype=np.int32)
    eps = np.finfo(np.float64).eps
    for ray in prange(count):
        r1, r2, r3 = r0[ray, 0], r0[ray, 1], r0[ray, 2]
        n, g1, g2, g3 = _sample(nodes, origin, inv_h, n_ref, periodic, r1, r2, r3)
        t1, t2, t3 = n * d0[ray, 0], n * d0[ray, 1], n * d0[ray, 2]
        offset = r1 - x_end
        on_plane = offset == 0.0
        if on_plane:
            side = 1.0 if t1 >= 0.0 else -1.0
        else:
            side = 1.0 if offset > 0.0 else -1.0
        status = -1
        steps = 0
        while status < 0:
            if steps >= limit:
                status = 3
                break
            q1, q2, q3, u1, u2, u3 = _step(
                nodes, origin, inv_h, n_ref, periodic, r1, r2, r3, t1, t2, t3, n, g1, g2, g3, h
            )
            steps += 1
            new_offset = q1 - x_end
            finite = (
                math.isfinite(q1) and math.isfinite(q2) and math.isfinite(q3)
                and math.isfinite(u1) and math.isfinite(u2) and math.isfinite(u3)
            )  # fmt: skip
            if not finite:
                status = 4
            elif side * new_offset <= 0.0:
                hk = h * offset / (offset - new_offset)
                for _ in range(_NEWTON_ITERATIONS):
                    q1, q2, q3, u1, u2, u3 = _step(
                        nodes, origin, inv_h, n_ref, periodic,
                        r1, r2, r3, t1, t2, t3, n, g1, g2, g3, hk,
                    )  # fmt: skip
                    dh = (q1 - x_end) / u1
                    if not abs(dh) > 4.0 * eps * hk:
                        break
                    hk = min(max(hk - dh, 0.0), h)
                status = 0
            r1, r2, r3, t1, t2, t3 = q1, q2, q3, u1, u2, u3
            offset = new_offset
            if status >= 0:
                break
            if (
                r1 < box_lo[0] or r1 > box_hi[0]
                or r2 < box_lo[1] or r2 > box_hi[1]
                or r3 < box_lo[2] or r3 > box_hi[2]
            ):  # fmt: skip
                status = 1
            elif not on_plane and -side * t1 <= 0.0:
                status = 2
            else:
                n, g1, g2, g3 = _sample(nodes, origin, inv_h, n_ref, periodic, r1, r2, r3)
        end[ray, 0], end[ray, 1], end[ray, 2] = r1, r2, r3
        end[ray, 3], end[ray, 4], end[ray, 5] = t1, t2, t3
        info[ray, 0] = steps
        info[ray, 1] = status
    return end, info


_trace_parallel = _jit(parallel=True)(_trace)
# not cached: numba's disk cache keys a function by its name and signature, not by
# `parallel`, so a cached serial build of _trace was loaded as the parallel one
_trace_serial = _jit(cache=False)(_trace)


def trace_rays_numba(
    field, origins, directions, *, x_end, step=None, max_steps=None, parallel=True
):
    """Trace rays like :func:`rimcl.trace_rays` (trilinear, fixed step) in numba float64.

    Parameters
    ----------
    field : Field
    origins, directions : array_like, shape (N, 3)
    x_end : float
    step : float, optional
        Step in ``t``; default :func:`rimcl.optics.trace.default_step`.
    max_steps : int, optional
    parallel : bool
        Parallel over rays on all cores (the baseline); False compiles in a third of
        the time (7 s against 17 s), for tests of the method.

    Returns
    -------
    TraceResult
        Path integrals are not computed (path length zero, ``n_metric`` NaN).
    """
    if not isinstance(field, Field):
        raise RimclError("the numba baseline traces gridded fields only")
    origins, directions = _validate_rays(origins, directions)
    step = default_step(field) if step is None else float(step)
    if max_steps is None:
        max_steps = _default_max_steps(field, step, x_end, origins, directions)
    if numba is None:
        raise RimclError('the numba baseline needs numba: pip install "rimcl[test]"')
    end, info = (_trace_parallel if parallel else _trace_serial)(
        field.packed,
        field.origin,
        1.0 / field.spacing,
        field.n_ref,
        field.periodic,
        np.asarray(field.box_lo, dtype=np.float64),
        np.asarray(field.box_hi, dtype=np.float64),
        origins,
        directions,
        float(x_end),
        step,
        int(max_steps),
    )
    # |T| = n at the exit point, as the kernel ends its rays; then the exit state as the
    # kernel writes it: float64 values in float32 (hi, lo) pairs
    rescale_to_exit_index(field, end[:, :3], end[:, 3:], info[:, 1] == 0, "trilinear")
    raw = np.zeros((len(origins), 17), dtype=np.float32)
    raw[:, 0:3], raw[:, 3:6] = split_pairs(end[:, :3])
    raw[:, 6:9], raw[:, 9:12] = split_pairs(end[:, 3:])
    config = {"x_end": float(x_end), "step": step, "interp": "trilinear", "precision": "numba-f64"}
    return _finish(origins, directions, raw, info, step, config)

"""Plain NumPy float64 versions of the kernels, for tests and as a readable specification.

:func:`trace_rays_reference` follows ``cl/trace.cl`` operation for operation (the same
Sharma step, interpolation, exact plane stop and status rules) in float64 arithmetic on
the same float32 field samples, vectorised over rays. It is slow; use it on small inputs.
"""

import numpy as np

from rimcl.fields.field import AnalyticField
from rimcl.optics.trace import (
    _default_max_steps,
    _finish,
    _validate_rays,
    default_step,
    split_pairs,
)

_NEWTON_ITERATIONS = 6


def _cell(u, count, periodic):
    if periodic:
        lower = np.floor(u)
        weight = u - lower
        index = np.mod(lower.astype(np.int64), count)
        return index, np.where(index + 1 == count, 0, index + 1), weight
    u = np.clip(u, 0.0, count - 1.0)
    index = np.minimum(np.floor(u).astype(np.int64), max(count - 2, 0))
    return index, np.minimum(index + 1, count - 1), u - index


def sample_field(field, points, interp="trilinear"):
    """``n`` and ``∇n`` at ``points`` in float64.

    Parameters
    ----------
    field : Field or AnalyticField
    points : ndarray, shape (M, 3)
        Positions ``(x1, x2, x3)``.
    interp : {"trilinear", "texture", "bspline3"}
        ``texture`` is trilinear interpolation done by the device's image hardware; its
        exact value is the ``trilinear`` one.

    Returns
    -------
    n : ndarray, shape (M,)
    grad : ndarray, shape (M, 3)
    """
    points = np.asarray(points, dtype=np.float64)
    if isinstance(field, AnalyticField):
        return field.refractive_index(points), field.index_gradient(points)
    if interp == "bspline3":
        return _sample_bspline3(field, points)
    u = (points - field.origin) / field.spacing
    data = field.packed.astype(np.float64)
    n1, n2, n3 = field.counts
    i1, j1, w1 = _cell(u[:, 0], n1, field.periodic)
    i2, j2, w2 = _cell(u[:, 1], n2, field.periodic)
    i3, j3, w3 = _cell(u[:, 2], n3, field.periodic)

    def lerp(a, b, w):
        return a + w[:, None] * (b - a)

    c00 = lerp(data[i3, i2, i1], data[i3, i2, j1], w1)
    c01 = lerp(data[i3, j2, i1], data[i3, j2, j1], w1)
    c10 = lerp(data[j3, i2, i1], data[j3, i2, j1], w1)
    c11 = lerp(data[j3, j2, i1], data[j3, j2, j1], w1)
    value = lerp(lerp(c00, c01, w2), lerp(c10, c11, w2), w3)
    return field.n_ref + value[:, 0], value[:, 1:]


def _bspline_taps(u, count, periodic):
    """Array indices (4, M) of the taps around coordinate u (cells) and the fraction."""
    if periodic:
        lower = np.floor(u)
        cell = lower.astype(np.int64)
        taps = np.mod(cell[None, :] + np.arange(-1, 3)[:, None], count)
        return taps, u - lower
    u = np.clip(u, 0.0, count - 1.0)
    cell = np.minimum(np.floor(u).astype(np.int64), max(count - 2, 0))
    # node i - 1 + k is stored at index i + k (rimcl.fields.bspline)
    return cell[None, :] + np.arange(4)[:, None], u - cell


def _sample_bspline3(field, points):
    from rimcl.fields.bspline import bspline_weights
    from rimcl.optics.trace import bspline_coefficients

    coefficients = bspline_coefficients(field).astype(np.float64)
    u = (points - field.origin) / field.spacing
    taps, weights, slopes = [], [], []
    for axis in range(3):
        axis_taps, fraction = _bspline_taps(u[:, axis], field.counts[axis], field.periodic)
        w, dw = bspline_weights(fraction)
        taps.append(axis_taps)
        weights.append(w)
        slopes.append(dw)
    value = np.zeros(len(points))
    grad = np.zeros((len(points), 3))
    for c in range(4):
        for b in range(4):
            for a in range(4):
                coef = coefficients[taps[2][c], taps[1][b], taps[0][a]]
                wx, wy, wz = weights[0][a], weights[1][b], weights[2][c]
                value += wx * wy * wz * coef
                grad[:, 0] += slopes[0][a] * wy * wz * coef
                grad[:, 1] += wx * slopes[1][b] * wz * coef
                grad[:, 2] += wx * wy * slopes[2][c] * coef
    return field.n_ref + value, grad / field.spacing


def _step(field, r, t, d_a, h, interp):
    """One Sharma step for rows of (r, t) with per-row step h; returns samples too."""
    h = h[:, None]
    a = h * d_a
    n_b, g_b = sample_field(field, r + 0.5 * h * t + 0.125 * h * a, interp)
    b = h * n_b[:, None] * g_b
    n_c, g_c = sample_field(field, r + h * t + 0.5 * h * b, interp)
    c = h * n_c[:, None] * g_c
    r_new = r + h * (t + (a + 2 * b) / 6)
    t_new = t + (a + 4 * b + c) / 6
    return r_new, t_new, (n_b, g_b), (n_c, g_c)


def _perpendicular(grad, t):
    unit = t / np.linalg.norm(t, axis=1, keepdims=True)
    return grad - np.sum(grad * unit, axis=1, keepdims=True) * unit


def rescale_to_exit_index(field, r, t, done, interp):
    """Rescale ``t`` of the rows ``done`` (in place) so that ``|t|`` is ``n`` sampled at
    their exit points ``r``, the direction kept: the exit index, as ``at_exit_index`` in
    ``cl/rimcl_trace.h`` does."""
    if np.any(done):
        n_exit, _ = sample_field(field, r[done], interp)
        t[done] *= (n_exit / np.linalg.norm(t[done], axis=1))[:, None]


def trace_rays_reference(
    field, origins, directions, *, x_end, step=None, max_steps=None, interp="trilinear"
):
    """Float64 NumPy twin of :func:`rimcl.trace_rays` with a fixed step (same inputs,
    same result type).

    Origins, directions and parameters are rounded to the (hi, lo) float32 pairs the
    kernel receives, so both see the same inputs. ``interp`` is ``trilinear``,
    ``texture`` (the same as trilinear) or ``bspline3``.
    """
    origins, directions = _validate_rays(origins, directions)
    origins = np.sum(split_pairs(origins), axis=0, dtype=np.float64)
    directions = np.sum(split_pairs(directions), axis=0, dtype=np.float64)
    step = default_step(field) if step is None else float(step)
    step = float(np.sum(split_pairs(step), dtype=np.float64))
    x_end = float(np.sum(split_pairs(float(x_end)), dtype=np.float64))
    if max_steps is None:
        max_steps = _default_max_steps(field, step, x_end, origins, directions)
    box_lo = np.asarray(field.box_lo, dtype=np.float32).astype(np.float64)
    box_hi = np.asarray(field.box_hi, dtype=np.float32).astype(np.float64)

    count = origins.shape[0]
    r = origins.copy()
    n_a, g_a = sample_field(field, r, interp)
    t = n_a[:, None] * directions
    offset = r[:, 0] - x_end
    on_plane = offset == 0
    side = np.where(on_plane, np.where(t[:, 0] >= 0, 1.0, -1.0), np.sign(offset))
    status = np.full(count, -1, dtype=np.int32)
    steps = np.zeros(count, dtype=np.int64)
    path = np.zeros(count)
    optical = np.zeros(count)
    nperp = np.zeros((count, 3))

    active = np.arange(count)
    while active.size:
        done_by_count = steps[active] >= max_steps
        status[active[done_by_count]] = 3
        active = active[~done_by_count]
        if not active.size:
            break
        ra, ta, na, ga = r[active], t[active], n_a[active], g_a[active]
        d_a = na[:, None] * ga
        h = np.full(active.size, step)
        r_new, t_new, sb, sc = _step(field, ra, ta, d_a, h, interp)
        steps[active] += 1
        new_offset = r_new[:, 0] - x_end
        finite = np.all(np.isfinite(r_new), axis=1) & np.all(np.isfinite(t_new), axis=1)
        crossed = finite & (side[active] * new_offset <= 0)
        if np.any(crossed):
            rows = np.flatnonzero(crossed)
            hk = step * offset[active[rows]] / (offset[active[rows]] - new_offset[rows])
            converged = np.zeros(rows.size, dtype=bool)
            for _ in range(_NEWTON_ITERATIONS):
                todo = np.flatnonzero(~converged)
                if not todo.size:
                    break
                sel = rows[todo]
                rk, tk, sbk, sck = _step(field, ra[sel], ta[sel], d_a[sel], hk[todo], interp)
                r_new[sel], t_new[sel] = rk, tk
                sb[0][sel], sb[1][sel], sc[0][sel], sc[1][sel] = sbk[0], sbk[1], sck[0], sck[1]
                h[sel] = hk[todo]
                dh = (rk[:, 0] - x_end) / tk[:, 0]
                small = ~(np.abs(dh) > 4 * np.finfo(np.float64).eps * hk[todo])
                converged[todo[small]] = True
                moved = todo[~small]
                hk[moved] = np.clip(hk[moved] - dh[~small], 0.0, step)
        w = h / 6
        t_mid = ta + 0.5 * (t_new - ta)
        path[active] += w * (na + 4 * sb[0] + sc[0])
        optical[active] += w * (na**2 + 4 * sb[0] ** 2 + sc[0] ** 2)
        nperp[active] += w[:, None] * (
            _perpendicular(ga, ta) + 4 * _perpendicular(sb[1], t_mid) + _perpendicular(sc[1], t_new)
        )
        r[active], t[active] = r_new, t_new
        offset[active] = new_offset
        status[active[~finite]] = 4
        status[active[crossed]] = 0
        running = finite & ~crossed
        outside = running & (np.any(r_new < box_lo, axis=1) | np.any(r_new > box_hi, axis=1))
        status[active[outside]] = 1
        running &= ~outside
        turned = running & ~on_plane[active] & (-side[active] * t_new[:, 0] <= 0)
        status[active[turned]] = 2
        running &= ~turned
        active = active[running]
        if active.size:
            n_a[active], g_a[active] = sample_field(field, r[active], interp)

    rescale_to_exit_index(field, r, t, status == 0, interp)
    raw = np.zeros((count, 17), dtype=np.float32)
    raw[:, 0:3], raw[:, 3:6] = split_pairs(r)
    raw[:, 6:9], raw[:, 9:12] = split_pairs(t)
    raw[:, 12], raw[:, 13], raw[:, 14:17] = path, optical, nperp
    info = np.column_stack([steps, status]).astype(np.int32)
    config = {
        "x_end": x_end,
        "step": step,
        "interp": interp,
        "precision": "numpy-f64",
        "max_steps": max_steps,
    }
    result = _finish(origins, directions, raw, info, step, config)
    # keep the float64 path integrals unrounded
    result.path_length, result.optical_path = path, optical
    with np.errstate(invalid="ignore", divide="ignore"):
        result.n_metric = nperp / path[:, None]
    return result

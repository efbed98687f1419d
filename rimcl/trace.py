"""Stage 1: trace rays through a refractive-index field to an exit plane.

The OpenCL kernel (``cl/trace.cl``) integrates Fermat's equation with Sharma's
Runge–Kutta–Nyström scheme and stops each ray exactly on the plane ``x1 = x_end``;
this module prepares the inputs, runs the kernel in batches of bounded memory and turns
the exit states into float64 results (back-projection, deflection, path integrals).
"""

import dataclasses
import math

import numpy as np

from rimcl.errors import RimclError
from rimcl.field import AnalyticField, Field

STATUS_NAMES = ("ok", "exit_side", "turned_back", "max_steps", "non_finite")
PRECISIONS = ("f32", "f32c", "f64")
INTERPOLATIONS = ("trilinear",)

_PRECISION_DEFINE = {"f32": 0, "f32c": 1, "f64": 2}
_ANALYTIC_DEFINE = {"uniform": 1, "grin": 2, "fisheye": 3, "linear": 4}
_ANALYTIC_PARAM_ORDER = {
    "uniform": ("n0",),
    "grin": ("n0", "alpha"),
    "fisheye": ("n_max",),
    "linear": ("n0", "g"),
}

# offsets of the float parameter block, as in cl/rimcl_params.h
_P_ORIGIN_HI, _P_ORIGIN_LO, _P_INVH_HI, _P_INVH_LO = 0, 3, 6, 9
_P_BOX_LO, _P_BOX_HI, _P_NREF, _P_XEND, _P_STEP = 12, 15, 18, 20, 22
_P_ANALYTIC_HI, _P_ANALYTIC_LO, _P_COUNT = 24, 28, 32
_RAY_IN_STRIDE, _RAY_OUT_STRIDE = 12, 17

DEFAULT_BATCH = 1 << 18


def split_pairs(values):
    """Split float64 values into float32 ``(hi, lo)`` with ``hi + lo`` ≈ value to ~1e-15.

    Parameters
    ----------
    values : array_like of float64

    Returns
    -------
    hi, lo : ndarray of float32, same shape
    """
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        hi = values.astype(np.float32)
        lo = np.where(np.isfinite(values), values - hi.astype(np.float64), 0.0).astype(np.float32)
    return hi, lo


def join_pairs(hi, lo):
    """Inverse of :func:`split_pairs`: ``hi + lo`` in float64."""
    return hi.astype(np.float64) + lo.astype(np.float64)


@dataclasses.dataclass
class TraceResult:
    """Per-ray results of :func:`trace_rays`, all float64 NumPy arrays.

    Attributes
    ----------
    origins, directions : ndarray, shape (N, 3)
        Start points and unit start directions ``d_0``.
    image_pos : ndarray, shape (N, 3)
        Where the straight backward extension of the exit ray meets the plane
        ``x1 = origins[:, 0]`` (what an ideal lens focused there images); NaN for rays
        whose status is not ``ok``.
    end_pos : ndarray, shape (N, 3)
        Exit point (on ``x1 = x_end`` for ``ok`` rays; the last position otherwise).
    end_dir : ndarray, shape (N, 3)
        Unit exit direction ``d_f``.
    deflection : ndarray, shape (N,)
        ``|Δθ|``, the angle between ``d_0`` and ``d_f`` (rad).
    deflection_angles : ndarray, shape (N, 3)
        ``θ_f - θ_0``, differences of the direction angles to ``x1, x2, x3`` (rad).
    path_length : ndarray, shape (N,)
        Geometric path length ``S`` (length units).
    optical_path : ndarray, shape (N,)
        ``∫ n ds`` (length units).
    n_metric : ndarray, shape (N, 3)
        The paper's ``N = (1/S) ∫ (∇n/n)_⊥ ds`` (1/length); ``|Δθ| ≈ |N| S``.
    steps : ndarray of int, shape (N,)
        Integration steps taken (the shortened last step included).
    status : ndarray of int8, shape (N,)
        Index into :data:`STATUS_NAMES`.
    step : float
        The step in ``t`` actually used (``dt = ds/n``).
    config : dict
        Settings of the call, for output files.
    """

    origins: np.ndarray
    directions: np.ndarray
    image_pos: np.ndarray
    end_pos: np.ndarray
    end_dir: np.ndarray
    deflection: np.ndarray
    deflection_angles: np.ndarray
    path_length: np.ndarray
    optical_path: np.ndarray
    n_metric: np.ndarray
    steps: np.ndarray
    status: np.ndarray
    step: float
    config: dict

    @property
    def counts(self):
        """Number of rays per status name (every name present, zeros included)."""
        found = np.bincount(self.status.astype(np.int64), minlength=len(STATUS_NAMES))
        return {name: int(found[i]) for i, name in enumerate(STATUS_NAMES)}

    @property
    def ok(self):
        """Boolean mask of rays that reached the exit plane."""
        return self.status == 0

    def __len__(self):
        return self.status.size


def direction_angles(directions):
    """Angles (rad) between unit vectors and the ``x1, x2, x3`` axes, shape (N, 3).

    Uses ``atan2(|d × e_k|, d_k)``, accurate for angles near 0 and π.
    """
    d = np.asarray(directions, dtype=np.float64)
    squares = d**2
    total = squares.sum(axis=-1, keepdims=True)
    return np.arctan2(np.sqrt(np.maximum(total - squares, 0.0)), d)


def angle_between(a, b):
    """Angle (rad) between rows of ``a`` and ``b``, accurate for small angles."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.sum(a * b, axis=-1))


def default_step(field):
    """Half a cell of arc: ``0.5 min(h) / n_ref`` (DESIGN §4.2); 1e-3 for closed forms."""
    if isinstance(field, Field):
        return 0.5 * float(np.min(field.spacing)) / field.n_ref
    return 1e-3


def _validate_rays(origins, directions):
    origins = np.atleast_2d(np.asarray(origins, dtype=np.float64))
    directions = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    if origins.ndim != 2 or origins.shape[1] != 3:
        raise RimclError(f"origins must have shape (N, 3), got {origins.shape}")
    if directions.shape != origins.shape:
        raise RimclError(
            f"directions must have the shape of origins {origins.shape}, got {directions.shape}"
        )
    if origins.shape[0] == 0:
        raise RimclError("no rays to trace (the ray set is empty)")
    if not (np.all(np.isfinite(origins)) and np.all(np.isfinite(directions))):
        raise RimclError("ray origins or directions hold NaN or infinite values")
    norms = np.linalg.norm(directions, axis=1)
    if np.any(norms == 0):
        raise RimclError("a ray direction is the zero vector")
    return origins, directions / norms[:, None]


def _check_step(field, step, x_end, origins):
    if not (step > 0 and math.isfinite(step)):
        raise RimclError(f"the step must be a positive number, got {step}")
    depth = float(np.max(np.abs(x_end - origins[:, 0])))
    if isinstance(field, Field):
        extent = float(np.max(field.counts * field.spacing))
        if step * field.n_ref > extent:
            raise RimclError(
                f"step {step:g} (arc {step * field.n_ref:g}) is larger than the field "
                f"({extent:g} across)"
            )
    elif depth > 0 and step * field.n_ref > depth:
        raise RimclError(f"step {step:g} is larger than the distance to the exit plane")


def _default_max_steps(field, step, x_end, origins, directions):
    n_min = field.n_min if isinstance(field, Field) else 0.5 * field.n_ref
    if isinstance(field, Field):
        span = float(np.linalg.norm(field.counts * field.spacing))
    else:
        depth = float(np.max(np.abs(x_end - origins[:, 0])))
        slope = max(float(np.min(np.abs(directions[:, 0]))), 0.05)
        span = max(depth / slope, 1.0) * math.pi
    return int(min(4 * span / (step * n_min) + 64, 2**31 - 1))


def _param_block(field, x_end, step):
    params = np.zeros(_P_COUNT, dtype=np.float32)

    def put(offset, values):
        hi, lo = split_pairs(np.atleast_1d(values))
        params[offset : offset + hi.size] = hi
        return lo

    def put_pair(offset, value):
        hi, lo = split_pairs([value])
        params[offset], params[offset + 1] = hi[0], lo[0]

    if isinstance(field, Field):
        params[_P_ORIGIN_LO : _P_ORIGIN_LO + 3] = put(_P_ORIGIN_HI, field.origin)
        params[_P_INVH_LO : _P_INVH_LO + 3] = put(_P_INVH_HI, 1.0 / field.spacing)
    else:
        names = _ANALYTIC_PARAM_ORDER[field.kind]
        values = [field.params[name] for name in names]
        params[_P_ANALYTIC_LO : _P_ANALYTIC_LO + len(values)] = put(_P_ANALYTIC_HI, values)
    with np.errstate(over="ignore"):
        params[_P_BOX_LO : _P_BOX_LO + 3] = np.asarray(field.box_lo, dtype=np.float32)
        params[_P_BOX_HI : _P_BOX_HI + 3] = np.asarray(field.box_hi, dtype=np.float32)
    put_pair(_P_NREF, field.n_ref)
    put_pair(_P_XEND, x_end)
    put_pair(_P_STEP, step)
    return params


def kernel_defines(field, precision):
    """``-D`` defines selecting the field kind, boundary and precision of ``trace.cl``."""
    if precision not in PRECISIONS:
        raise RimclError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if isinstance(field, Field):
        kind, periodic = 0, int(field.periodic)
    elif isinstance(field, AnalyticField):
        kind, periodic = _ANALYTIC_DEFINE[field.kind], 0
    else:
        raise RimclError(f"cannot trace through a {type(field).__name__}")
    return {
        "RIMCL_PRECISION": _PRECISION_DEFINE[precision],
        "RIMCL_FIELD": kind,
        "RIMCL_PERIODIC": periodic,
    }


def _field_buffer(field, context):
    import pyopencl as cl

    if isinstance(field, Field):
        return field.cached(
            ("trilinear", context),
            lambda: cl.Buffer(
                context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=field.packed
            ),
        )
    return cl.Buffer(context, cl.mem_flags.READ_ONLY, size=16)


def trace_rays(
    field,
    origins,
    directions,
    *,
    x_end,
    step=None,
    interp="trilinear",
    precision="f32c",
    device=None,
    max_steps=None,
    batch_size=DEFAULT_BATCH,
    progress=False,
):
    """Trace rays from ``origins`` along ``directions`` to the plane ``x1 = x_end``.

    Parameters
    ----------
    field : Field or AnalyticField
        The refractive-index field.
    origins : array_like, shape (N, 3)
        Start points ``(x1, x2, x3)`` (length units).
    directions : array_like, shape (N, 3)
        Start directions (normalised here).
    x_end : float
        The exit plane ``x1 = x_end``; it may be crossed in either direction, and a ray
        starting on it may come back to it.
    step : float, optional
        The paper's Δζ, a step in ``t`` (``dt = ds/n``, so ``n·step`` of arc). Default:
        half a cell of arc (:func:`default_step`).
    interp : {"trilinear"}
        Interpolation of gridded fields.
    precision : {"f32", "f32c", "f64"}
        Accumulation of position and direction: plain float32, double-float (default),
        or float64 (needs ``cl_khr_fp64``). Field samples are float32 in every mode.
    device : str or pyopencl.Device, optional
        See :func:`rimcl.select_device`.
    max_steps : int, optional
        Steps after which a ray is stopped with status ``max_steps``.
    batch_size : int
        Rays per kernel launch; bounds the memory used.
    progress : bool
        Show a progress bar over batches.

    Returns
    -------
    TraceResult
    """
    import pyopencl as cl

    from rimcl.device import context_for, has_fp64, queue_for, select_device
    from rimcl.program import build_program, get_kernel

    if interp not in INTERPOLATIONS:
        raise RimclError(f"interp must be one of {INTERPOLATIONS}, got {interp!r}")
    origins, directions = _validate_rays(origins, directions)
    x_end = float(x_end)
    step = default_step(field) if step is None else float(step)
    _check_step(field, step, x_end, origins)
    step = float(np.float64(np.float32(step)) + np.float32(step - np.float32(step)))
    if max_steps is None:
        max_steps = _default_max_steps(field, step, x_end, origins, directions)
    device = select_device(device)
    if precision == "f64" and not has_fp64(device):
        raise RimclError(f"precision f64 needs cl_khr_fp64, which {device.name.strip()} lacks")
    context, queue = context_for(device), queue_for(device)
    program = build_program(context, "trace.cl", kernel_defines(field, precision))
    kernel = get_kernel(program, "trace_rays")
    field_buffer = _field_buffer(field, context)
    counts = (
        np.array([*field.counts, 0], dtype=np.int32)
        if isinstance(field, Field)
        else (np.zeros(4, dtype=np.int32))
    )
    params = cl.Buffer(
        context,
        cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
        hostbuf=_param_block(field, x_end, step),
    )

    count = origins.shape[0]
    raw_out = np.empty((count, _RAY_OUT_STRIDE), dtype=np.float32)
    info = np.empty((count, 2), dtype=np.int32)
    batch_size = max(1, min(int(batch_size), count))
    rays_in_buf = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=batch_size * _RAY_IN_STRIDE * 4)
    rays_out_buf = cl.Buffer(
        context, cl.mem_flags.WRITE_ONLY, size=batch_size * _RAY_OUT_STRIDE * 4
    )
    info_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, size=batch_size * 8)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=count, unit="ray", desc="trace", leave=False)
    try:
        for start in range(0, count, batch_size):
            stop = min(start + batch_size, count)
            rays_in = np.empty((stop - start, _RAY_IN_STRIDE), dtype=np.float32)
            rays_in[:, 0:3], rays_in[:, 3:6] = split_pairs(origins[start:stop])
            rays_in[:, 6:9], rays_in[:, 9:12] = split_pairs(directions[start:stop])
            cl.enqueue_copy(queue, rays_in_buf, rays_in)
            kernel.set_args(
                field_buffer,
                counts,
                params,
                rays_in_buf,
                rays_out_buf,
                info_buf,
                np.int32(max_steps),
                np.int32(stop - start),
            )
            cl.enqueue_nd_range_kernel(queue, kernel, (stop - start,), None)
            cl.enqueue_copy(queue, raw_out[start:stop], rays_out_buf)
            cl.enqueue_copy(queue, info[start:stop], info_buf)
            queue.finish()
            if bar is not None:
                bar.update(stop - start)
    finally:
        if bar is not None:
            bar.close()

    config = {
        "x_end": x_end,
        "step": step,
        "interp": interp,
        "precision": precision,
        "max_steps": int(max_steps),
        "field": field.describe(),
    }
    return _finish(origins, directions, raw_out, info, step, config)


def _finish(origins, directions, raw_out, info, step, config):
    end_pos = join_pairs(raw_out[:, 0:3], raw_out[:, 3:6])
    end_t = join_pairs(raw_out[:, 6:9], raw_out[:, 9:12])
    status = info[:, 1].astype(np.int8)
    with np.errstate(invalid="ignore", divide="ignore"):
        end_dir = end_t / np.linalg.norm(end_t, axis=1, keepdims=True)
        ok = status == 0
        distance = (end_pos[:, 0] - origins[:, 0]) / end_dir[:, 0]
        image_pos = end_pos - distance[:, None] * end_dir
        image_pos[:, 0] = origins[:, 0]
        image_pos[~ok] = np.nan
        path_length = raw_out[:, 12].astype(np.float64)
        n_metric = raw_out[:, 14:17].astype(np.float64) / path_length[:, None]
    return TraceResult(
        origins=origins,
        directions=directions,
        image_pos=image_pos,
        end_pos=end_pos,
        end_dir=end_dir,
        deflection=angle_between(directions, end_dir),
        deflection_angles=direction_angles(end_dir) - direction_angles(directions),
        path_length=path_length,
        optical_path=raw_out[:, 13].astype(np.float64),
        n_metric=n_metric,
        steps=info[:, 0].astype(np.int64),
        status=status,
        step=step,
        config=config,
    )

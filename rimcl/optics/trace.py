"""Stage 1: trace rays through a refractive-index field to an exit plane.

The OpenCL kernel (``cl/trace.cl``) integrates Fermat's equation with Sharma's
Runge–Kutta–Nyström scheme and stops each ray exactly on the plane ``x1 = x_end``;
this module prepares the inputs, runs the kernel in batches of bounded memory and turns
the exit states into float64 results (back-projection, deflection, path integrals).

Choices a call makes:

- ``interp``: ``trilinear`` (software, float4 nodes ``δn, ∇n``), ``texture`` (the same
  nodes in an OpenCL image read with the hardware linear filter), ``bspline3`` (cubic
  B-spline of ``δn``, gradient from the same spline), or ``auto`` (calibrated).
- ``precision``: ``f32``, ``f32c`` (double-float accumulation, the default), ``f64``.
- ``step``: a fixed step in ``t``; None for half a cell of arc; ``"adaptive"`` for step
  doubling to ``tolerance``; ``"auto"`` for the largest fixed step that meets
  ``tolerance`` on a calibration subset (:mod:`rimcl.optics.auto_choice`).

:func:`rimcl.trace_rays` (:mod:`rimcl.optics.tracing`) resolves the ``auto`` choices and calls
:func:`run_trace` here, which traces with settings already chosen.
"""

import dataclasses
import logging
import math
import time

import numpy as np

from rimcl.core.errors import RimclError
from rimcl.fields.field import AnalyticField, Field
from rimcl.optics.shapes import KernelShape, default_kernel_shape, launch_group

logger = logging.getLogger(__name__)

STATUS_NAMES = ("ok", "exit_side", "turned_back", "max_steps", "non_finite")
PRECISIONS = ("f32", "f32c", "f64")
INTERPOLATIONS = ("trilinear", "texture", "bspline3")
#: What ``interp=`` accepts: an interpolation, or ``auto`` (calibrated per call).
INTERP_CHOICES = (*INTERPOLATIONS, "auto")
#: What ``step=`` accepts besides a number and None.
STEP_KEYWORDS = ("adaptive", "auto")

#: Pixels across the field of view of the paper's camera; default tolerances are 0.01 of
#: such a pixel (:func:`default_tolerance`).
PAPER_PIXELS = 8192
#: Adaptive steps stay within [ADAPTIVE_STEP_RANGE[0], ADAPTIVE_STEP_RANGE[1]] times the
#: default step: 1/512 of a cell to 2 cells of arc on a grid, where longer steps skip
#: features that the step-doubling estimate then misses too (both of its halves skip
#: them); closed-form fields may grow to a quarter of the depth.
ADAPTIVE_STEP_RANGE = (1 / 256, 4.0)
#: The local error allowed per unit arc length is tolerance / (ADAPTIVE_SAFETY * depth):
#: local errors add up and propagate along the ray, and interpolated fields have kinks
#: that the 4th-order estimate sees late.
ADAPTIVE_SAFETY = 4.0
#: Smallest adaptive tolerance per precision, relative to the lever arm (the depth): the
#: step-doubling estimate cannot resolve less than the rounding of the ray state.
TOLERANCE_FLOOR = {"f32": 1e-5, "f32c": 2e-8, "f64": 1e-13}
#: A fixed step longer than this many cells of arc is flagged (features narrower than
#: the step are skipped); it is used, not refused, since smooth fields allow it.
LONG_STEP_CELLS = 2.0

_PRECISION_DEFINE = {"f32": 0, "f32c": 1, "f64": 2}
_INTERP_DEFINE = {"trilinear": 0, "texture": 1, "bspline3": 2}
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
_P_ANALYTIC_HI, _P_ANALYTIC_LO = 24, 28
_P_STEP_MIN, _P_STEP_MAX, _P_TOL, _P_DEPTH, _P_COUNT = 32, 34, 36, 38, 40
_RAY_IN_STRIDE, _RAY_OUT_STRIDE, _RAY_INFO_STRIDE = 12, 17, 4

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
    """Per-ray results of :func:`rimcl.trace_rays`, all float64 NumPy arrays.

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
    exit_index : ndarray, shape (N,)
        The refractive index at the exit point, ``|T|`` of the exit state (``T = n dR/ds``):
        every engine rescales the exit ``T`` of a ray that ends on the plane so that
        ``|T|`` is ``n`` sampled at its exit point (the integrated ``|T|`` drifts from it).
        What Snell at a wall on the exit plane takes, for every camera.
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
    exit_index: np.ndarray
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
    """Half a cell of arc: ``0.5 min(h) / n_ref``; 1e-3 for closed forms."""
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


def default_tolerance(field, origins, x_end):
    """Default r' tolerance of ``step="adaptive"`` and ``auto``: 0.01 pixel of the paper's
    camera, whose :data:`PAPER_PIXELS` pixels span the field's widest transverse extent
    (for closed-form fields: the depth ``max |x_end - x1_0|``, or 1 length unit).

    Returns
    -------
    float
        Length units.
    """
    if isinstance(field, Field):
        span = float(np.max((field.grid_hi - field.grid_lo)[1:]))
    else:
        span = float(np.max(np.abs(x_end - origins[:, 0]))) or 1.0
    return 0.01 * span / PAPER_PIXELS


@dataclasses.dataclass(frozen=True)
class StepPlan:
    """The integration step of one kernel run.

    Attributes
    ----------
    step : float
        The fixed step in ``t``, or the first step if adaptive.
    adaptive : bool
    tolerance : float or None
        Adaptive: allowed r' error (length units).
    step_min, step_max : float or None
        Adaptive: bounds of the step in ``t``.
    lever : float or None
        Adaptive: lever arm of direction errors on r' (length units).
    """

    step: float
    adaptive: bool = False
    tolerance: float | None = None
    step_min: float | None = None
    step_max: float | None = None
    lever: float | None = None

    def describe(self):
        if not self.adaptive:
            return {"step_control": "fixed", "step": self.step}
        return {
            "step_control": "adaptive",
            "first_step": self.step,
            "tolerance": self.tolerance,
            "step_min": self.step_min,
            "step_max": self.step_max,
        }


def _round_to_pairs(value):
    """``value`` as the kernel sees it: the sum of its float32 (hi, lo) pair."""
    hi, lo = split_pairs([value])
    return float(join_pairs(hi, lo)[0])


def _check_step(field, step, x_end, origins, precision="f32c"):
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
        cells = step * field.n_ref / float(np.min(field.spacing))
        if cells < 1e-6:
            raise RimclError(
                f"step {step:g} is {cells:.1e} of a cell: more than a million steps per cell"
            )
    elif depth > 0 and step * field.n_ref > depth:
        raise RimclError(f"step {step:g} is larger than the distance to the exit plane")
    if precision == "f32":
        reach = float(np.max(np.abs(np.concatenate([origins.ravel(), [x_end]]))))
        if step * field.n_ref < 4 * np.finfo(np.float32).eps * reach:
            raise RimclError(
                f"step {step:g} is below the float32 resolution of positions near {reach:g}: "
                "plain f32 would not move the rays; use f32c or f64"
            )


def _long_step_warning(field, step):
    """A note when a fixed step spans more than LONG_STEP_CELLS cells of arc, else None."""
    if not isinstance(field, Field):
        return None
    cells = step * field.n_ref / float(np.min(field.spacing))
    if cells <= LONG_STEP_CELLS * (1 + 1e-6):  # allow for the rounding of the step
        return None
    return (
        f"the step spans {cells:.1f} cells of arc: features narrower than the step are "
        "skipped; check with a smaller step, step='adaptive' or step='auto'"
    )


def _default_max_steps(field, step, x_end, origins, directions):
    n_min = field.n_min if isinstance(field, Field) else 0.5 * field.n_ref
    if isinstance(field, Field):
        span = float(np.linalg.norm(field.counts * field.spacing))
    else:
        depth = float(np.max(np.abs(x_end - origins[:, 0])))
        slope = max(float(np.min(np.abs(directions[:, 0]))), 0.05)
        span = max(depth / slope, 1.0) * math.pi
    return int(min(4 * span / (step * n_min) + 64, 2**31 - 1))


def plan_steps(field, step, x_end, origins, precision="f32c", tolerance=None):
    """Resolve ``step=`` (a number, None or ``"adaptive"``) into a :class:`StepPlan`.

    Parameters
    ----------
    field : Field or AnalyticField
    step : float, None or "adaptive"
    x_end : float
    origins : ndarray, shape (N, 3)
    precision : str
    tolerance : float, optional
        Adaptive: allowed r' error (length units); default :func:`default_tolerance`.

    Returns
    -------
    StepPlan
    """
    if step == "adaptive":
        tolerance = default_tolerance(field, origins, x_end) if tolerance is None else tolerance
        tolerance = float(tolerance)
        if not (tolerance > 0 and math.isfinite(tolerance)):
            raise RimclError(f"the tolerance must be a positive length, got {tolerance}")
        first = default_step(field)
        lever = float(np.max(np.abs(x_end - origins[:, 0]))) or 1.0
        floor = TOLERANCE_FLOOR.get(precision, TOLERANCE_FLOOR["f32c"]) * lever
        if tolerance < floor:
            raise RimclError(
                f"tolerance {tolerance:.3g} is below what precision {precision} can resolve "
                f"over a depth of {lever:.4g} (about {floor:.1g}); use a larger tolerance"
                + ("" if precision == "f64" else " or precision f64")
            )
        largest = first * ADAPTIVE_STEP_RANGE[1]
        if not isinstance(field, Field):
            largest = max(largest, lever / (4 * field.n_ref))
        return StepPlan(
            step=_round_to_pairs(first),
            adaptive=True,
            tolerance=tolerance,
            step_min=_round_to_pairs(first * ADAPTIVE_STEP_RANGE[0]),
            step_max=_round_to_pairs(largest),
            lever=lever,
        )
    if isinstance(step, str):
        raise RimclError(f"step must be a number, None, 'adaptive' or 'auto', got {step!r}")
    step = default_step(field) if step is None else float(step)
    _check_step(field, step, x_end, origins, precision)
    return StepPlan(step=_round_to_pairs(step))


def _param_block(field, x_end, plan):
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
    put_pair(_P_STEP, plan.step)
    if plan.adaptive:
        put_pair(_P_STEP_MIN, plan.step_min)
        put_pair(_P_STEP_MAX, plan.step_max)
        put_pair(_P_TOL, plan.tolerance / (ADAPTIVE_SAFETY * plan.lever))
        put_pair(_P_DEPTH, plan.lever)
    return params


def kernel_defines(field, precision, interp="trilinear", adaptive=False, shape=None):
    """``-D`` defines of ``trace.cl``: field kind, interpolation, boundary, precision,
    step control and kernel shape.

    Parameters
    ----------
    field : Field or AnalyticField
    precision : {"f32", "f32c", "f64"}
    interp : {"trilinear", "texture", "bspline3"}
        Ignored for closed-form fields.
    adaptive : bool
    shape : KernelShape, optional
        Default: one ray per work-item, standard functions.

    Returns
    -------
    dict of str to int
    """
    if precision not in PRECISIONS:
        raise RimclError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if interp not in INTERPOLATIONS:
        raise RimclError(f"interp must be one of {INTERPOLATIONS}, got {interp!r}")
    shape = KernelShape() if shape is None else shape
    if isinstance(field, Field):
        kind, periodic, interp_define = 0, int(field.periodic), _INTERP_DEFINE[interp]
    elif isinstance(field, AnalyticField):
        kind, periodic, interp_define = _ANALYTIC_DEFINE[field.kind], 0, 0
    else:
        raise RimclError(f"cannot trace through a {type(field).__name__}")
    return {
        "RIMCL_PRECISION": _PRECISION_DEFINE[precision],
        "RIMCL_FIELD": kind,
        "RIMCL_INTERP": interp_define,
        "RIMCL_PERIODIC": periodic,
        "RIMCL_ADAPTIVE": int(adaptive),
        "RIMCL_LANES": shape.lanes,
        "RIMCL_POCL_FAST": int(shape.pocl_fast),
    }


def _texture_image(field, context, device):
    import pyopencl as cl

    if not device.image_support:
        raise RimclError(
            f"interp 'texture' needs OpenCL image support, which {device.name.strip()} lacks; "
            "use 'trilinear' (the same interpolation in software)"
        )
    nodes = field.packed
    if nodes.shape[0] == 1:
        # a 3-D image needs a depth of at least 2: repeat the single x3 layer
        nodes = np.concatenate([nodes, nodes], axis=0)
    n3, n2, n1 = nodes.shape[:3]
    limits = (device.image3d_max_width, device.image3d_max_height, device.image3d_max_depth)
    if n1 > limits[0] or n2 > limits[1] or n3 > limits[2]:
        raise RimclError(
            f"the field ({n1} x {n2} x {n3} nodes) exceeds the largest 3-D image of "
            f"{device.name.strip()} ({limits[0]} x {limits[1]} x {limits[2]}); use 'trilinear'"
        )
    image_format = cl.ImageFormat(cl.channel_order.RGBA, cl.channel_type.FLOAT)
    return cl.Image(
        context,
        cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
        image_format,
        shape=(n1, n2, n3),
        hostbuf=np.ascontiguousarray(nodes),
    )


def bspline_coefficients(field):
    """The field's cubic B-spline coefficients (:func:`rimcl.fields.bspline.bspline_coefficients`),
    computed once per field."""
    from rimcl.fields.bspline import bspline_coefficients as prefilter

    return field.cached("bspline3", lambda: prefilter(field.delta_n, field.periodic))


def _field_buffer(field, context, device=None, interp="trilinear"):
    """The device copy of the field for ``interp``, uploaded once per field and context."""
    import pyopencl as cl

    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    if not isinstance(field, Field):
        return cl.Buffer(context, cl.mem_flags.READ_ONLY, size=16)
    if interp == "texture":
        return field.cached(("texture", context), lambda: _texture_image(field, context, device))
    if interp == "bspline3":
        coefficients = bspline_coefficients(field)
        return field.cached(
            ("bspline3", context), lambda: cl.Buffer(context, flags, hostbuf=coefficients)
        )
    return field.cached(
        ("trilinear", context), lambda: cl.Buffer(context, flags, hostbuf=field.packed)
    )


@dataclasses.dataclass(frozen=True)
class TraceLaunch:
    """What every trace kernel takes besides its rays, resolved for one field and settings.

    Attributes
    ----------
    defines : dict
        ``-D`` defines of the trace (:func:`kernel_defines`).
    shape : KernelShape
    max_steps : int
    field_buffer : pyopencl.Buffer or pyopencl.Image
        The field on the device (uploaded once per field and context).
    counts : ndarray of int32, shape (4,)
        Grid nodes ``(n1, n2, n3, 0)``.
    params : pyopencl.Buffer
        The float parameter block (``cl/rimcl_params.h``).
    """

    defines: dict
    shape: KernelShape
    max_steps: int
    field_buffer: object
    counts: np.ndarray
    params: object


def prepare_launch(
    field,
    *,
    x_end,
    plan,
    interp,
    precision,
    device,
    origins,
    directions,
    max_steps=None,
    kernel_shape=None,
):
    """Resolve the kernel arguments shared by all rays of a trace (no rays are uploaded).

    Parameters
    ----------
    field : Field or AnalyticField
    x_end : float
    plan : StepPlan
    interp : {"trilinear", "texture", "bspline3"}
    precision : {"f32", "f32c", "f64"}
    device : pyopencl.Device
    origins, directions : ndarray, float64, shape (N, 3)
        Rays representative of the trace (they set the default ``max_steps`` of
        closed-form fields; gridded fields only need their start plane).
    max_steps : int, optional
    kernel_shape : KernelShape, optional
        Default :func:`default_kernel_shape`.

    Returns
    -------
    TraceLaunch
    """
    import pyopencl as cl

    from rimcl.core.device import context_for, has_fp64

    if precision == "f64" and not has_fp64(device):
        raise RimclError(f"precision f64 needs cl_khr_fp64, which {device.name.strip()} lacks")
    shape = (
        default_kernel_shape(device, precision, interp) if kernel_shape is None else kernel_shape
    )
    defines = kernel_defines(field, precision, interp, plan.adaptive, shape)
    if max_steps is None:
        smallest = plan.step_min if plan.adaptive else plan.step
        max_steps = _default_max_steps(field, smallest, x_end, origins, directions)
    context = context_for(device)
    counts = (
        np.array([*field.counts, 0], dtype=np.int32)
        if isinstance(field, Field)
        else np.zeros(4, dtype=np.int32)
    )
    params = cl.Buffer(
        context,
        cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
        hostbuf=_param_block(field, x_end, plan),
    )
    return TraceLaunch(
        defines=defines,
        shape=shape,
        max_steps=int(max_steps),
        field_buffer=_field_buffer(field, context, device, interp),
        counts=counts,
        params=params,
    )


def run_trace(
    field,
    origins,
    directions,
    *,
    x_end,
    plan,
    interp,
    precision,
    device,
    max_steps=None,
    batch_size=DEFAULT_BATCH,
    progress=False,
    kernel_shape=None,
):
    """Run the trace kernel with settings already resolved (no ``auto``).

    Parameters
    ----------
    field : Field or AnalyticField
    origins, directions : ndarray, float64, shape (N, 3)
        Validated rays (unit directions).
    x_end : float
    plan : StepPlan
    interp : {"trilinear", "texture", "bspline3"}
    precision : {"f32", "f32c", "f64"}
    device : pyopencl.Device
    max_steps, batch_size, progress, kernel_shape
        As :func:`rimcl.trace_rays`.

    Returns
    -------
    TraceResult
    """
    import pyopencl as cl

    from rimcl.core.device import context_for, queue_for
    from rimcl.core.program import build_program, get_kernel

    launch = prepare_launch(
        field,
        x_end=x_end,
        plan=plan,
        interp=interp,
        precision=precision,
        device=device,
        origins=origins,
        directions=directions,
        max_steps=max_steps,
        kernel_shape=kernel_shape,
    )
    shape, max_steps = launch.shape, launch.max_steps
    group = launch_group(shape, device)  # CPUs: one compiled kernel for every ray count
    context, queue = context_for(device), queue_for(device)
    kernel = get_kernel(build_program(context, "trace.cl", launch.defines), "trace_rays")
    field_buffer, counts, params = launch.field_buffer, launch.counts, launch.params

    count = origins.shape[0]
    raw_out = np.empty((count, _RAY_OUT_STRIDE), dtype=np.float32)
    info = np.empty((count, _RAY_INFO_STRIDE), dtype=np.int32)
    batch_size = max(1, min(int(batch_size), count))
    rays_in_buf = cl.Buffer(context, cl.mem_flags.READ_ONLY, size=batch_size * _RAY_IN_STRIDE * 4)
    rays_out_buf = cl.Buffer(
        context, cl.mem_flags.WRITE_ONLY, size=batch_size * _RAY_OUT_STRIDE * 4
    )
    info_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, size=batch_size * _RAY_INFO_STRIDE * 4)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=count, unit="ray", desc="trace", leave=False, disable=None)
    kernel_seconds = 0.0
    try:
        for start in range(0, count, batch_size):
            stop = min(start + batch_size, count)
            rays_in = np.empty((stop - start, _RAY_IN_STRIDE), dtype=np.float32)
            rays_in[:, 0:3], rays_in[:, 3:6] = split_pairs(origins[start:stop])
            rays_in[:, 6:9], rays_in[:, 9:12] = split_pairs(directions[start:stop])
            cl.enqueue_copy(queue, rays_in_buf, rays_in, is_blocking=True)
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
            work_items = -(-(stop - start) // shape.lanes)
            local = None
            if group is not None:  # surplus work-items return at once (n_rays)
                work_items = -(-work_items // group) * group
                local = (group,)
            launched = time.perf_counter()
            cl.enqueue_nd_range_kernel(queue, kernel, (work_items,), local)
            queue.finish()
            kernel_seconds += time.perf_counter() - launched
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
        "step": plan.step,
        **plan.describe(),
        "interp": interp if isinstance(field, Field) else "analytic",
        "precision": precision,
        "max_steps": int(max_steps),
        "rays_per_work_item": shape.lanes,
        "kernel_shape": {**shape.describe(), "group": group},
        "field": field.describe(),
        "sharma_steps": int(info[:, 3].sum(dtype=np.int64)),
        "kernel_seconds": kernel_seconds,
    }
    if plan.adaptive:
        config["rejected_steps"] = int(info[:, 2].sum(dtype=np.int64))
    else:
        warning = _long_step_warning(field, plan.step)
        if warning is not None:
            config["warnings"] = [warning]
            logger.warning(warning)
    result = _finish(origins, directions, raw_out, info, plan.step, config)
    if plan.adaptive:
        ok = result.ok
        steps = int(result.steps[ok].sum())
        travel = float(np.sum(result.path_length[ok])) / field.n_ref
        config["mean_step"] = travel / steps if steps else None
    return result


def _finish(origins, directions, raw_out, info, step, config):
    end_pos = join_pairs(raw_out[:, 0:3], raw_out[:, 3:6])
    end_t = join_pairs(raw_out[:, 6:9], raw_out[:, 9:12])
    status = info[:, 1].astype(np.int8)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        exit_index = np.linalg.norm(end_t, axis=1)  # |T| = n sampled at the exit point
        end_dir = end_t / exit_index[:, None]
        distance = (end_pos[:, 0] - origins[:, 0]) / end_dir[:, 0]
        image_pos = end_pos - distance[:, None] * end_dir
        image_pos[:, 0] = origins[:, 0]
        path_length = raw_out[:, 12].astype(np.float64)
        optical_path = raw_out[:, 13].astype(np.float64)
        n_metric = raw_out[:, 14:17].astype(np.float64) / path_length[:, None]
        deflection = angle_between(directions, end_dir)
        deflection_angles = direction_angles(end_dir) - direction_angles(directions)
    # a ray that reached the exit plane with outputs that overflowed (an absurd grid
    # spacing, say) is not a measurement: it counts as non_finite, never as ok
    finite = np.all(np.isfinite(np.hstack([image_pos, end_pos, end_dir, deflection_angles])), 1)
    finite &= np.isfinite(deflection) & np.isfinite(path_length) & np.isfinite(optical_path)
    finite &= np.all(np.isfinite(n_metric), axis=1) | (path_length == 0)
    status[(status == 0) & ~finite] = STATUS_NAMES.index("non_finite")
    image_pos[status != 0] = np.nan
    return TraceResult(
        origins=origins,
        directions=directions,
        image_pos=image_pos,
        end_pos=end_pos,
        end_dir=end_dir,
        deflection=deflection,
        deflection_angles=deflection_angles,
        path_length=path_length,
        optical_path=optical_path,
        n_metric=n_metric,
        exit_index=exit_index,
        steps=info[:, 0].astype(np.int64),
        status=status,
        step=step,
        config=config,
    )

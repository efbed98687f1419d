"""The public tracer, :func:`trace_rays`: its ``auto`` choices calibrated, then traced.

``interp="auto"`` and ``step="auto"`` are resolved on a subset of the rays by
:mod:`rimcl.optics.auto_choice`; the rays are then traced by
:func:`rimcl.optics.trace.run_trace` with the settings chosen (so the tracer itself never
imports the calibration that drives it).
"""

from rimcl.core.errors import RimclError
from rimcl.optics.auto_choice import calibrate
from rimcl.optics.trace import (
    DEFAULT_BATCH,
    INTERP_CHOICES,
    STEP_KEYWORDS,
    _validate_rays,
    plan_steps,
    run_trace,
)
from rimcl.optics.tuning import tuned_entry


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
    tolerance=None,
    kernel_shape=None,
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
    step : float, None, "adaptive" or "auto"
        A number: the paper's Δζ, a fixed step in ``t`` (``dt = ds/n``, so ``n·step`` of
        arc). None: half a cell of arc (:func:`rimcl.optics.trace.default_step`).
        ``"adaptive"``: step doubling, each step sized so that the estimated r' error stays within
        ``tolerance`` over the path (``TraceResult.steps`` counts the accepted steps).
        ``"auto"``: the largest fixed step whose r' error, calibrated on a subset of the
        rays against a 4 times smaller step, is within ``tolerance``
        (:mod:`rimcl.optics.auto_choice`).
    interp : {"trilinear", "texture", "bspline3", "auto"}
        Interpolation of gridded fields (ignored for closed forms): ``trilinear`` nodes
        ``δn, ∇n``; ``texture``, the same nodes filtered by the device's image hardware
        (needs image support); ``bspline3``, a cubic B-spline of ``δn`` and its exact
        gradient; ``auto``, the cheapest whose calibrated r' error is within
        ``tolerance``.
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
    tolerance : float, optional
        For ``step="adaptive"`` and ``auto``: the allowed error of the image points r'
        (length units; convert from pixels with the camera's pixel size). Default:
        :func:`rimcl.optics.trace.default_tolerance`, 0.01 pixel of the paper's camera.
    kernel_shape : rimcl.optics.shapes.KernelShape, optional
        Rays per work-item and the PoCL switch; default
        :func:`rimcl.optics.shapes.default_kernel_shape`.
        For benchmarks; results do not depend on it.

    Returns
    -------
    TraceResult
        ``config`` records the settings used, the work (``sharma_steps``: Sharma steps
        evaluated, Newton and rejected steps included) and ``kernel_seconds`` (time in
        the kernel; uploads, downloads and host work excluded), and for ``auto`` the
        calibration (``config["auto"]``: the choice, its estimated error and every
        candidate).
    """
    from rimcl.core.device import select_device

    if interp not in INTERP_CHOICES:
        raise RimclError(f"interp must be one of {INTERP_CHOICES}, got {interp!r}")
    if isinstance(step, str) and step not in STEP_KEYWORDS:
        raise RimclError(f"step must be a number, None, 'adaptive' or 'auto', got {step!r}")
    origins, directions = _validate_rays(origins, directions)
    x_end = float(x_end)
    device = select_device(device)
    if kernel_shape is None:
        tuned_entry(device)  # the device's kernel shapes, measured once on first use
    calibration = None
    if interp == "auto" or step == "auto":
        calibration = calibrate(
            field,
            origins,
            directions,
            x_end=x_end,
            interp=interp,
            step=step,
            precision=precision,
            device=device,
            tolerance=tolerance,
            kernel_shape=kernel_shape,
        )
        interp, step = calibration["interp"], calibration["step"]
    result = run_trace(
        field,
        origins,
        directions,
        x_end=x_end,
        plan=plan_steps(field, step, x_end, origins, precision, tolerance),
        interp=interp,
        precision=precision,
        device=device,
        max_steps=max_steps,
        batch_size=batch_size,
        progress=progress,
        kernel_shape=kernel_shape,
    )
    if calibration is not None:
        result.config["auto"] = calibration
    return result

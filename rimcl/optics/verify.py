"""The verification suite: closed-form rays, analytic and gridded.

Every case traces a small fan of rays through a field whose rays are known exactly, in
the kernel's precision modes, and compares the end points (or, in a uniform medium,
the back-projected image points) with the exact ones. The suite also measures the
order of convergence of the float64 integrator and the drift of plain float32.
"""

import dataclasses

import numpy as np

from rimcl.core.device import has_fp64, select_device
from rimcl.fields.field import analytic_field
from rimcl.optics.tracing import trace_rays


def exact_uniform(origins, directions, x_end):
    """Exit points of straight rays (any uniform index), shape (N, 3)."""
    travel = (x_end - origins[:, 0]) / directions[:, 0]
    return origins + travel[:, None] * directions


def exact_grin(field, origins, directions, x_end):
    """Exit points in the GRIN rod ``n² = n0² (1 - α² x2²)``, shape (N, 3).

    In ``t`` the motion is harmonic: ``T1, T3`` constant, ``x2'' = -(n0 α)² x2``. This is
    the exact ray, not the paper's paraxial matrix.
    """
    n0, alpha = field.params["n0"], field.params["alpha"]
    tangent = field.refractive_index(origins)[:, None] * directions
    t_end = (x_end - origins[:, 0]) / tangent[:, 0]
    omega = n0 * alpha
    end = np.empty_like(origins)
    end[:, 0] = x_end
    end[:, 1] = origins[:, 1] * np.cos(omega * t_end) + tangent[:, 1] / omega * np.sin(
        omega * t_end
    )
    end[:, 2] = origins[:, 2] + tangent[:, 2] * t_end
    return end


def exact_linear(field, origins, directions, x_end):
    """Exit points in the linear medium ``n = n0 + g x2``, shape (N, 3).

    With ``y = n0 + g x2``, ``y'' = g² y`` in ``t``: ``y = y0 cosh(g t) + T2 sinh(g t)``.
    """
    n0, g = field.params["n0"], field.params["g"]
    tangent = field.refractive_index(origins)[:, None] * directions
    t_end = (x_end - origins[:, 0]) / tangent[:, 0]
    y0 = n0 + g * origins[:, 1]
    y = y0 * np.cosh(g * t_end) + tangent[:, 1] * np.sinh(g * t_end)
    end = np.empty_like(origins)
    end[:, 0] = x_end
    end[:, 1] = (y - n0) / g
    end[:, 2] = origins[:, 2] + tangent[:, 2] * t_end
    return end


def exact_fisheye(origins):
    """Exit points of fish-eye rays from ``(0, -1, x3)``: all arrive at ``(0, 1, x3)``."""
    end = origins.copy()
    end[:, 1] = 1.0
    return end


def _fan(count, spread, rng):
    """Unit directions within ``spread`` rad of +x1 in x2 and x3."""
    angles = rng.uniform(-spread, spread, size=(count, 2))
    directions = np.column_stack([np.ones(count), np.tan(angles[:, 0]), np.tan(angles[:, 1])])
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


@dataclasses.dataclass
class Case:
    """One verification setup: a field, rays, the exit plane and the exact answer."""

    name: str
    field: object
    origins: np.ndarray
    directions: np.ndarray
    x_end: float
    length: float
    exact: np.ndarray
    compare: str  # "end" (exit points) or "image" (back-projected points)
    grid: str = "-"


def _cases(rays):
    rng = np.random.default_rng(1982)
    cases = []

    uniform = analytic_field("uniform", n0=1.33)
    origins = np.column_stack([np.zeros(rays), rng.uniform(0.5, 2.5, (rays, 2))])
    directions = _fan(rays, 0.9, rng)
    cases.append(
        Case("uniform", uniform, origins, directions, np.pi, np.pi, origins.copy(), "image")
    )

    grin = analytic_field("grin", n0=1.5, alpha=0.5)
    origins = np.column_stack([np.zeros(rays), rng.uniform(-0.5, 0.5, rays), np.zeros(rays)])
    directions = _fan(rays, 0.5, rng)
    exact = exact_grin(grin, origins, directions, np.pi)
    cases.append(Case("grin a=0.5 L=pi", grin, origins, directions, np.pi, np.pi, exact, "end"))

    grin_paper = analytic_field("grin", n0=1.5, alpha=0.01)
    origins = np.column_stack([np.zeros(rays), rng.uniform(-1, 1, rays), np.zeros(rays)])
    directions = _fan(rays, 0.02, rng)
    exact = exact_grin(grin_paper, origins, directions, 100.0)
    cases.append(
        Case("grin a=0.01 L=100", grin_paper, origins, directions, 100.0, 100.0, exact, "end")
    )

    fisheye = analytic_field("fisheye", n_max=2.0)
    theta = np.linspace(np.pi / 3, 2 * np.pi / 3, rays)
    origins = np.column_stack([np.zeros(rays), -np.ones(rays), np.zeros(rays)])
    directions = np.column_stack([np.sin(theta), np.cos(theta), np.zeros(rays)])
    cases.append(
        Case("fisheye", fisheye, origins, directions, 0.0, 2.0, exact_fisheye(origins), "end")
    )

    linear = analytic_field("linear", n0=1.33, g=0.05)
    origins = np.column_stack([np.zeros(rays), rng.uniform(-1, 1, (rays, 2))])
    directions = _fan(rays, 0.6, rng)
    exact = exact_linear(linear, origins, directions, np.pi)
    cases.append(Case("linear g=0.05", linear, origins, directions, np.pi, np.pi, exact, "end"))
    return cases


def _gridded_cases(analytic_cases):
    """The same rays through the closed forms sampled on grids (trilinear)."""
    by_name = {case.name: case for case in analytic_cases}
    grids = {
        "uniform": ((33, 33, 33), (0.0, -4.0, -4.0), (np.pi, 7.0, 7.0)),
        "grin a=0.5 L=pi": ((257, 257, 3), (0.0, -1.9, -2.0), (np.pi, 1.9, 2.0)),
        "linear g=0.05": ((33, 65, 65), (0.0, -5.0, -5.0), (np.pi, 5.0, 5.0)),
    }
    gridded = []
    for name, (counts, lo, hi) in grids.items():
        case = by_name[name]
        field = case.field.on_grid(counts, lo, hi)
        gridded.append(dataclasses.replace(case, field=field, grid="x".join(map(str, counts))))
    # the lens-only 512² grid holds the rays with θ0 in [π/3, π/2]
    fish = by_name["fisheye"]
    keep = np.arctan2(fish.directions[:, 0], fish.directions[:, 1]) <= np.pi / 2 + 1e-12
    field = fish.field.on_grid((512, 512, 1), (-0.05, -1.05, 0.0), (1.05, 1.05, 0.0), n_ref=1.0)
    gridded.append(
        dataclasses.replace(
            fish,
            field=field,
            origins=fish.origins[keep],
            directions=fish.directions[keep],
            exact=fish.exact[keep],
            grid="512x512",
        )
    )
    return gridded


# tolerance on the max error (length units) per precision; None: relative to L
TOLERANCE = {"f64": 1e-9, "f32c": 1e-6}
GRID_TOLERANCE = {"uniform": 1e-6, "grin a=0.5 L=pi": 2e-5, "linear g=0.05": 1e-6, "fisheye": 1e-5}
ANALYTIC_STEP = 1e-3
UNIFORM_STEP = 1e-4


def _trace(case, step, precision, device):
    return trace_rays(
        case.field,
        case.origins,
        case.directions,
        x_end=case.x_end,
        step=step,
        precision=precision,
        device=device,
    )


def _error(case, result):
    got = result.image_pos if case.compare == "image" else result.end_pos
    distance = np.linalg.norm(got - case.exact, axis=1)
    return float(np.max(np.where(result.ok, distance, np.inf)))


def run_verification(device=None, rays=16, precisions=None, progress=None):
    """Run the whole suite.

    Parameters
    ----------
    device : str or pyopencl.Device, optional
    rays : int
        Rays per case.
    precisions : sequence of str, optional
        Default: ``f32c`` and, where the device has ``cl_khr_fp64``, ``f64``.
    progress : callable, optional
        Called with each finished row (for live printing).

    Returns
    -------
    dict
        ``rows`` (case, interpolation, precision, step, grid, max error, tolerance, pass),
        ``convergence`` (float64 errors and ratios as the step halves), ``f32_drift``
        (plain float32 in a uniform medium, information only), ``passed`` and ``device``.
    """
    device = select_device(device)
    if precisions is None:
        precisions = ["f32c", "f64"] if has_fp64(device) else ["f32c"]
    analytic = _cases(rays)
    rows = []

    def run(case, precision, step, interpolation, tolerance):
        result = _trace(case, step, precision, device)
        error = _error(case, result)
        row = {
            "case": case.name,
            "interpolation": interpolation,
            "precision": precision,
            "step": result.step,
            "grid": case.grid,
            "max_error": error,
            "tolerance": tolerance,
            "passed": bool(error <= tolerance),
            "rays_not_ok": int(np.count_nonzero(~result.ok)),
        }
        rows.append(row)
        if progress is not None:
            progress(row)

    for case in analytic:
        step = UNIFORM_STEP if case.name == "uniform" else ANALYTIC_STEP
        for precision in precisions:
            tolerance = TOLERANCE[precision] * (case.length if precision == "f32c" else 1.0)
            run(case, precision, step, "analytic", tolerance)
    for case in _gridded_cases(analytic):
        for precision in precisions:
            run(case, precision, None, "trilinear", GRID_TOLERANCE[case.name])

    convergence = _convergence(analytic[1], device, precisions)
    drift = _f32_drift(analytic[0], device)
    return {
        "device": device.name.strip(),
        "rows": rows,
        "convergence": convergence,
        "f32_drift": drift,
        "passed": all(row["passed"] for row in rows) and convergence["passed"],
    }


def _convergence(case, device, precisions):
    """Float64 (else f32c) errors on the strong GRIN rod as the step halves."""
    precision = "f64" if "f64" in precisions else "f32c"
    steps = [0.08, 0.04, 0.02, 0.01]
    errors = []
    for step in steps:
        result = _trace(case, step, precision, device)
        errors.append(_error(case, result))
    ratios = [errors[i] / errors[i + 1] for i in range(len(errors) - 1)]
    return {
        "case": case.name,
        "precision": precision,
        "steps": steps,
        "errors": errors,
        "ratios": ratios,
        "required_ratio": 12.0,
        "passed": bool(precision != "f64" or min(ratios) >= 12.0),
    }


def _f32_drift(case, device):
    """Back-projection error of plain float32 vs f32c in a uniform medium (~3e4 steps)."""
    found = {}
    for precision in ("f32", "f32c"):
        result = _trace(case, UNIFORM_STEP, precision, device)
        found[precision] = _error(case, result)
    return {"step": UNIFORM_STEP, "length": case.length, **found}

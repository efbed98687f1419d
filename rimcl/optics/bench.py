"""``rimcl bench``: speed against accuracy of the tracing methods.

On a field (default: the shipped sample, as air ``C1`` and water ``C4``) and a ray set
(the paper's camera: tracers in the sheet, an ``M x M`` fan of rays each), every
combination of interpolation × precision × step is traced, warm (kernel build and field
upload excluded), and compared with two references:

- ``ref``: ``bspline3`` in float64 at a fine step (a sixteenth of the default step) --
  the best answer rimcl can give, so this error includes the interpolation error;
- ``fine``: the same interpolation in float64 at the fine step -- the error of the step
  and precision alone.

Errors are the largest ``|r' - r'_ref|`` over the rays that both trace to the exit plane,
in units of ``L`` (the field of view) and of pixels of the camera (``L / pixels``).
Rows are marked where a method fails: ``f32 drift`` (plain float32 more than 10 times
worse than ``f32c`` at the same setting), ``step error > tolerance`` (the step alone costs
more than the tolerance, 0.01 pixel), ``rays lost`` (rays the reference traces to the exit
plane that the setting does not), and the counts of ``turned_back`` and ``exit_side`` rays
(water bends rays back).

Outputs in the output directory: ``bench.csv`` (one row per setting; ``#`` comment lines
hold the configuration, versions and device), ``bench.json`` (the same, machine-readable)
and ``bench.png`` (error against cost, one panel per case, Pareto front drawn).
"""

import contextlib
import dataclasses
import logging
import math
import time
from pathlib import Path

import numpy as np

from rimcl import __version__
from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.provenance import to_json, versions
from rimcl.fields.field import Field
from rimcl.optics.trace import (
    INTERPOLATIONS,
    PAPER_PIXELS,
    PRECISIONS,
    STATUS_NAMES,
    default_step,
    plan_steps,
    run_trace,
)

#: The Gladstone–Dale cases benchmarked by default: air and water.
DEFAULT_CASES = ("C1", "C4")
#: The one case of a field file that stores δn (its own refractive index).
DELTA_N_CASE = "delta_n"
#: Step factors (times the default step, half a cell of arc), full and quick sweeps.
STEP_FACTORS = (8.0, 4.0, 2.0, 1.0, 0.5, 0.25)
QUICK_STEP_FACTORS = (4.0, 1.0, 0.25)
#: Adaptive-step tolerances in pixels of the camera, full and quick sweeps.
ADAPTIVE_PIXELS = (1.0, 0.1, 0.01)
QUICK_ADAPTIVE_PIXELS = (0.1,)
#: Reference step as a fraction of the default step: 4 times below the smallest step
#: swept, so that its own step error is 256 times below that step's.
REFERENCE_FRACTION = 1 / 16
#: Tracers and fan size (rays per tracer = fan²), full and quick.
RAY_SET = (30, 32)
QUICK_RAY_SET = (8, 16)
#: Timed runs per setting (the fastest counts), full and quick.
REPEATS = 3
QUICK_REPEATS = 1
#: f32 is marked as drifting when its error exceeds f32c's at the same setting this much.
F32_DRIFT_FACTOR = 10.0
#: The tolerance of the ``step error`` mark, in pixels.
TOLERANCE_PIXELS = 0.01
#: Notes that mark a failing method.
FAIL_F32_DRIFT = "f32 drift"
FAIL_STEP = "step error > tolerance"
FAIL_LOST = "rays lost"

CSV_COLUMNS = (
    "case",
    "k_rho",
    "interp",
    "precision",
    "step_control",
    "step",
    "step_cells",
    "tolerance",
    "rays",
    *(f"rays_{name}" for name in STATUS_NAMES),
    "rays_lost",
    "steps_per_ray",
    "sharma_steps_per_ray",
    "seconds",
    "ray_steps_per_s",
    "us_per_ray",
    "kernel_seconds",
    "kernel_ray_steps_per_s",
    "kernel_us_per_ray",
    "err_ref_max_L",
    "err_ref_median_L",
    "err_ref_max_px",
    "err_fine_max_L",
    "err_fine_max_px",
    "notes",
)


@dataclasses.dataclass
class BenchCase:
    """One field and ray set of the benchmark.

    Attributes
    ----------
    name : str
        Case name (``C1``, ``C4``, ``G=...``, or ``delta_n`` for a file of δn).
    k_rho : float or None
        Gladstone–Dale product of the case; None for a file of δn.
    field : Field
    origins, directions : ndarray, shape (N, 3)
    x_end : float
        Exit plane.
    length : float
        ``L``, the width of the field of view (length units).
    pixel : float
        Pixel size of the camera (length units).
    """

    name: str
    k_rho: float
    field: Field
    origins: np.ndarray
    directions: np.ndarray
    x_end: float
    length: float
    pixel: float


def synthetic_density(size=64, seed=0):
    """A smooth random periodic density on ``size³`` nodes (box 2π), the stand-in for the
    shipped sample: 12 random Fourier modes of wavenumber up to 4, scaled to the density
    range of the mixing flow, light fluid 1 to heavy 1.105 (Atwood number 0.05).

    Returns
    -------
    ndarray, float64, shape (size, size, size)
    """
    rng = np.random.default_rng(seed)
    x = 2 * np.pi * np.arange(size) / size
    x3, x2, x1 = np.meshgrid(x, x, x, indexing="ij")
    values = np.zeros((size, size, size))
    for _ in range(12):
        k = rng.integers(-4, 5, size=3)
        phase = rng.uniform(0, 2 * np.pi)
        values += np.cos(k[0] * x1 + k[1] * x2 + k[2] * x3 + phase) / (1.0 + np.sum(k**2))
    return 1.0 + 0.105 * (values - values.min()) / np.ptp(values)


def bench_cases(field_path=None, cases=DEFAULT_CASES, quick=False, pixels=PAPER_PIXELS, seed=0):
    """The fields and ray sets of the benchmark.

    Parameters
    ----------
    field_path : str or Path, optional
        A rimcl field file (frame 0 is used); default the shipped sample, or a synthetic
        smooth random field where the sample is missing.
    cases : sequence of str
        Gladstone–Dale cases (``C0`` … ``C4``) to apply to the density.
    quick : bool
        The small ray set.
    pixels : int
        Pixels of the camera across ``L``.
    seed : int
        Tracer positions.

    Returns
    -------
    list of BenchCase
    """
    from rimcl.fields.cases import resolve_k_rho
    from rimcl.fields.field_reader import field_kind
    from rimcl.optics.rays import fan_rays, scene_for

    if int(pixels) < 1:
        raise RimclError(f"the camera needs at least one pixel, got {pixels}")
    tracers, fan = QUICK_RAY_SET if quick else RAY_SET
    found = []
    if field_path is not None and field_kind(field_path) == "delta_n":
        # the file carries its own refractive index: one case, whatever the cases say
        resolved = [(DELTA_N_CASE, None)]
    else:
        resolved = [resolve_k_rho(case=case) for case in cases]
    for name, k_rho in resolved:
        field = _load(field_path, k_rho)
        scene = scene_for(field)
        origins, directions, _ = fan_rays(scene, tracers, fan, seed)
        length = float(np.max(scene.fov_size))
        found.append(
            BenchCase(name, k_rho, field, origins, directions, scene.x_end, length, length / pixels)
        )
    return found


def _load(field_path, k_rho):
    """The field of a case: the file's frame 0, the shipped sample, or (no sample) a
    synthetic density with the sample's range."""
    from rimcl.fields.field_loading import load_field

    if field_path is not None:
        return load_field(field_path, 0, k_rho=k_rho)  # k_rho None: the file's own δn
    try:
        return load_field(None, 0, k_rho=k_rho)
    except RimclError:
        density = synthetic_density()
        values = k_rho * density
        spacing = 2 * np.pi / density.shape[0]
        return Field.from_arrays(
            values - values.mean(),
            spacing=(spacing,) * 3,
            n_ref=1.0 + float(values.mean()),
            boundary="periodic",
            attrs={"source": "synthetic smooth random density (the sample is missing)"},
        )


def _settings(device, quick, interps, precisions):
    from rimcl.core.device import has_fp64

    interps = list(INTERPOLATIONS if interps is None else interps)
    if "texture" in interps and not device.image_support:
        interps.remove("texture")
    precisions = list(PRECISIONS if precisions is None else precisions)
    if "f64" in precisions and not has_fp64(device):
        precisions.remove("f64")
    for name in interps:
        if name not in INTERPOLATIONS:
            raise RimclError(f"interp must be among {INTERPOLATIONS}, got {name!r}")
    for name in precisions:
        if name not in PRECISIONS:
            raise RimclError(f"precision must be among {PRECISIONS}, got {name!r}")
    if not interps or not precisions:
        raise RimclError("nothing to benchmark on this device")
    steps = QUICK_STEP_FACTORS if quick else STEP_FACTORS
    adaptive = QUICK_ADAPTIVE_PIXELS if quick else ADAPTIVE_PIXELS
    return interps, precisions, steps, adaptive


def _trace(case, plan, interp, precision, device, kernel_shape, rays=slice(None)):
    return run_trace(
        case.field,
        case.origins[rays],
        case.directions[rays],
        x_end=case.x_end,
        plan=plan,
        interp=interp,
        precision=precision,
        device=device,
        kernel_shape=kernel_shape,
    )


def _timed(case, plan, interp, precision, device, repeats, kernel_shape):
    """The result of the fastest of ``repeats`` warm runs and its wall time (seconds)."""
    # warm up with the whole ray set: PoCL specialises kernels for the launch size
    _trace(case, plan, interp, precision, device, kernel_shape)
    best, fastest = math.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        result = _trace(case, plan, interp, precision, device, kernel_shape)
        seconds = time.perf_counter() - start
        if seconds < best:
            best, fastest = seconds, result
    return fastest, best


def _errors(result, reference):
    both = result.ok & reference.ok
    if not np.any(both):
        return math.inf, math.inf
    distance = np.linalg.norm(result.image_pos[both] - reference.image_pos[both], axis=1)
    return float(np.max(distance)), float(np.median(distance))


@contextlib.contextmanager
def _long_steps_expected():
    """Silence the tracer's note on long steps: the sweep takes them on purpose and marks
    their error itself."""
    logger = logging.getLogger("rimcl.optics.trace")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def run_bench(
    cases,
    *,
    device=None,
    quick=False,
    interps=None,
    precisions=None,
    kernel_shape=None,
    progress=None,
):
    """Trace every setting of the sweep on every case and measure speed and error.

    Parameters
    ----------
    cases : list of BenchCase
    device : str or pyopencl.Device, optional
    quick : bool
        The short sweep (3 steps, 1 adaptive tolerance, 1 timed run).
    interps, precisions : sequence of str, optional
        Restrict the sweep (default: all the device supports).
    kernel_shape : rimcl.optics.shapes.KernelShape, optional
    progress : callable, optional
        Called with each finished row.

    Returns
    -------
    rows : list of dict
        One per setting and case, keys :data:`CSV_COLUMNS`.
    meta : dict
        Device, references, sweep.
    """
    from rimcl.core.device import describe_device, has_fp64, select_device

    device = select_device(device)
    interps, precisions, step_factors, adaptive_pixels = _settings(
        device, quick, interps, precisions
    )
    reference_precision = "f64" if has_fp64(device) else "f32c"
    fraction = REFERENCE_FRACTION
    repeats = QUICK_REPEATS if quick else REPEATS
    sweep = _Sweep(
        interps=interps,
        precisions=precisions,
        step_factors=step_factors,
        adaptive_pixels=adaptive_pixels,
        reference_precision=reference_precision,
        reference_fraction=fraction,
        repeats=repeats,
        device=device,
        kernel_shape=kernel_shape,
    )
    rows = []
    with _long_steps_expected():
        for case in cases:
            rows.extend(_bench_case(case, sweep, progress))
    mark_failures(rows)
    meta = {
        "device": describe_device(device),
        "quick": bool(quick),
        "references": {
            "ref": f"bspline3, {reference_precision}, step = default x {fraction:g}",
            "fine": f"same interpolation, {reference_precision}, step = default x {fraction:g}",
        },
        "step_factors": list(step_factors),
        "adaptive_tolerance_pixels": list(adaptive_pixels),
        "repeats": repeats,
        "cases": [
            {
                "name": case.name,
                "k_rho": case.k_rho,
                "field": case.field.describe(),
                "rays": len(case.origins),
                "x_end": case.x_end,
                "L": case.length,
                "pixel": case.pixel,
                "default_step": default_step(case.field),
            }
            for case in cases
        ],
    }
    return rows, meta


@dataclasses.dataclass(frozen=True)
class _Sweep:
    """The settings swept on every case, and how they are measured."""

    interps: list
    precisions: list
    step_factors: tuple
    adaptive_pixels: tuple
    reference_precision: str
    reference_fraction: float
    repeats: int
    device: object
    kernel_shape: object


def _bench_case(case, sweep, progress):
    """The rows of one case: references first, then every setting."""
    field = case.field

    def plan(step, tolerance=None):
        return plan_steps(field, step, case.x_end, case.origins, "f32c", tolerance=tolerance)

    fine_plan = plan(default_step(field) * sweep.reference_fraction)
    fine = {
        interp: _trace(
            case, fine_plan, interp, sweep.reference_precision, sweep.device, sweep.kernel_shape
        )
        for interp in dict.fromkeys(["bspline3", *sweep.interps])
    }
    plans = [("fixed", plan(default_step(field) * factor)) for factor in sweep.step_factors]
    plans += [("adaptive", plan("adaptive", p * case.pixel)) for p in sweep.adaptive_pixels]
    rows = []
    for interp in sweep.interps:
        for control, step_plan in plans:
            # adaptive steps are charted in the default precision only
            for precision in sweep.precisions if control == "fixed" else ["f32c"]:
                result, seconds = _timed(
                    case,
                    step_plan,
                    interp,
                    precision,
                    sweep.device,
                    sweep.repeats,
                    sweep.kernel_shape,
                )
                row = _row(case, interp, precision, control, step_plan, result, seconds, fine)
                rows.append(row)
                if progress is not None:
                    progress(row)
    return rows


def _row(case, interp, precision, control, plan, result, seconds, fine):
    field = case.field
    counts = result.counts
    ref_max, ref_median = _errors(result, fine["bspline3"])
    fine_max, _ = _errors(result, fine[interp])
    steps = int(result.steps.sum())
    kernel = result.config["kernel_seconds"]
    lost = int(np.count_nonzero(fine["bspline3"].ok & ~result.ok))
    return {
        "case": case.name,
        "k_rho": case.k_rho,
        "interp": interp,
        "precision": precision,
        "step_control": control,
        "step": plan.step if control == "fixed" else result.config["mean_step"],
        "step_cells": (plan.step if control == "fixed" else result.config["mean_step"] or 0.0)
        * field.n_ref
        / float(np.min(field.spacing)),
        "tolerance": plan.tolerance if control == "adaptive" else None,
        "rays": len(result),
        **{f"rays_{name}": counts[name] for name in STATUS_NAMES},
        "rays_lost": lost,
        "steps_per_ray": steps / len(result),
        "sharma_steps_per_ray": result.config["sharma_steps"] / len(result),
        "seconds": seconds,
        "ray_steps_per_s": steps / seconds,
        "us_per_ray": 1e6 * seconds / len(result),
        "kernel_seconds": kernel,
        "kernel_ray_steps_per_s": steps / kernel,
        "kernel_us_per_ray": 1e6 * kernel / len(result),
        "err_ref_max_L": ref_max / case.length,
        "err_ref_median_L": ref_median / case.length,
        "err_ref_max_px": ref_max / case.pixel,
        "err_fine_max_L": fine_max / case.length,
        "err_fine_max_px": fine_max / case.pixel,
        "notes": "",
    }


def mark_failures(rows):
    """Fill each row's ``notes`` with the ways its method fails (see the module text), and
    the counts of rays that did not reach the exit plane."""
    by_key = {
        (r["case"], r["interp"], r["precision"], r["step_control"], r["step"]): r for r in rows
    }
    for row in rows:
        notes = []
        if row["precision"] == "f32":
            twin = by_key.get((row["case"], row["interp"], "f32c", "fixed", row["step"]))
            if twin is not None and row["err_fine_max_px"] > F32_DRIFT_FACTOR * max(
                twin["err_fine_max_px"], 1e-300
            ):
                notes.append(FAIL_F32_DRIFT)
        if row["step_control"] == "fixed" and row["err_fine_max_px"] > TOLERANCE_PIXELS:
            notes.append(FAIL_STEP)
        if row["rays_lost"]:
            notes.append(f"{row['rays_lost']} {FAIL_LOST}")
        for name in STATUS_NAMES[1:]:
            if row[f"rays_{name}"]:
                notes.append(f"{row[f'rays_{name}']} {name.replace('_', ' ')}")
        row["notes"] = "; ".join(notes)


def write_csv(path, rows, meta):
    """Write the rows as CSV with ``#`` comment lines holding configuration, versions and
    device (read with ``pandas.read_csv(path, comment="#")``). :func:`bench` makes the
    three outputs atomic together."""
    with open(path, "w", encoding="utf-8") as out:
        out.write("# rimcl bench: speed against accuracy of the tracing methods\n")
        out.write(f"# config: {to_json({k: v for k, v in meta.items() if k != 'device'})}\n")
        out.write(f"# device: {to_json(meta['device'])}\n")
        out.write(f"# versions: {to_json(versions())}\n")
        out.write(",".join(CSV_COLUMNS) + "\n")
        for row in rows:
            out.write(",".join(_cell(row[name]) for name in CSV_COLUMNS) + "\n")


def _cell(value):
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    text = str(value)
    return f'"{text}"' if "," in text or ";" in text else text


def write_json(path, rows, meta):
    """The rows and the configuration as one JSON document."""
    Path(path).write_text(
        to_json({"meta": meta, "versions": versions(), "rows": rows}), encoding="utf-8"
    )


_COLORS = {"trilinear": "#1f77b4", "texture": "#2ca02c", "bspline3": "#d62728"}
_MARKERS = {"f32": "v", "f32c": "o", "f64": "s"}


def _pareto(points):
    """Indices of the points (cost, error) that no other point beats in both, by cost."""
    order = sorted(range(len(points)), key=lambda i: points[i])
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def _reference_counts(rows, name):
    """Rays of case ``name`` that do not reach the exit plane with the best setting."""
    best = min(
        (r for r in rows if r["case"] == name and r["precision"] != "f32"),
        key=lambda r: r["err_ref_max_L"],
    )
    counts = [
        f"{best[f'rays_{s}']} {s.replace('_', ' ')}" for s in STATUS_NAMES[1:] if best[f"rays_{s}"]
    ]
    return ", ".join(counts) or "all rays reach the exit plane"


def plot_pareto(path, rows, meta):
    """Error of r' against cost (kernel µs per ray), one panel per case, on the Agg canvas.

    Colour: interpolation; marker: precision; hollow: adaptive step; black ring: the step
    alone errs by more than the tolerance; red cross: f32 drift; "-k": rays lost.
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    cases = list(dict.fromkeys(row["case"] for row in rows))
    infos = {info["name"]: info for info in meta["cases"]}
    figure = Figure(figsize=(6.6 * len(cases), 6.0), layout="constrained")
    axes = figure.subplots(1, len(cases), squeeze=False)[0]
    for ax, name in zip(axes, cases, strict=True):
        info = infos[name]
        chosen = [r for r in rows if r["case"] == name and math.isfinite(r["err_ref_max_L"])]
        floor = min((r["err_ref_max_L"] for r in chosen if r["err_ref_max_L"] > 0), default=1e-12)
        for row in chosen:
            error = max(row["err_ref_max_L"], floor)
            fixed = row["step_control"] == "fixed"
            ax.scatter(
                row["kernel_us_per_ray"],
                error,
                marker=_MARKERS[row["precision"]],
                s=55 if fixed else 110,
                facecolors=_COLORS[row["interp"]] if fixed else "none",
                edgecolors="black" if FAIL_STEP in row["notes"] else _COLORS[row["interp"]],
                linewidths=1.6 if FAIL_STEP in row["notes"] or not fixed else 0.8,
                zorder=3,
            )
            if FAIL_F32_DRIFT in row["notes"]:
                ax.scatter(row["kernel_us_per_ray"], error, marker="x", s=90, color="red", zorder=4)
            if row["rays_lost"]:
                ax.annotate(
                    f"−{row['rays_lost']}",
                    (row["kernel_us_per_ray"], error),
                    xytext=(5, -9),
                    textcoords="offset points",
                    fontsize=7,
                    color="0.2",
                )
        points = [(r["kernel_us_per_ray"], max(r["err_ref_max_L"], floor)) for r in chosen]
        front = _pareto(points)
        ax.plot(
            [points[i][0] for i in front],
            [points[i][1] for i in front],
            color="0.45",
            linestyle="--",
            linewidth=1,
            zorder=2,
        )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(
            "cost: kernel time per ray (µs; warm, all cores; build and transfers excluded)"
        )
        ax.set_ylabel("max |r′ − r′_ref| / L")
        pixels_per_l = info["L"] / info["pixel"]
        secondary = ax.secondary_yaxis(
            "right", functions=(lambda y, s=pixels_per_l: y * s, lambda p, s=pixels_per_l: p / s)
        )
        secondary.set_ylabel(f"max |r′ − r′_ref| in pixels ({pixels_per_l:.0f} px across L)")
        tolerance = TOLERANCE_PIXELS / pixels_per_l
        ax.axhline(tolerance, color="0.5", linewidth=0.8, linestyle=":", zorder=1)
        ax.annotate(
            f"{TOLERANCE_PIXELS:g} px",
            (0.01, tolerance),
            xycoords=("axes fraction", "data"),
            xytext=(0, 2),
            textcoords="offset points",
            fontsize=7,
            color="0.35",
        )
        shape = "x".join(str(n) for n in info["field"]["shape_n3_n2_n1"][::-1])
        ax.set_title(
            f"{name}: "
            + ("δn stored" if info["k_rho"] is None else f"G = {info['k_rho']:.3g}")
            + f", Δn = {info['field']['delta_n_range']:.2g}, "
            f"{shape} nodes, {info['rays']} rays\n{_reference_counts(rows, name)}",
            fontsize=9.5,
        )
        ax.grid(True, which="major", alpha=0.3)
    handles = [
        Line2D([], [], color=c, marker="o", linestyle="", label=k) for k, c in _COLORS.items()
    ]
    handles += [
        Line2D([], [], color="0.35", marker=m, linestyle="", label=k) for k, m in _MARKERS.items()
    ]
    handles += [
        Line2D(
            [],
            [],
            color="0.35",
            marker="o",
            markerfacecolor="none",
            markersize=9,
            linestyle="",
            label="adaptive step, f32c",
        ),
        Line2D(
            [],
            [],
            color="0.8",
            marker="o",
            markeredgecolor="black",
            markeredgewidth=1.6,
            linestyle="",
            label="step error > 0.01 px",
        ),
        Line2D([], [], color="red", marker="x", linestyle="", label="f32 drift"),
        Line2D([], [], color="0.45", linestyle="--", label="Pareto front"),
    ]
    figure.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=len(handles))
    figure.suptitle(
        "rimcl bench: error of r′ against a float64 bspline3 fine-step reference, against cost"
        f" — {meta['device']['device']}",
        fontsize=11,
    )
    record = {"device": meta["device"], "versions": versions(), "references": meta["references"]}
    figure.savefig(
        path,
        format="png",
        dpi=130,
        metadata={"Software": f"rimcl bench {__version__}", "Description": to_json(record)},
    )


def bench(
    out_dir,
    *,
    quick=False,
    device=None,
    field_path=None,
    cases=DEFAULT_CASES,
    interps=None,
    precisions=None,
    pixels=PAPER_PIXELS,
    progress=None,
):
    """Run the benchmark and write ``bench.csv``, ``bench.json`` and ``bench.png``.

    Parameters
    ----------
    out_dir : str or Path
        Existing or new directory.
    quick : bool
        The short sweep (about a minute on 2 CPU cores once the kernels are built).
    device : str or pyopencl.Device, optional
    field_path : str or Path, optional
        Field file; default the shipped sample.
    cases : sequence of str
        Gladstone–Dale cases.
    interps, precisions : sequence of str, optional
    pixels : int
        Camera pixels across L.
    progress : callable, optional
        Called with each finished row.

    Returns
    -------
    dict
        ``csv``, ``json``, ``png`` paths, ``rows`` and ``meta``.
    """
    out_dir = Path(out_dir)
    if cases is not None and not list(cases):
        raise RimclError("name at least one case to benchmark (e.g. C1,C4)")
    found = bench_cases(field_path, cases, quick=quick, pixels=pixels)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RimclError(f"cannot create output directory {out_dir}: {exc.strerror}") from None
    rows, meta = run_bench(
        found,
        device=device,
        quick=quick,
        interps=interps,
        precisions=precisions,
        progress=progress,
    )
    meta["pixels"] = int(pixels)
    if not rows:
        raise RimclError("the sweep produced no results; nothing was written")
    paths = {
        "csv": out_dir / "bench.csv",
        "json": out_dir / "bench.json",
        "png": out_dir / "bench.png",
    }
    # all three or none: a failure in any (the plot, a full disk) keeps the earlier results
    with contextlib.ExitStack() as stack:
        temporary = {key: stack.enter_context(atomic_path(path)) for key, path in paths.items()}
        write_csv(temporary["csv"], rows, meta)
        write_json(temporary["json"], rows, meta)
        plot_pareto(temporary["png"], rows, meta)
    return {**paths, "rows": rows, "meta": meta}

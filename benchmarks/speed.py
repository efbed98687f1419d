"""Ray-steps per second of rimcl.trace_rays, as ratios to a float64 numba baseline.

The machines drift by 30-40 % from minute to minute, so only ratios measured
in one run mean anything. This script times, on one field and one ray set, interleaved:

- the numba float64 implementation of the same method (``rimcl.optics.baseline``: trilinear,
  same rays, same step, parallel over rays on all CPU cores), the baseline of every ratio;
- a second numba implementation of the method written apart from the package
  (``benchmarks/numba_independent.py``), which checks that baseline: the package's must
  trace within 10 % of its speed or faster (issue 26), so that ratios are not inflated;
- ``rimcl.trace_rays`` with every interpolation x precision the device supports, each
  with the kernel shape ``trace_rays`` chooses for it (warm: kernel build and field
  upload excluded);
- on CPUs, the kernel shapes (rays per work-item, the PoCL switch) for the
  default trilinear f32c: 1, 8 and 16 rays per work-item with and without the switch
  (16 with it is the default and the device engine's fan kernel,
  ``rimcl.imaging.engine.FAN_CPU_LANES``).

and prints a compact table (ray-steps/s, best of the repeats; ratio = median over the
repeats of the paired ratios to numba, and to the independent numba code) plus the largest
difference of r' between the default trace and numba, in units of L. Run it on any device:

    python benchmarks/speed.py                      # default device, 128³ field, 30720 rays
    python benchmarks/speed.py --device nvidia --json gpu.json
    python benchmarks/speed.py --field sample --repeats 7

The field is a seeded smooth random field (128³ nodes, Δn = 2.8e-4 as air, clamped)
or the shipped 64³ sample (``--field sample``, case C1); the rays are the paper's
camera: 30 tracers in the sheet with a 32 x 32 fan each.
"""

import argparse
import importlib.util
import statistics
import time

import numpy as np

import rimcl
from rimcl.core.device import describe_device, has_fp64
from rimcl.core.provenance import to_json, versions
from rimcl.imaging.engine import FAN_CPU_LANES
from rimcl.optics.bench import synthetic_density
from rimcl.optics.rays import fan_rays, scene_for
from rimcl.optics.shapes import CPU_LANES, POCL_FLOAT_LANES, KernelShape, default_kernel_shape
from rimcl.optics.trace import INTERPOLATIONS, PRECISIONS, _default_max_steps, default_step


def make_field(name):
    """The benchmark field: ``synthetic`` (128³, clamped) or ``sample`` (C1)."""
    if name == "sample":
        return rimcl.load_field(None, 0, case="C1")
    density = synthetic_density(128, seed=3)
    k_rho = 2.82e-4
    values = k_rho * (density - density.mean())
    return rimcl.Field.from_arrays(
        values, spacing=(1 / 127,) * 3, n_ref=1.0 + k_rho * density.mean(), boundary="clamp"
    )


def timed(function):
    start = time.perf_counter()
    result = function()
    return result, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="OpenCL device spec (rimcl devices).")
    parser.add_argument("--field", choices=("synthetic", "sample"), default="synthetic")
    parser.add_argument("--tracers", type=int, default=30)
    parser.add_argument("--fan", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-numba", action="store_true", help="Skip the numba baseline.")
    parser.add_argument("--json", default=None, help="Also write the results to this file.")
    args = parser.parse_args()

    device = rimcl.select_device(args.device)
    field = make_field(args.field)
    scene = scene_for(field)
    origins, directions, _ = fan_rays(scene, args.tracers, args.fan, seed=0)
    x_end = scene.x_end
    length = float(np.max(scene.fov_size))

    settings = [
        (interp, precision, default_kernel_shape(device, precision, interp))
        for interp in INTERPOLATIONS
        for precision in PRECISIONS
        if (interp != "texture" or device.image_support)
        and (precision != "f64" or has_fp64(device))
    ]
    default = ("trilinear", "f32c", default_kernel_shape(device))
    if default[2].lanes > 1:  # the kernel shapes, and the device engine's
        shapes = (
            (1, False),
            (1, True),
            (CPU_LANES, False),
            (CPU_LANES, True),
            (POCL_FLOAT_LANES, False),
            (FAN_CPU_LANES, True),
        )
        for lanes, pocl_fast in shapes:
            setting = ("trilinear", "f32c", KernelShape(lanes, pocl_fast))
            if setting not in settings:
                settings.append(setting)

    def run(interp, precision, shape):
        return rimcl.trace_rays(
            field,
            origins,
            directions,
            x_end=x_end,
            interp=interp,
            precision=precision,
            device=device,
            kernel_shape=shape,
        )

    numba_trace = independent = None
    if not args.no_numba and importlib.util.find_spec("numba") is None:
        print("numba is not installed: no numba baselines (ratios n/a)")
        args.no_numba = True
    if not args.no_numba:
        from numba_independent import trace_field as independent_trace

        from rimcl.optics.baseline import trace_rays_numba

        def numba_trace():
            return trace_rays_numba(field, origins, directions, x_end=x_end)

        step = default_step(field)
        limit = _default_max_steps(field, step, x_end, origins, directions)

        def independent():
            return independent_trace(
                field, origins, directions, x_end=x_end, step=step, max_steps=limit
            )

        numba_trace()  # compile (cached on disk), warm up
        independent()
    for setting in settings:
        run(*setting)  # build, upload, warm up at the full launch size

    rates = {setting: [] for setting in settings}
    kernel_rates = {setting: [] for setting in settings}
    ratios = {setting: [] for setting in settings}
    numba_rates, independent_rates, baseline_ratios = [], [], []
    independent_ratios = {setting: [] for setting in settings}
    reference = baseline = None
    for _ in range(args.repeats):
        if independent is not None:  # the two numba codes back to back: their ratio
            (_, steps, _), independent_seconds = timed(independent)
            baseline, numba_seconds = timed(numba_trace)
            independent_rates.append(int(steps.sum()) / independent_seconds)
            baseline_ratios.append(independent_seconds / numba_seconds)
        for setting in settings:
            # numba right before each setting: the pair sees the same machine load
            if numba_trace is not None:
                baseline, numba_seconds = timed(numba_trace)
                numba_rates.append(int(baseline.steps.sum()) / numba_seconds)
            result, seconds = timed(lambda s=setting: run(*s))
            rates[setting].append(int(result.steps.sum()) / seconds)
            kernel_rates[setting].append(int(result.steps.sum()) / result.config["kernel_seconds"])
            if numba_trace is not None:
                ratios[setting].append(numba_seconds / seconds)
                # the independent code's time, scaled by its ratio to the baseline's
                independent_ratios[setting].append(numba_seconds * baseline_ratios[-1] / seconds)
            if setting == default:
                reference = result

    rows = [
        {
            "interp": interp,
            "precision": precision,
            "rays_per_work_item": shape.lanes,
            "pocl_switch": shape.pocl_fast,
            "ray_steps_per_s": max(rates[(interp, precision, shape)]),
            "kernel_ray_steps_per_s": max(kernel_rates[(interp, precision, shape)]),
            "ratio_to_numba": statistics.median(ratios[(interp, precision, shape)])
            if ratios[(interp, precision, shape)]
            else None,
            "ratio_to_independent_numba": statistics.median(
                independent_ratios[(interp, precision, shape)]
            )
            if independent_ratios[(interp, precision, shape)]
            else None,
        }
        for interp, precision, shape in settings
    ]
    agreement = None
    if baseline is not None:
        both = reference.ok & baseline.ok
        agreement = float(np.max(np.abs(reference.image_pos[both] - baseline.image_pos[both])))
    report = {
        "device": describe_device(device),
        "field": field.describe(),
        "rays": len(origins),
        "steps_per_ray": float(reference.steps.mean()),
        "numba_ray_steps_per_s": max(numba_rates) if numba_rates else None,
        "independent_numba_ray_steps_per_s": max(independent_rates) if independent_rates else None,
        "numba_speed_over_independent": statistics.median(baseline_ratios)
        if baseline_ratios
        else None,
        "max_image_difference_to_numba_L": None if agreement is None else agreement / length,
        "rows": rows,
        "versions": versions(),
    }
    print(f"device: {report['device']['device']} ({report['device']['platform']})")
    print(
        f"field: {args.field} {field.shape[::-1]} nodes, {len(origins)} rays, "
        f"{report['steps_per_ray']:.0f} steps per ray (half a cell of arc)"
    )
    if numba_rates:
        print(
            f"numba float64: rimcl.optics.baseline {max(numba_rates):.3g} ray-steps/s (best), "
            f"independent code {max(independent_rates):.3g}; baseline speed / independent: "
            f"{report['numba_speed_over_independent']:.2f} (median of paired runs)"
        )
    print("ray-steps/s: through rimcl.trace_rays (x numba, x indep: median of paired ratios to")
    print("the two numba codes), and in the kernel alone (uploads, downloads, host work excluded)")
    print(
        f"{'interp':10s} {'prec':5s} {'rays/item':>9s} {'PoCL sw':>7s} {'ray-steps/s':>12s} "
        f"{'x numba':>8s} {'x indep':>8s} {'kernel':>10s}"
    )

    def ratio_text(ratio):
        return "n/a" if ratio is None else f"{ratio:.2f}"

    for row in rows:
        print(
            f"{row['interp']:10s} {row['precision']:5s} {row['rays_per_work_item']:9d} "
            f"{'yes' if row['pocl_switch'] else 'no':>7s} {row['ray_steps_per_s']:12.3g} "
            f"{ratio_text(row['ratio_to_numba']):>8s} "
            f"{ratio_text(row['ratio_to_independent_numba']):>8s} "
            f"{row['kernel_ray_steps_per_s']:10.3g}"
        )
    if agreement is not None:
        print(f"max |r' - r'_numba| / L (trilinear f32c): {agreement / length:.2e}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as out:
            out.write(to_json(report))
    return report


if __name__ == "__main__":
    main()

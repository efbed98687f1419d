"""``rimcl trace``: trace a ray fan (or rays from a file) through a field to HDF5."""

import time

import click
import numpy as np

from rimcl.cli.options import (
    COUNT,
    INDEX,
    MAX_STEPS_LIMIT,
    POSITIVE,
    case_option,
    device_option,
    field_option,
    handle_errors,
    interp_option,
    k_rho_option,
    overwrite_option,
    parse_step,
    precision_option,
    seed_option,
    step_option,
    tolerance_option,
)

ANALYTIC_NAMES = ("uniform", "grin", "fisheye", "linear")


@click.command()
@field_option
@click.option("--frame", type=INDEX, default=0, show_default=True, help="Frame of the field file.")
@case_option
@k_rho_option
@click.option(
    "--analytic",
    type=click.Choice(ANALYTIC_NAMES),
    default=None,
    help="Trace through a closed-form field instead (default parameters, L = --length).",
)
@click.option(
    "--length",
    type=POSITIVE,
    default=None,
    help="Depth L1 of the traced slab (default: the field's depth; π for --analytic).",
)
@click.option(
    "--tracers", type=COUNT, default=10, show_default=True, help="Random tracers in the sheet."
)
@click.option(
    "--fan", type=COUNT, default=32, show_default=True, help="M: each tracer sends M×M rays."
)
@click.option(
    "--rays",
    "rays_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Trace these rays instead (.npz/.h5 with origins, directions; or CSV x1..d3).",
)
@interp_option
@precision_option
@step_option
@tolerance_option
@click.option(
    "--max-steps",
    type=click.IntRange(1, MAX_STEPS_LIMIT),
    default=None,
    help="Stop rays after this many steps.",
)
@device_option
@seed_option
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    default="trace.h5",
    show_default=True,
    help="Output HDF5 file.",
)
@overwrite_option
@handle_errors
def trace(
    field_path,
    frame,
    case,
    k_rho,
    analytic,
    length,
    tracers,
    fan,
    rays_path,
    interp,
    precision,
    step,
    tolerance,
    max_steps,
    device_spec,
    seed,
    output,
    overwrite,
):
    """Trace rays through a refractive-index field to the exit plane and write every
    ray's image point, exit state, deflection, path length and status.

    \b
    Examples:
      rimcl trace --tracers 20 --fan 32 -o air.h5            # shipped sample, case C1
      rimcl trace --case C4 --precision f64 -o water.h5
      rimcl trace --analytic grin --length 100 --fan 8 -o grin.h5
    """
    from rimcl.core.device import describe_device, select_device
    from rimcl.core.memory import check_field_upload, check_trace_memory
    from rimcl.core.provenance import check_output
    from rimcl.fields.field import Field, analytic_field
    from rimcl.fields.field_loading import case_arguments, load_field
    from rimcl.optics.rays import fan_rays, read_rays, scene_for, write_trace
    from rimcl.optics.tracing import trace_rays

    check_output(output, overwrite)
    if analytic is not None:
        field = analytic_field(analytic)
        source = {"analytic": analytic, "params": field.params}
    else:
        case, k_rho = case_arguments(field_path, case, k_rho)
        field = load_field(field_path, frame=frame, case=case, k_rho=k_rho)
        source = {
            "field": field_path or "shipped sample",
            "frame": frame,
            "case": field.attrs.get("case", "delta_n"),
            "k_rho": field.attrs.get("k_rho"),
        }
    scene = scene_for(field, length)
    tracer_id = None
    if rays_path is not None:
        origins, directions = read_rays(rays_path)
    else:
        check_trace_memory(tracers * fan**2, "tracing")
        origins, directions, tracer_id = fan_rays(scene, tracers, fan, seed)
    device = select_device(device_spec)
    if interp != "auto" and isinstance(field, Field):
        check_field_upload(field.shape, device, interp)
    started = time.perf_counter()
    result = trace_rays(
        field,
        origins,
        directions,
        x_end=scene.x_end,
        step=parse_step(step),
        interp=interp,
        precision=precision,
        device=device,
        max_steps=max_steps,
        progress=True,
        tolerance=tolerance,
    )
    elapsed = time.perf_counter() - started
    config = {
        "command": "trace",
        "source": source,
        "scene": scene.describe(),
        "rays": rays_path or {"tracers": tracers, "fan": fan, "seed": seed},
    }
    write_trace(output, result, config, device=device, tracer_id=tracer_id, overwrite=overwrite)
    auto = result.config.get("auto")
    if auto is not None:
        click.echo(
            f"auto: interp {auto['interp']}, step {auto['step']:.4g}, estimated r' error "
            f"{auto['estimated_error']:.2e} (tolerance {auto['tolerance']:.2e}"
            f"{'' if auto['met'] else ', NOT met: the most accurate candidate was kept'})"
        )
    counts = ", ".join(f"{name} {count}" for name, count in result.counts.items())
    ok = result.ok
    click.echo(f"traced {len(result)} rays on {describe_device(device)['device']}: {counts}")
    work = result.config.get("sharma_steps", int(result.steps.sum()))
    kernel_seconds = result.config.get("kernel_seconds") or float("nan")
    click.echo(
        f"step {result.step:.4g} (in t): {work:.3g} ray-steps, {elapsed:.2f} s in all "
        f"(kernel builds included), {work / kernel_seconds:.3g} ray-steps/s in the kernel"
    )
    if ok.any():
        shift = abs(result.image_pos[ok] - result.origins[ok])[:, 1:].max()
        click.echo(
            f"deflection |Δθ|: median {np.median(result.deflection[ok]):.3g}"
            f" rad; largest image shift |r' - r0| {shift:.3g} (L1 = {scene.depth:.4g})"
        )
    click.echo(f"wrote {output}")

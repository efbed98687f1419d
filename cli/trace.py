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
    command_scene,
    device_option,
    field_option,
    handle_errors,
    k_rho_option,
    overwrite_option,
    parse_step,
    scene_options,
    step_option,
    tolerance_option,
)

ANALYTIC_NAMES = ("uniform", "grin", "fisheye", "linear")


#: ``rimcl trace`` option -> scene key it overrides (the rest are the command's own)
SCENE_KEYS = {
    "field_path": "field.path",
    "frame": "field.start_frame",
    "length": "field.depth",
    "tracers": "tracers.count",
    "fan": "camera.fan",
    "precision": "integrator.precision",
    "device_spec": "run.device",
    "seed": "tracers.seed",
}


@click.command()
@scene_options
@field_option
@click.option("--frame", type=INDEX, help="Frame of the field file [field.start_frame].")
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
    help="Depth L1 of the traced slab (default: the field's depth; π for --analytic) "
    "[field.depth].",
)
@click.option("--tracers", type=COUNT, help="Random tracers in the sheet [tracers.count].")
@click.option("--fan", type=COUNT, help="M: each tracer sends M×M rays [camera.fan].")
@click.option(
    "--rays",
    "rays_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Trace these rays instead (.npz/.h5 with origins, directions; or CSV x1..d3).",
)
@click.option(
    "--interp",
    type=click.Choice(["trilinear", "texture", "bspline3", "auto"]),
    help="Interpolation of the gridded field; auto: chosen by --tolerance [integrator.interp].",
)
@click.option(
    "--precision",
    type=click.Choice(["f32", "f32c", "f64"]),
    help="Accumulation precision [integrator.precision].",
)
@step_option
@tolerance_option
@click.option(
    "--max-steps",
    type=click.IntRange(1, MAX_STEPS_LIMIT),
    default=None,
    help="Stop rays after this many steps.",
)
@device_option
@click.option("--seed", type=INDEX, help="Random seed of the tracers [tracers.seed].")
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
    scene_file,
    scene_option,
    case,
    k_rho,
    analytic,
    rays_path,
    interp,
    step,
    tolerance,
    max_steps,
    output,
    overwrite,
    **options,
):
    """Trace rays through a refractive-index field to the exit plane and write every
    ray's image point, exit state, deflection, path length and status.

    The field, sheet, depth, tracers, fan and integrator come from the scene (SCENE_FILE,
    default: the default scene); options override its keys (named in brackets). The case
    is --case, else the scene's first case other than C0 (the default scene: C1, air).

    \b
    Examples:
      rimcl trace --tracers 20 --fan 32 -o air.h5            # shipped sample, case C1
      rimcl trace scene.toml --case C4 --precision f64 -o water.h5
      rimcl trace --analytic grin --length 100 --fan 8 -o grin.h5
    """
    from rimcl.core.atomic import check_output
    from rimcl.core.device import describe_device, select_device
    from rimcl.core.memory import check_field_upload, check_trace_memory
    from rimcl.fields.field import Field, analytic_field
    from rimcl.fields.field_loading import load_field
    from rimcl.optics.rays import fan_rays, read_rays, scene_for, write_trace
    from rimcl.optics.tracing import trace_rays
    from rimcl.scene.command import command_case

    check_output(output, overwrite)
    overrides = {SCENE_KEYS[name]: value for name, value in options.items()}
    parsed_step = parse_step(step)
    if isinstance(parsed_step, float):
        overrides["integrator.step"] = parsed_step
    if interp not in (None, "auto"):
        overrides["integrator.interp"] = interp
    scene_table = command_scene(scene_file, scene_option, overrides, "trace", velocity=False)
    field_keys, integrator = scene_table["field"], scene_table["integrator"]
    frame, length = field_keys["start_frame"], field_keys["depth"]
    tracers, seed = scene_table["tracers"]["count"], scene_table["tracers"]["seed"]
    fan, device_spec = scene_table["camera"]["fan"], scene_table["run"]["device"] or None
    interp = "auto" if interp == "auto" else integrator["interp"]
    precision = integrator["precision"]
    step = parsed_step if isinstance(parsed_step, str) else integrator["step"]
    field_path = field_keys["path"] or None
    check_output(output, True, [field_path, scene_file, scene_option, rays_path])
    if analytic is not None:
        field = analytic_field(analytic)
        source = {"analytic": analytic, "params": field.params}
    else:
        case, k_rho = command_case(scene_table, case, k_rho)
        field = load_field(field_path, frame=frame, case=case, k_rho=k_rho)
        source = {
            "field": field_path or "shipped sample",
            "frame": frame,
            "case": field.attrs.get("case", "delta_n"),
            "k_rho": field.attrs.get("k_rho"),
        }
    scene = scene_for(field, length, x_sheet=field_keys["x_sheet"])
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
        step=step,
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

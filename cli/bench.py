"""``rimcl bench``: speed against accuracy of the tracing methods."""

import click

from rimcl.cli.options import COUNT, device_option, field_option, handle_errors

_COLUMNS = (
    ("case", 5, "case"),
    ("interp", 9, "interp"),
    ("precision", 4, "prec"),
    ("step_control", 8, "control"),
    ("step_cells", 6, "cells"),
    ("kernel_ray_steps_per_s", 9, "steps/s"),
    ("kernel_us_per_ray", 8, "µs/ray"),
    ("err_ref_max_px", 9, "err px"),
    ("err_fine_max_px", 9, "step px"),
)


def _format(key, value):
    if isinstance(value, float):
        return f"{value:.3g}" if key != "step_cells" else f"{value:.2f}"
    return str(value)


@click.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    default=None,
    help="Directory for bench.csv, bench.json and bench.png (created if missing); "
    "required unless --tune.",
)
@click.option(
    "--tune",
    is_flag=True,
    help="Measure the device's kernel shapes again (rays per work-item, PoCL switch, "
    "work-group size of the trace kernels; the image kernel's work-group size), keep the "
    "fastest in the user's cache and print the measurements.",
)
@click.option(
    "--quick", is_flag=True, help="Short sweep: 3 steps, 1 adaptive tolerance, small ray set."
)
@field_option
@click.option(
    "--cases",
    default="C1,C4",
    show_default=True,
    help="Gladstone–Dale cases to apply to the field's density, comma-separated.",
)
@click.option(
    "--interp",
    "interps",
    default=None,
    help="Interpolations to sweep, comma-separated (default: all the device supports).",
)
@click.option(
    "--precision",
    "precisions",
    default=None,
    help="Precisions to sweep, comma-separated (default: all the device supports).",
)
@click.option(
    "--pixels",
    type=COUNT,
    default=8192,
    show_default=True,
    help="Camera pixels across the field of view L (errors are also given in pixels).",
)
@device_option
@handle_errors
def bench(out_dir, tune, quick, field_path, cases, interps, precisions, pixels, device_spec):
    """Trace the same rays with every interpolation, precision and step (fixed and
    adaptive), measure warm ray-steps/s and the error of the image points r' against a
    float64 bspline3 fine-step reference, and chart error against cost.

    Columns: cells = step in cells of arc (adaptive: the mean); steps/s and µs/ray =
    kernel time (warm; build and transfers excluded); err px = max |r' - r'_ref| in
    pixels; step px = the same against the same interpolation at the fine step.

    Rows where a method fails are marked: f32 drift, a step error above 0.01 pixel,
    rays lost; rays turned back or leaving through the side (water) are counted.

    \b
    Examples:
      rimcl bench --quick --out bench-out
      rimcl bench --tune
    """
    from rimcl.core.errors import RimclError
    from rimcl.optics.bench import bench as run

    if out_dir is None and not tune:
        raise RimclError("give --out DIR for the sweep, or --tune to measure kernel shapes")
    if tune:
        _tune(device_spec)
        if out_dir is None:
            return

    def split(text):
        return None if text is None else [item.strip() for item in text.split(",") if item]

    shown = []

    def show(row):
        if not shown:  # the header comes with the first row, not before a refusal
            click.echo("  ".join(title.ljust(width) for _, width, title in _COLUMNS))
        shown.append(row)
        cells = [_format(key, row[key]).ljust(width) for key, width, _ in _COLUMNS]
        click.echo("  ".join(cells).rstrip())

    report = run(
        out_dir,
        quick=quick,
        device=device_spec,
        field_path=field_path,
        cases=split(cases),
        interps=split(interps),
        precisions=split(precisions),
        pixels=pixels,
        progress=show,
    )
    marked = [row for row in report["rows"] if row["notes"]]
    if marked:
        click.echo("\nwhere methods fail (and rays that do not reach the exit plane):")
        for row in marked:
            setting = " ".join(_format(key, row[key]) for key, _, _ in _COLUMNS[:5])
            click.echo(f"  {setting} cells: {row['notes']}")
    click.echo(f"\ndevice: {report['meta']['device']['device']}")
    for key in ("csv", "json", "png"):
        click.echo(f"wrote {report[key]}")


def _tune(device_spec):
    """Measure the kernel shapes of the device and print what was measured."""
    from rimcl.core.device import select_device
    from rimcl.imaging.device import tune_image
    from rimcl.optics.shapes import cache_path, describe_shape
    from rimcl.optics.tuning import tune

    device = select_device(device_spec)
    click.echo(f"measuring kernel shapes on {device.name.strip()} (trilinear f32c) ...")
    entry = tune(device)
    work = entry["workload"]
    click.echo(
        f"{work['rays']} rays, {work['field_nodes']}^3 field, best of {work['repeats']} "
        f"kernel runs each ({entry['seconds']:.0f} s in all, builds included)"
    )
    click.echo(f"{'shape':40s} {'ray-steps/s':>12s}")
    for row in sorted(entry["measurements"], key=lambda m: -m["ray_steps_per_s"]):
        click.echo(f"{describe_shape(row):40s} {row['ray_steps_per_s']:12.3g}")
    click.echo(f"chosen: {describe_shape(entry['shape'])}; stored in {cache_path()}")
    click.echo("measuring the image kernel's work-group sizes ...")
    image = tune_image(device)
    work = image["workload"]
    click.echo(
        f"{work['tracers']} tracers x {work['rays']} rays, best of {work['repeats']} "
        f"kernel runs each ({image['seconds']:.0f} s in all, builds included)"
    )
    click.echo(f"{'image work-group size':40s} {'tracers/s':>12s}")
    for row in sorted(image["measurements"], key=lambda m: -m["tracers_per_s"]):
        click.echo(f"{row['group']:<40d} {row['tracers_per_s']:12.3g}")
    click.echo(f"chosen: image group {image['group']}; stored in {cache_path()}")

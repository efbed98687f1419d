"""``rimcl render``: the synthetic PTV measurement of one case, to HDF5."""

import click
import numpy as np

from rimcl.cli.options import (
    COUNT,
    INDEX,
    NON_NEGATIVE,
    POSITIVE,
    FiniteFloat,
    case_option,
    device_option,
    engine_option,
    field_option,
    handle_errors,
    interp_option,
    k_rho_option,
    overwrite_option,
    parse_step,
    precision_option,
    seed_option,
    step_option,
)


@click.command()
@field_option
@case_option
@k_rho_option
@click.option(
    "--tracers", type=COUNT, default=1000, show_default=True, help="Tracers in the sheet."
)
@click.option(
    "--camera",
    type=click.Choice(["plane", "pupil"]),
    default="plane",
    show_default=True,
    help="plane: M×M rays to the exit plane (the paper); pupil: rays over a lens aperture.",
)
@click.option(
    "--fan", type=COUNT, default=32, show_default=True, help="M of the plane camera (paper: 100)."
)
@click.option(
    "--pupil-rays", type=COUNT, default=1024, show_default=True, help="Rays per tracer (pupil)."
)
@click.option(
    "--aperture-diameter",
    type=POSITIVE,
    default=None,
    help="Pupil diameter, field length units [default: camera distance / 4].",
)
@click.option("--focal-length", type=POSITIVE, default=None, help="With --f-number: D = F / N.")
@click.option("--f-number", type=POSITIVE, default=None, help="With --focal-length: D = F / N.")
@click.option(
    "--camera-distance",
    type=POSITIVE,
    default=None,
    help="Sheet to pupil centre along the viewing axis [default: 4 L1].",
)
@click.option(
    "--view-angle",
    type=FiniteFloat(-90.0, 90.0),
    default=0.0,
    show_default=True,
    help="Viewing axis angle to x1, towards +x2 (degrees).",
)
@click.option(
    "--renderer",
    type=click.Choice(["exact", "paper"]),
    default="exact",
    show_default=True,
    help="exact: pixel-integrated Gaussian per ray; paper: binning + Gaussian filter.",
)
@click.option(
    "--pixels",
    type=COUNT,
    default=8192,
    show_default=True,
    help="Pixels across the wider side of the field of view (paper: 8192).",
)
@click.option(
    "--psf-sigma", type=POSITIVE, default=2.3, show_default=True, help="Gaussian PSF σ in pixels."
)
@click.option(
    "--threshold",
    type=NON_NEGATIVE,
    default=100.0,
    show_default=True,
    help="Grey threshold in camera counts (paper, 10 bits: 100 air, 500 water).",
)
@click.option(
    "--centroid-weights",
    type=click.Choice(["excess", "grey"]),
    default="excess",
    show_default=True,
    help="excess: grey minus threshold; grey: grey value (the paper, biased).",
)
@click.option(
    "--max-window",
    type=COUNT,
    default=512,
    show_default=True,
    help="Largest tracer window side (px).",
)
@click.option(
    "--bit-depth",
    type=click.IntRange(8, 16),
    default=10,
    show_default=True,
    help="Bits per pixel of the camera (paper: 10); the threshold is in its counts.",
)
@interp_option
@precision_option
@step_option
@click.option(
    "--frames",
    type=click.IntRange(1, 1000),
    default=3,
    show_default=True,
    help="Frames imaged; 1: positions; 2: + velocity; 3 or more: + acceleration.",
)
@click.option(
    "--dt",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Time between imaged frames [default: the field's frame spacing].",
)
@click.option(
    "--fit-window",
    type=click.IntRange(min=3),
    default=5,
    show_default=True,
    help="Frames of the sliding polynomial fit of each track (odd).",
)
@click.option(
    "--fit-order", type=click.IntRange(min=2), default=2, show_default=True, help="Fit order."
)
@click.option(
    "--start-frame", type=INDEX, default=0, show_default=True, help="First field frame used."
)
@click.option(
    "--margin",
    type=FiniteFloat(0.0, 0.5),
    default=0.05,
    show_default=True,
    help="Edge band free of tracers (fraction of the field of view).",
)
@click.option(
    "--frame-image",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write the first frame of all tracers as a 16-bit PNG or TIFF.",
)
@device_option
@engine_option
@seed_option
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    default="render.h5",
    show_default=True,
    help="Output HDF5 file.",
)
@overwrite_option
@handle_errors
def render(
    field_path, case, k_rho, step, frame_image, device_spec, engine, output, overwrite, **options
):
    """Synthetic PTV: trace each tracer's rays, render its image, centroid it, track it;
    compare with a uniform medium and with the true motion.

    \b
    Examples:
      rimcl render --tracers 200 --fan 16 -o air.h5              # shipped sample, C1
      rimcl render --case C4 --threshold 500 -o water.h5
      rimcl render --camera pupil --camera-distance 30 --f-number 8 --focal-length 50 \\
                   --view-angle 10 -o pupil.h5
      rimcl render --tracers 50 --frame-image frame.png -o look.h5
    """
    from rimcl.core.device import describe_device
    from rimcl.core.provenance import check_output
    from rimcl.fields.field_loading import case_arguments
    from rimcl.ptv.measure import run_render
    from rimcl.ptv.render_file import check_frame_image, write_frame_image, write_render
    from rimcl.scene.config import MeasureConfig

    check_output(output, overwrite)
    if frame_image is not None:
        check_frame_image(frame_image, overwrite)
    case, k_rho = case_arguments(field_path, case, k_rho)
    config = MeasureConfig.from_options(
        **options,
        step=parse_step(step),
        frame_image=frame_image is not None,
        device=device_spec,
        **({} if engine is None else {"engine": engine}),
    )
    result = run_render(field_path, case=case, k_rho=k_rho, config=config, progress=True)
    write_render(output, result, overwrite=overwrite)
    if frame_image is not None:
        write_frame_image(frame_image, result, overwrite=overwrite)
    _summary(result, describe_device(result.device)["device"])
    click.echo(f"wrote {output}" + (f" and {frame_image}" if frame_image else ""))


def _summary(result, device_name):
    """A few lines a user can read: rays, flags, position errors, stage times."""
    attrs, rows = result.attrs, result.tracers
    counts = ", ".join(
        f"{name.removeprefix('count_')} {value}"
        for name, value in result.ray_attrs.items()
        if name.startswith("count_")
    )
    click.echo(
        f"case {attrs['case']} (G = {attrs['k_rho']:.4g}, Δn_max = {attrs['delta_n_max']:.3g}): "
        f"{attrs['n_tracers']} tracers × {attrs['rays_per_tracer']} rays × "
        f"{attrs['n_frames']} frames on {device_name}"
    )
    click.echo(f"measured rays: {counts}")
    auto = result.config.get("auto")
    if auto is not None:
        click.echo(
            f"auto: interp {auto['interp']}, estimated r' error {auto['estimated_error']:.2e} "
            f"(tolerance 0.01 pixel = {auto['tolerance']:.2e}"
            f"{'' if auto['met'] else ', NOT met: the most accurate candidate was kept'})"
        )
    flagged = int(np.count_nonzero(rows["flags"]))
    click.echo(f"tracer images flagged: {flagged} of {len(rows['flags'])}")
    error = np.hypot(rows["x2_meas"] - rows["x2_ref"], rows["x3_meas"] - rows["x3_ref"])
    if np.isfinite(error).any():
        click.echo(
            f"position error |x' - x_ref|: median {np.nanmedian(error) / attrs['length_L']:.3g} L,"
            f" max {np.nanmax(error) / attrs['length_L']:.3g} L"
            f" ({np.nanmedian(error) / attrs['pixel_size']:.3g} px median)"
        )
    times = ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in result.timings.items())
    click.echo(f"time per stage: {times}")
    steps = result.ray_attrs["ray_steps"] + result.ray_attrs["ref_ray_steps"]
    if result.timings["trace"] > 0:
        click.echo(
            f"{steps:.3g} ray-steps traced ({steps / result.timings['trace']:.3g} per second, "
            "reference included)"
        )

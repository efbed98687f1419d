"""``rimcl render``: the synthetic PTV measurement of one case, to HDF5."""

import dataclasses

import click
import numpy as np

from rimcl.cli.options import (
    COUNT,
    INDEX,
    NON_NEGATIVE,
    POSITIVE,
    FiniteFloat,
    case_option,
    command_scene,
    device_option,
    engine_option,
    field_option,
    handle_errors,
    k_rho_option,
    measure_step_option,
    overwrite_option,
    scene_options,
)

#: ``rimcl render`` option -> scene key it overrides (the rest are the command's own)
SCENE_KEYS = {
    "field_path": "field.path",
    "length_m": "field.length_m",
    "time_s": "field.time_s",
    "start_frame": "field.start_frame",
    "tracers": "tracers.count",
    "seed": "tracers.seed",
    "margin": "tracers.margin",
    "camera": "camera.kind",
    "fan": "camera.fan",
    "pupil_rays": "camera.pupil_rays",
    "aperture_diameter": "camera.aperture_diameter",
    "focal_length": "camera.focal_length",
    "f_number": "camera.f_number",
    "camera_distance": "camera.distance",
    "view_angle": "camera.view_angle",
    "renderer": "renderer.kind",
    "pixels": "renderer.pixels",
    "psf_sigma": "renderer.psf_sigma",
    "centroid_weights": "renderer.centroid_weights",
    "max_window": "renderer.max_window",
    "bit_depth": "renderer.bit_depth",
    "precision": "integrator.precision",
    "step": "integrator.step",
    "dt": "time.dt",
    "fit_window": "time.fit_window",
    "fit_order": "time.fit_order",
    "device_spec": "run.device",
    "engine": "run.engine",
}


@click.command()
@scene_options
@field_option
@case_option
@k_rho_option
@click.option("--tracers", type=COUNT, help="Tracers in the sheet [tracers.count].")
@click.option(
    "--camera",
    type=click.Choice(["plane", "pupil", "lens"]),
    help="plane: M×M rays to the exit plane (the paper); pupil: rays over an aperture; "
    "lens: a real lens in physical units (needs field.length_m) [camera.kind].",
)
@click.option("--fan", type=COUNT, help="M of the plane camera (paper: 100) [camera.fan].")
@click.option("--pupil-rays", type=COUNT, help="Rays per tracer (pupil, lens) [camera.pupil_rays].")
@click.option(
    "--aperture-diameter",
    type=POSITIVE,
    help="Pupil diameter, field length units [camera.aperture_diameter].",
)
@click.option("--focal-length", type=POSITIVE, help="With --f-number: D = F / N.")
@click.option("--f-number", type=POSITIVE, help="With --focal-length: D = F / N [camera.f_number].")
@click.option(
    "--camera-distance",
    type=POSITIVE,
    help="Sheet to pupil centre along the viewing axis [camera.distance].",
)
@click.option(
    "--view-angle",
    type=FiniteFloat(-90.0, 90.0),
    help="Viewing axis angle to x1, towards +x2, degrees [camera.view_angle].",
)
@click.option(
    "--length-m",
    type=POSITIVE,
    help="Metres per field length unit: outputs in µm and mm, and the lens camera "
    "[field.length_m].",
)
@click.option(
    "--time-s", type=POSITIVE, help="Seconds per field time unit: outputs in mm/s [field.time_s]."
)
@click.option(
    "--renderer",
    type=click.Choice(["exact", "paper"]),
    help="exact: pixel-integrated Gaussian per ray; paper: binning + Gaussian filter "
    "[renderer.kind].",
)
@click.option(
    "--pixels", type=COUNT, help="Pixels across the field of view (paper: 8192) [renderer.pixels]."
)
@click.option("--psf-sigma", type=POSITIVE, help="Gaussian PSF σ, pixels [renderer.psf_sigma].")
@click.option(
    "--threshold",
    type=NON_NEGATIVE,
    help="Grey threshold, camera counts, for the case measured [renderer.threshold, "
    "cases.thresholds].",
)
@click.option(
    "--centroid-weights",
    type=click.Choice(["excess", "grey"]),
    help="excess: grey minus threshold; grey: grey value (the paper) [renderer.centroid_weights].",
)
@click.option(
    "--max-window", type=COUNT, help="Largest tracer window side, px [renderer.max_window]."
)
@click.option(
    "--bit-depth",
    type=click.IntRange(8, 16),
    help="Bits per pixel (paper: 10) [renderer.bit_depth].",
)
@click.option(
    "--interp",
    type=click.Choice(["trilinear", "texture", "bspline3", "auto"]),
    help="Interpolation of the gridded field; auto: chosen by the tolerance [integrator.interp].",
)
@click.option(
    "--precision",
    type=click.Choice(["f32", "f32c", "f64"]),
    help="Accumulation precision [integrator.precision].",
)
@measure_step_option
@click.option(
    "--frames",
    type=click.IntRange(1, 1000),
    help="Frames imaged; 1: positions; 2: + velocity; 3 or more: + acceleration [time.frames].",
)
@click.option(
    "--dt",
    type=click.FloatRange(min=0, min_open=True),
    help="Time between imaged frames [time.dt; default: the field's frame spacing].",
)
@click.option("--fit-window", type=click.IntRange(min=3), help="Frames of the track fit (odd).")
@click.option("--fit-order", type=click.IntRange(min=2), help="Order of the track fit.")
@click.option("--start-frame", type=INDEX, help="First field frame used [field.start_frame].")
@click.option(
    "--margin",
    type=FiniteFloat(0.0, 0.5),
    help="Edge band free of tracers, fraction of the field of view [tracers.margin].",
)
@click.option(
    "--frame-image",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write the first frame of all tracers as a 16-bit PNG or TIFF.",
)
@device_option
@engine_option
@click.option("--seed", type=INDEX, help="Random seed of tracers and rays [tracers.seed].")
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
    scene_file,
    scene_option,
    case,
    k_rho,
    interp,
    frames,
    threshold,
    frame_image,
    output,
    overwrite,
    **options,
):
    """Synthetic PTV of one case from a scene (SCENE_FILE, default: the default scene):
    trace each tracer's rays, render its image, centroid it, track it; compare with a
    uniform medium and with the true motion.

    Options override the scene's keys (named in brackets); the case is --case, else the
    scene's first case other than C0 (the default scene: C1, air).

    \b
    Examples:
      rimcl render --tracers 200 --fan 16 -o air.h5              # shipped sample, C1
      rimcl render scene.toml --case C4 -o water.h5              # a study's scene
      rimcl render --camera pupil --camera-distance 30 --f-number 8 --focal-length 50 \\
                   --view-angle 10 -o pupil.h5
      rimcl render --tracers 50 --frame-image frame.png -o look.h5
    """
    from rimcl.core.atomic import check_output
    from rimcl.core.device import describe_device
    from rimcl.ptv.measure import run_render
    from rimcl.ptv.render_file import check_frame_image, write_frame_image, write_render
    from rimcl.scene.command import command_case
    from rimcl.scene.config import MeasureConfig

    check_output(output, overwrite)
    if frame_image is not None:
        check_frame_image(frame_image, overwrite)
    overrides = {SCENE_KEYS[name]: value for name, value in options.items()}
    # what the scene's keys cannot hold (a study needs 3 frames and a fixed
    # interpolation) is set on the configuration built from it
    if interp not in (None, "auto"):
        overrides["integrator.interp"] = interp
    if frames is not None and frames >= 3:
        overrides["time.frames"] = frames
    scene = command_scene(scene_file, scene_option, overrides, "render")
    case, k_rho = command_case(scene, case, k_rho)
    config = MeasureConfig.from_scene(scene, case)
    config = dataclasses.replace(
        config,
        renderer=dataclasses.replace(
            config.renderer,
            threshold=config.renderer.threshold if threshold is None else threshold,
        ),
        integrator=dataclasses.replace(
            config.integrator,
            interp="auto" if interp == "auto" else config.integrator.interp,
        ),
        time=config.time if frames is None else dataclasses.replace(config.time, frames=frames),
        run=dataclasses.replace(config.run, frame_image=frame_image is not None),
    )
    field_path = scene["field"]["path"] or None
    for path in (output, frame_image):  # an output that is an input: refused before work
        if path is not None:
            check_output(path, True, [field_path, scene_file, scene_option])
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
            f" ({np.nanmedian(error) / attrs['pixel_size']:.3g} px median"
            + (
                f", {np.nanmedian(error) * attrs['length_m'] * 1e6:.3g} µm"
                if attrs.get("length_m") is not None
                else ""
            )
            + ")"
        )
    times = ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in result.timings.items())
    click.echo(f"time per stage: {times}")
    steps = result.ray_attrs["ray_steps"] + result.ray_attrs["ref_ray_steps"]
    if result.timings["trace"] > 0:
        click.echo(
            f"{steps:.3g} ray-steps traced ({steps / result.timings['trace']:.3g} per second, "
            "reference included)"
        )

"""``rimcl piv``: correlate image pairs (any PIV images), render pairs through a field."""

import click
import numpy as np

from rimcl.cli.options import (
    COUNT,
    FINITE,
    INDEX,
    NON_NEGATIVE,
    POSITIVE,
    case_option,
    device_option,
    engine_option,
    field_option,
    handle_errors,
    k_rho_option,
    overwrite_option,
    parse_step,
    precision_option,
    seed_option,
    step_option,
)
from rimcl.study.summary import number

window_option = click.option(
    "--window",
    type=COUNT,
    default=32,
    show_default=True,
    help="Interrogation window of the last pass (px).",
)
overlap_option = click.option(
    "--overlap",
    type=NON_NEGATIVE,
    default=0.5,
    show_default=True,
    help="Window overlap (fraction).",
)


def echo_piv_case_lines(stats):
    """One line per case of a study's PIV results: vectors used, errors in pixels and u3."""
    for case in stats["cases"]:
        if "piv" not in case:
            continue
        piv = case["piv"]
        pixels, u3 = piv["displacement_px"], piv["velocity"]["u3"]
        click.echo(
            f"{'PIV ' + case['name']:>8}  G = {number(piv['G'])}: "
            f"{piv['n_used']}/{piv['n_vectors']} vectors, refraction "
            f"{number(pixels['refraction_rms'])} px rms (truth {number(pixels['truth_rms'])} "
            f"px), u3 rms(ε)/rms(u) {number(u3['rms_normalized'])}"
        )


@click.group()
def piv():
    """PIV: cross-correlation of image pairs, and image pairs rendered through a field."""


@piv.command()
@click.argument("image_a", type=click.Path(dir_okay=False))
@click.argument("image_b", type=click.Path(dir_okay=False))
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output HDF5 file."
)
@window_option
@overlap_option
@click.option(
    "--passes", type=COUNT, default=3, show_default=True, help="Passes (2+: window deformation)."
)
@click.option(
    "--first-window",
    type=COUNT,
    default=None,
    help="Window of the first pass (px) [default: --window]; shrinks to --window.",
)
@click.option(
    "--outlier-eps",
    type=POSITIVE,
    default=0.2,
    show_default=True,
    help="eps of the normalized median test (px).",
)
@click.option(
    "--outlier-threshold",
    type=POSITIVE,
    default=2.0,
    show_default=True,
    help="Threshold of the normalized median test.",
)
@click.option(
    "--export",
    "exports",
    multiple=True,
    type=click.Path(dir_okay=False),
    help="Also write the vectors as .nc (xarray), .txt (OpenPIV) or .mat (PIVlab); repeatable.",
)
@click.option("--pixel-size-m", type=POSITIVE, default=None, help="Exports: metres per pixel.")
@click.option("--dt-s", type=POSITIVE, default=None, help="Exports: seconds between A and B.")
@overwrite_option
@handle_errors
def analyze(
    image_a,
    image_b,
    output,
    window,
    overlap,
    passes,
    first_window,
    outlier_eps,
    outlier_threshold,
    exports,
    pixel_size_m,
    dt_s,
    overwrite,
):
    """Correlate two grey TIFF frames A and B into a displacement field (HDF5).

    Vectors are at window centres, x along image columns and y along rows (pixels; pixel
    (row i, column j) covers [j, j+1) x [i, i+1)); dx, dy move B relative to A.

    \b
    Example:
      rimcl piv analyze run_field_A.tif run_field_B.tif -o vectors.h5 --window 32 --passes 3
    """
    from rimcl.piv.analysis import PivSettings
    from rimcl.piv.export import run_analyze

    settings = PivSettings(
        window=window,
        overlap=overlap,
        passes=passes,
        first_window=first_window,
        outlier_eps=outlier_eps,
        outlier_threshold=outlier_threshold,
    )
    result = run_analyze(
        image_a, image_b, output, settings, exports, pixel_size_m, dt_s, overwrite=overwrite
    )
    rows, cols = result.dx.shape
    invalid = int(np.count_nonzero(~result.valid))
    click.echo(
        f"{rows} x {cols} vectors ({result.window} px windows, overlap {overlap:g}), "
        f"{invalid} invalid, {int(np.count_nonzero(result.replaced))} of them replaced"
    )
    if result.valid.any():
        mean_x, mean_y = (float(np.mean(d[result.valid])) for d in (result.dx, result.dy))
        click.echo(f"mean displacement of the valid vectors dx {mean_x:.4g} px, dy {mean_y:.4g} px")
    else:
        click.echo("mean displacement n/a: no window holds particle signal in both frames")
    times = ", ".join(f"{seconds:.3f}" for seconds in result.pass_seconds)
    click.echo(f"seconds per pass: {times}")
    click.echo("wrote " + ", ".join(str(path) for path in (output, *exports)))


@piv.command()
@field_option
@case_option
@k_rho_option
@click.option(
    "--pixels", type=COUNT, default=512, show_default=True, help="Pixels across the field of view."
)
@click.option(
    "--density",
    type=POSITIVE,
    default=0.03,
    show_default=True,
    help="Particle images per pixel in the sheet.",
)
@click.option(
    "--diameter",
    type=POSITIVE,
    default=3.0,
    show_default=True,
    help="Particle image diameter d = 4σ (px).",
)
@click.option(
    "--sheet-thickness",
    type=POSITIVE,
    default=None,
    help="Light sheet 1/e² thickness (field length units) [default: 8 pixels].",
)
@click.option("--bit-depth", type=click.IntRange(8, 16), default=16, show_default=True)
@click.option(
    "--peak-fraction",
    type=POSITIVE,
    default=0.5,
    show_default=True,
    help="Peak of an isolated in-focus particle, fraction of full scale.",
)
@click.option(
    "--camera",
    type=click.Choice(["plane", "pupil"]),
    default="plane",
    show_default=True,
    help="plane: M×M rays to the exit plane (the paper); pupil: rays over a lens aperture.",
)
@click.option("--fan", type=COUNT, default=8, show_default=True, help="M of the plane camera.")
@click.option(
    "--pupil-rays", type=COUNT, default=64, show_default=True, help="Rays per tracer (pupil)."
)
@click.option("--aperture-diameter", type=POSITIVE, default=None, help="Pupil diameter.")
@click.option("--focal-length", type=POSITIVE, default=None, help="With --f-number: D = F / N.")
@click.option("--f-number", type=POSITIVE, default=None, help="With --focal-length: D = F / N.")
@click.option("--camera-distance", type=POSITIVE, default=None, help="Sheet to pupil [4 L1].")
@click.option("--view-angle", type=FINITE, default=0.0, show_default=True, help="Degrees.")
@click.option(
    "--start-frame", type=INDEX, default=0, show_default=True, help="Field frame of exposure A."
)
@click.option(
    "--dt",
    type=POSITIVE,
    default=0.1,
    show_default=True,
    help="Time between exposures (0.1 on the sample: 1.5 px rms at 512 px).",
)
@click.option("--x-sheet", type=FINITE, default=None, help="Sheet centre x1 [default: scene].")
@click.option(
    "--scaling",
    type=click.Choice(["fixed", "per_image"]),
    default="fixed",
    show_default=True,
    help="fixed: one scale for all frames; per_image: each frame's brightest pixel at the peak.",
)
@click.option("--noise", is_flag=True, help="Sensor noise: shot, read noise, background, well.")
@click.option(
    "--peak-electrons",
    type=POSITIVE,
    default=10000.0,
    show_default=True,
    help="With --noise: mean e- at an in-focus particle's peak.",
)
@click.option(
    "--background-e", type=FINITE, default=0.0, show_default=True, help="With --noise: e-/px."
)
@click.option("--mie", is_flag=True, help="Weigh each ray by its Mie intensity (10 µm in air).")
@engine_option
@window_option
@overlap_option
@click.option(
    "--interp",
    type=click.Choice(["trilinear", "texture", "bspline3"]),
    default="trilinear",
    show_default=True,
    help="Interpolation of the gridded field.",
)
@precision_option
@step_option
@device_option
@seed_option
@click.option(
    "-o",
    "--output",
    "prefix",
    default="piv",
    show_default=True,
    help="Output prefix: PREFIX_{field,uniform}_{A,B}.tif and PREFIX_truth.h5.",
)
@overwrite_option
@handle_errors
def render(
    field_path,
    case,
    k_rho,
    pixels,
    density,
    diameter,
    sheet_thickness,
    bit_depth,
    peak_fraction,
    camera,
    fan,
    pupil_rays,
    aperture_diameter,
    focal_length,
    f_number,
    camera_distance,
    view_angle,
    start_frame,
    dt,
    x_sheet,
    scaling,
    noise,
    peak_electrons,
    background_e,
    mie,
    engine,
    window,
    overlap,
    interp,
    precision,
    step,
    device_spec,
    seed,
    prefix,
    overwrite,
):
    """PIV frame pairs through the field and through a uniform medium, with the truth.

    The truth file holds every tracer's positions at both exposures and the true
    displacement averaged over the interrogation windows of --window/--overlap.

    \b
    Examples:
      rimcl piv render --case C1 -o air          # air_field_A.tif ... air_truth.h5
      rimcl piv render --case C4 --camera pupil --pupil-rays 32 -o water
      rimcl piv analyze water_field_A.tif water_field_B.tif -o water_vectors.h5
    """
    from rimcl.fields.field_loading import case_arguments
    from rimcl.piv.analysis import PivSettings
    from rimcl.piv.imaging_config import PivImaging
    from rimcl.piv.render import PivConfig, run_piv_render
    from rimcl.piv.truth import check_outputs, write_piv_render
    from rimcl.scene.config import (
        CameraConfig,
        IntegratorConfig,
        MieConfig,
        RunConfig,
        SensorConfig,
    )

    check_outputs(prefix, overwrite)
    piv_config = PivConfig(
        imaging=PivImaging(
            pixels=pixels,
            density=density,
            diameter=diameter,
            sheet_thickness=sheet_thickness,
            bit_depth=bit_depth,
            peak_fraction=peak_fraction,
            scaling=scaling,
        ),
        settings=PivSettings(window=window, overlap=overlap),
        dt=dt,
        start_frame=start_frame,
        x_sheet=x_sheet,
        seed=seed,
    )
    camera_config = CameraConfig(
        kind=camera,
        fan=fan,
        pupil_rays=pupil_rays,
        aperture_diameter=aperture_diameter,
        focal_length=focal_length,
        f_number=f_number,
        distance=camera_distance,
        view_angle=view_angle,
    )
    case, k_rho = case_arguments(field_path, case, k_rho)
    result = run_piv_render(
        field_path,
        case=case,
        k_rho=k_rho,
        piv=piv_config,
        camera=camera_config,
        integrator=IntegratorConfig(interp=interp, precision=precision, step=parse_step(step)),
        run=RunConfig(device=device_spec, **({} if engine is None else {"engine": engine})),
        sensor=SensorConfig(noise=noise, peak_electrons=peak_electrons, background_e=background_e),
        mie=MieConfig(enabled=mie),
        progress=True,
    )
    paths = write_piv_render(prefix, result, overwrite=overwrite)
    truth = result.reference.truth
    click.echo(
        f"case {result.case} (G = {result.k_rho:.4g}, Δn_max = {result.delta_n_max:.3g}): "
        f"{result.config['n_tracers']} tracers × {result.camera.rays_per_tracer} rays, "
        f"frames {' x '.join(map(str, result.field.images.shape[1:]))} px"
    )
    rms = [np.sqrt(np.nanmean(truth[name] ** 2)) for name in ("dx", "dy")]
    click.echo(
        f"true displacement over {window} px windows: rms dx {rms[0]:.3g} px, dy {rms[1]:.3g} px"
    )
    click.echo(f"rays through the field: {result.field.ray_counts}")
    click.echo(f"motion: {result.motion}")
    click.echo("wrote " + ", ".join(str(path) for path in paths.values()))


@piv.command()
@field_option
@case_option
@k_rho_option
@click.option("--frames", type=click.IntRange(min=2), default=5, show_default=True)
@click.option(
    "--seeds",
    default="0",
    show_default=True,
    help="Comma-separated seeds: one independent realisation each.",
)
@click.option(
    "--pixels", type=COUNT, default=512, show_default=True, help="Pixels across the field of view."
)
@click.option("--density", type=POSITIVE, default=0.03, show_default=True, help="Per pixel.")
@click.option("--fan", type=COUNT, default=8, show_default=True, help="M: M×M rays per tracer.")
@click.option("--dt", type=POSITIVE, default=0.02, show_default=True, help="Time between frames.")
@click.option("--start-frame", type=INDEX, default=0, show_default=True)
@click.option("--length-m", type=POSITIVE, default=None, help="Metres per field length unit.")
@click.option("--time-s", type=POSITIVE, default=None, help="Seconds per field time unit.")
@click.option("--noise", is_flag=True, help="Sensor noise: shot, read noise, background, well.")
@engine_option
@device_option
@click.option("-o", "--output", "prefix", default="seq", show_default=True, help="Prefix.")
@overwrite_option
@handle_errors
def sequence(
    field_path,
    case,
    k_rho,
    frames,
    seeds,
    pixels,
    density,
    fan,
    dt,
    start_frame,
    length_m,
    time_s,
    noise,
    engine,
    device_spec,
    prefix,
    overwrite,
):
    """Time-resolved PIV: FRAMES frames DT apart per seed, dense truth, particle tables.

    Writes PREFIX_seed<s>_<k>.tif and PREFIX_seed<s>_truth.h5 per seed (truth in px per
    frame, and in m/s with --length-m and --time-s).

    \b
    Example:
      rimcl piv sequence --case C2 --frames 5 --seeds 0,1,2 -o c2
    """
    from rimcl.core.errors import RimclError
    from rimcl.fields.field_loading import case_arguments
    from rimcl.piv.imaging_config import PivImaging
    from rimcl.piv.render import PivConfig
    from rimcl.piv.sequence import (
        check_sequence_outputs,
        run_piv_sequence,
        write_piv_sequence,
    )
    from rimcl.scene.config import CameraConfig, RunConfig, SensorConfig

    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        raise RimclError(f"--seeds takes comma-separated integers, got {seeds!r}") from None
    check_sequence_outputs(prefix, seed_list, frames, overwrite)
    case, k_rho = case_arguments(field_path, case, k_rho)
    made = run_piv_sequence(
        field_path,
        case=case,
        k_rho=k_rho,
        piv=PivConfig(
            imaging=PivImaging(pixels=pixels, density=density), dt=dt, start_frame=start_frame
        ),
        frames=frames,
        seeds=seed_list,
        camera=CameraConfig(kind="plane", fan=fan),
        run=RunConfig(device=device_spec, **({} if engine is None else {"engine": engine})),
        sensor=SensorConfig(noise=noise),
        length_m=length_m,
        time_s=time_s,
        progress=True,
    )
    for result in made:
        paths = write_piv_sequence(prefix, result, overwrite=overwrite)
        rms = np.sqrt(np.mean(result.truth_px**2, axis=(0, 1, 2)))
        click.echo(
            f"seed {result.seed}: {result.config['n_tracers']} tracers, {frames} frames; "
            f"dense truth rms dx {rms[0]:.3g}, dy {rms[1]:.3g} px per frame; wrote "
            f"{paths[0].name} .. {paths[-1].name}"
        )

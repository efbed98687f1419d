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
from rimcl.study.summary_format import number

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
@click.option(
    "--orientation",
    type=click.Choice(["y-up", "y-down"]),
    default="y-up",
    show_default=True,
    help="Exports .txt and .mat: y and v up the frame (OpenPIV after transform_coordinates, "
    "PIVlab's y to the top) or down it (image coordinates).",
)
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
    orientation,
    overwrite,
):
    """Correlate two grey TIFF frames A and B into a displacement field (HDF5).

    Vectors are at window centres, x along image columns and y along rows (pixels; pixel
    centres at integer coordinates: pixel (row i, column j) is at (x, y) = (j, i) and
    covers [j - 1/2, j + 1/2) x [i - 1/2, i + 1/2)); dx, dy move B relative to A.

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
        image_a,
        image_b,
        output,
        settings,
        exports,
        pixel_size_m,
        dt_s,
        overwrite=overwrite,
        orientation=orientation,
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


#: ``rimcl piv render`` option -> scene key it overrides (the rest are the command's own)
RENDER_SCENE_KEYS = {
    "field_path": "field.path",
    "length_m": "field.length_m",
    "time_s": "field.time_s",
    "start_frame": "field.start_frame",
    "x_sheet": "field.x_sheet",
    "pixels": "piv.pixels",
    "density": "piv.density",
    "diameter": "piv.diameter",
    "sheet_thickness": "piv.sheet_thickness",
    "bit_depth": "piv.bit_depth",
    "rays": "piv.rays",
    "dt": "piv.dt",
    "window": "piv.window",
    "overlap": "piv.overlap",
    "passes": "piv.passes",
    "camera": "camera.kind",
    "aperture_diameter": "camera.aperture_diameter",
    "focal_length": "camera.focal_length",
    "f_number": "camera.f_number",
    "camera_distance": "camera.distance",
    "view_angle": "camera.view_angle",
    "interp": "integrator.interp",
    "precision": "integrator.precision",
    "device_spec": "run.device",
    "seed": "tracers.seed",
    "noise": "sensor.noise",
    "peak_electrons": "sensor.peak_electrons",
    "background_e": "sensor.background_e",
    "mie": "mie.enabled",
    "engine": "run.engine",
}


#: The options that set PIV frames (``rimcl piv render`` and ``rimcl piv sequence``), top
#: down: the scene file, field and case, the [piv] section, camera, sensor, integrator, run.
_FRAME_OPTIONS = (
    scene_options,
    field_option,
    case_option,
    k_rho_option,
    click.option("--pixels", type=COUNT, help="Pixels across the field of view [piv.pixels]."),
    click.option(
        "--density", type=POSITIVE, help="Particle images per pixel in the sheet [piv.density]."
    ),
    click.option(
        "--diameter", type=POSITIVE, help="Particle image diameter d = 4σ, px [piv.diameter]."
    ),
    click.option(
        "--sheet-thickness",
        type=POSITIVE,
        help="Light sheet 1/e² thickness, field length units [piv.sheet_thickness].",
    ),
    click.option("--bit-depth", type=click.IntRange(8, 16), help="Bits per pixel [piv.bit_depth]."),
    click.option(
        "--peak-fraction",
        type=POSITIVE,
        default=0.5,
        show_default=True,
        help="Peak of an isolated in-focus particle, fraction of full scale.",
    ),
    click.option(
        "--camera",
        type=click.Choice(["plane", "pupil", "lens"]),
        help="plane: rays to the exit plane (the paper); pupil: rays over an aperture; lens: a "
        "real lens in physical units (needs field.length_m) [camera.kind].",
    ),
    click.option(
        "--rays",
        type=COUNT,
        help="Rays per tracer (a plane camera: a fan of round(√rays) per side) [piv.rays].",
    ),
    click.option(
        "--fan",
        type=COUNT,
        help="Plane camera: M×M rays per tracer (--rays M²); alone: the plane camera.",
    ),
    click.option(
        "--pupil-rays", type=COUNT, help="Pupil or lens camera: rays per tracer (--rays)."
    ),
    click.option(
        "--aperture-diameter", type=POSITIVE, help="Pupil diameter [camera.aperture_diameter]."
    ),
    click.option("--focal-length", type=POSITIVE, help="With --f-number: D = F / N."),
    click.option(
        "--f-number", type=POSITIVE, help="With --focal-length: D = F / N [camera.f_number]."
    ),
    click.option("--camera-distance", type=POSITIVE, help="Sheet to pupil [camera.distance]."),
    click.option("--view-angle", type=FINITE, help="Degrees [camera.view_angle]."),
    click.option(
        "--length-m", type=POSITIVE, help="Metres per field length unit [field.length_m]."
    ),
    click.option("--time-s", type=POSITIVE, help="Seconds per field time unit [field.time_s]."),
    click.option(
        "--start-frame", type=INDEX, help="Field frame of exposure A [field.start_frame]."
    ),
    click.option(
        "--dt",
        type=POSITIVE,
        help="Time between exposures (0.1 on the sample: 1.5 px rms at 512 px) [piv.dt].",
    ),
    click.option("--x-sheet", type=FINITE, help="Sheet centre x1 [field.x_sheet]."),
    click.option(
        "--scaling",
        type=click.Choice(["fixed", "per_image"]),
        default="fixed",
        show_default=True,
        help="fixed: one scale for all frames; per_image: each frame's brightest pixel at "
        "the peak.",
    ),
    click.option(
        "--noise",
        is_flag=True,
        default=None,
        help="Sensor noise: shot, read noise, background, well [sensor.noise].",
    ),
    click.option(
        "--peak-electrons",
        type=POSITIVE,
        help="Mean e- at an in-focus particle's peak [sensor.peak_electrons].",
    ),
    click.option("--background-e", type=FINITE, help="Background, e-/px [sensor.background_e]."),
    click.option(
        "--mie",
        is_flag=True,
        default=None,
        help="Weigh each ray by its Mie intensity [mie.enabled].",
    ),
    engine_option,
    click.option(
        "--interp",
        type=click.Choice(["trilinear", "texture", "bspline3"]),
        help="Interpolation of the gridded field [integrator.interp].",
    ),
    click.option(
        "--precision",
        type=click.Choice(["f32", "f32c", "f64"]),
        help="Accumulation precision [integrator.precision].",
    ),
    measure_step_option,
    device_option,
    click.option("--seed", type=INDEX, help="Random seed of the tracers [tracers.seed]."),
)


def piv_frame_options(command):
    """Decorate ``command`` with :data:`_FRAME_OPTIONS` (listed top down)."""
    for option in reversed(_FRAME_OPTIONS):
        command = option(command)
    return command


def frame_configs(scene_file, scene_option, case, k_rho, peak_fraction, scaling, step, options):
    """The scene, case and PIV configuration that :data:`_FRAME_OPTIONS` set.

    Returns
    -------
    scene : dict
    case : str
    k_rho : float or None
    piv : rimcl.piv.render.PivConfig
    configs : dict
        ``camera``, ``integrator``, ``fluid``, ``run``, ``sensor``, ``mie``.
    """
    import dataclasses

    from rimcl.piv.study import configs_from_study
    from rimcl.scene.command import command_case
    from rimcl.scene.study_config import StudyConfig

    fan, pupil_rays = options.pop("fan"), options.pop("pupil_rays")
    given = [
        name
        for name, v in (("--rays", options["rays"]), ("--fan", fan), ("--pupil-rays", pupil_rays))
        if v is not None
    ]
    if len(given) > 1:
        raise click.UsageError(f"{' and '.join(given)} both set the rays per tracer: give one")
    if fan is not None or pupil_rays is not None:
        options["rays"] = fan**2 if fan is not None else pupil_rays
    if options["camera"] is None and (fan is not None or pupil_rays is not None):
        # --fan alone asks for the plane camera (--pupil-rays for the pupil), as in rimcl study
        options["camera"] = "plane" if fan is not None else "pupil"
    overrides = {RENDER_SCENE_KEYS[name]: value for name, value in options.items()}
    if step is not None:
        overrides["integrator.step"] = step
    scene = command_scene(scene_file, scene_option, overrides, "piv")
    case, k_rho = command_case(scene, case, k_rho)
    piv_config, configs = configs_from_study(StudyConfig.from_scene(scene))
    piv_config = dataclasses.replace(
        piv_config,
        imaging=dataclasses.replace(
            piv_config.imaging, peak_fraction=peak_fraction, scaling=scaling
        ),
    )
    return scene, case, k_rho, piv_config, configs


@piv.command()
@piv_frame_options
@click.option(
    "--window", type=COUNT, help="Interrogation window of the last pass, px [piv.window]."
)
@click.option("--overlap", type=NON_NEGATIVE, help="Window overlap, fraction [piv.overlap].")
@click.option("--passes", type=COUNT, help="Correlation passes [piv.passes].")
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
    scene_file,
    scene_option,
    case,
    k_rho,
    peak_fraction,
    scaling,
    step,
    prefix,
    overwrite,
    **options,
):
    """PIV frame pairs of one case from a scene (SCENE_FILE, default: the default scene),
    through the field and through a uniform medium, with the truth.

    Options override the scene's keys (named in brackets): the [piv] section, the field,
    camera, integrator and seed the PTV cases of a study use too. The case is --case, else
    the scene's first case other than C0 (the default scene: C1, air). The truth file
    holds every tracer's positions at both exposures and the true displacement averaged
    over the interrogation windows.

    \b
    Examples:
      rimcl piv render --case C1 -o air          # air_field_A.tif ... air_truth.h5
      rimcl piv render scene.toml --case C4 -o water
      rimcl piv analyze water_field_A.tif water_field_B.tif -o water_vectors.h5
    """
    from rimcl.piv.render import run_piv_render
    from rimcl.piv.truth import check_outputs, write_piv_render

    check_outputs(prefix, overwrite)
    scene, case, k_rho, piv_config, configs = frame_configs(
        scene_file, scene_option, case, k_rho, peak_fraction, scaling, step, options
    )
    check_outputs(prefix, overwrite, [scene["field"]["path"], scene_file, scene_option])
    result = run_piv_render(
        scene["field"]["path"] or None,
        case=case,
        k_rho=k_rho,
        piv=piv_config,
        progress=True,
        **configs,
    )
    paths = write_piv_render(prefix, result, overwrite=overwrite)
    truth = result.reference.truth
    click.echo(
        f"case {result.case} (G = {result.k_rho:.4g}, Δn_max = {result.delta_n_max:.3g}): "
        f"{result.config['n_tracers']} tracers × {result.camera.rays_per_tracer} rays, "
        f"frames {' x '.join(map(str, result.field.images.shape[1:]))} px"
    )
    rms = [np.sqrt(np.nanmean(truth[name] ** 2)) for name in ("dx", "dy")]
    speed = ""  # in mm/s too where the field's scales are known
    if result.m_s_per_px is not None:
        mm_s = [value * result.m_s_per_px * 1e3 for value in rms]
        speed = f" ({mm_s[0]:.3g} and {mm_s[1]:.3g} mm/s)"
    click.echo(
        f"true displacement over {piv_config.settings.window} px windows: rms dx {rms[0]:.3g} px, "
        f"dy {rms[1]:.3g} px{speed}"
    )
    click.echo(f"rays through the field: {result.field.ray_counts}")
    click.echo(f"motion: {result.motion}")
    click.echo("wrote " + ", ".join(str(path) for path in paths.values()))


@piv.command()
@piv_frame_options
@click.option("--frames", type=click.IntRange(min=2), default=5, show_default=True)
@click.option(
    "--seeds",
    default="0",
    show_default=True,
    help="Comma-separated seeds: one independent realisation each.",
)
@click.option("-o", "--output", "prefix", default="seq", show_default=True, help="Prefix.")
@overwrite_option
@handle_errors
def sequence(
    scene_file,
    scene_option,
    case,
    k_rho,
    peak_fraction,
    scaling,
    step,
    frames,
    seeds,
    prefix,
    overwrite,
    **options,
):
    """Time-resolved PIV from a scene (SCENE_FILE, default: the default scene): FRAMES
    exposures piv.dt apart per seed, through the field and through a uniform medium (the
    reference), with the dense truth and the particle tables.

    The options and the scene are those of rimcl piv render. Writes
    PREFIX_seed<s>_<k>.tif (through the field), PREFIX_seed<s>_uniform_<k>.tif (the same
    tracers and noise through the uniform medium) and PREFIX_seed<s>_truth.h5 per seed
    (truth in px per frame, and in m/s with the scene's field.length_m and field.time_s).

    \b
    Example:
      rimcl piv sequence --case C2 --frames 5 --seeds 0,1,2 -o c2
    """
    from rimcl.core.errors import RimclError
    from rimcl.piv.sequence import open_sequence_outputs, run_piv_sequence, write_piv_sequence

    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        raise RimclError(f"--seeds takes comma-separated integers, got {seeds!r}") from None
    if not seed_list or min(seed_list) < 0 or len(set(seed_list)) != len(seed_list):
        raise RimclError(
            f"--seeds takes distinct comma-separated integers >= 0 (at least one), got {seeds!r}"
        )
    scene, case, k_rho, piv_config, configs = frame_configs(
        scene_file, scene_option, case, k_rho, peak_fraction, scaling, step, options
    )
    # the shipped sample's size is known (the lens camera's default): m/s on any camera
    length_m = scene["field"]["length_m"] or configs["camera"].length_m
    if scene["field"]["time_s"] is not None and length_m is None:
        raise RimclError(
            "field.time_s (--time-s) gives the truth in m/s only with the field's size: "
            "give --length-m (field.length_m) too"
        )
    inputs = [scene["field"]["path"], scene_file, scene_option]
    with open_sequence_outputs(prefix, overwrite, inputs) as outputs:
        made = run_piv_sequence(
            scene["field"]["path"] or None,
            case=case,
            k_rho=k_rho,
            piv=piv_config,
            frames=frames,
            seeds=seed_list,
            length_m=length_m,
            time_s=scene["field"]["time_s"],
            progress=True,
            **configs,
        )
        written = [(result, write_piv_sequence(outputs, result)) for result in made]
    for result, paths in written:
        rms = np.sqrt(np.mean(result.truth_px**2, axis=(0, 1, 2)))
        click.echo(
            f"seed {result.seed}: {result.config['n_tracers']} tracers, {frames} frames; "
            f"dense truth rms dx {rms[0]:.3g}, dy {rms[1]:.3g} px per frame; wrote "
            f"{paths[0].name} .. {paths[frames - 1].name} (through the field), "
            f"{paths[frames].name} .. {paths[-2].name} (uniform medium), {paths[-1].name}"
        )

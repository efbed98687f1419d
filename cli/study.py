"""``rimcl study``: the whole chain over refractive-index cases, resumable."""

from pathlib import Path

import click

from rimcl.cli.options import (
    COUNT,
    INDEX,
    NON_NEGATIVE,
    POSITIVE,
    command_scene,
    device_option,
    engine_option,
    handle_errors,
    measure_step_option,
    scene_options,
)
from rimcl.cli.piv import echo_piv_case_lines
from rimcl.cli.stats import echo_case_lines


def _case_list(_ctx, _param, value):
    if value is None:
        return None
    names = [name.strip() for name in value.split(",") if name.strip()]
    if not names:
        raise click.BadParameter("name at least one case, e.g. C0,C1,C4", param_hint="--cases")
    return names


@click.command()
@scene_options
@click.option(
    "-o",
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    help="Study directory (created if missing; a rerun resumes it).",
)
@click.option(
    "--preset",
    type=click.Choice(["paper"]),
    help="A named scene under SCENE_FILE's keys; paper: the paper's own imaging (docs: the paper).",
)
@engine_option
@click.option(
    "--mode",
    type=click.Choice(["ptv", "piv", "both", "lpt"]),
    help="PTV tracks, PIV frames, both compared, or 3-D LPT [run.mode].",
)
@click.option("--force", is_flag=True, help="Redo every case and the statistics.")
@click.option("--no-figures", is_flag=True, help="Skip the figures (stats and summary only).")
@click.option(
    "--field",
    "field_path",
    type=click.Path(dir_okay=False),
    help="Field file [scene: field.path; default: the shipped sample].",
)
@click.option(
    "--cases",
    callback=_case_list,
    help="Comma-separated cases, e.g. C0,C1,C4 or G=0.01 [scene: cases.names].",
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
@click.option("--tracers", type=COUNT, help="Tracers [tracers.count].")
@click.option("--seed", type=INDEX, help="Random seed [tracers.seed].")
@click.option(
    "--camera",
    type=click.Choice(["lens", "plane", "pupil"]),
    help="Camera model [camera.kind]; lens needs field.length_m (scene or field file; the "
    "shipped sample has one).",
)
@click.option(
    "--fan", type=COUNT, help="Plane camera rays per side [camera.fan]; alone: the plane camera."
)
@click.option("--renderer", type=click.Choice(["exact", "paper"]), help="Renderer [renderer.kind].")
@click.option("--pixels", type=COUNT, help="Pixels across [renderer.pixels].")
@click.option("--threshold", type=NON_NEGATIVE, help="Grey threshold, counts [renderer.threshold].")
@click.option(
    "--precision",
    type=click.Choice(["f32", "f32c", "f64"]),
    help="Accumulation precision [integrator.precision].",
)
@measure_step_option
@device_option
@click.option(
    "--scheduler",
    metavar="local:N|tcp://HOST:PORT",
    help="Measure on Dask: N worker processes here, or a running scheduler [run.scheduler].",
)
@click.option(
    "--sensitivity",
    is_flag=True,
    help="Measure every case again with the other interpolation and 4x the rays: their "
    "part of the sensitivity band (every study has the threshold x1/2 and x2) "
    "[run.sensitivity].",
)
@click.option("--no-progress", is_flag=True, help="No progress bars.")
@handle_errors
def study(
    scene_file,
    scene_option,
    out_dir,
    preset,
    engine,
    mode,
    force,
    no_figures,
    field_path,
    cases,
    length_m,
    time_s,
    tracers,
    seed,
    camera,
    fan,
    renderer,
    pixels,
    threshold,
    precision,
    step,
    device_spec,
    scheduler,
    sensitivity,
    no_progress,
):
    """Run the whole chain (trace, render, centroid, track, statistics, figures) over the
    refractive-index cases of SCENE_FILE (default: C0-C4 on the shipped sample) into
    --out DIR.

    DIR receives scene.toml (the scene used), cases/<case>.h5 (render tables),
    stats.json, figures/ and summary.md. A rerun skips finished cases; --force redoes
    all. Options override the scene's keys (named in brackets).
    """
    from rimcl.scene.study_config import StudyConfig
    from rimcl.study.run import run_study

    if out_dir is None:
        raise click.UsageError("give the study directory with --out DIR")
    overrides = {
        "field.path": field_path,
        "cases.names": cases,
        "field.length_m": length_m,
        "field.time_s": time_s,
        "tracers.count": tracers,
        "tracers.seed": seed,
        "camera.kind": camera,
        "camera.fan": fan,
        "renderer.kind": renderer,
        "renderer.pixels": pixels,
        "renderer.threshold": threshold,
        "integrator.precision": precision,
        "integrator.step": step,
        "run.device": device_spec,
        "run.engine": engine,
        "run.mode": mode,
        "run.scheduler": scheduler,
        "run.sensitivity": sensitivity or None,  # a scene file may ask for it
    }
    study = StudyConfig.from_scene(
        command_scene(scene_file, scene_option, overrides, "study", preset=preset)
    )
    if study.run.mode == "piv":
        ignored = [
            option
            for option, value in (
                ("--tracers", tracers),
                ("--fan", fan),
                ("--renderer", renderer),
                ("--pixels", pixels),
                ("--threshold", threshold),
                ("--engine", engine),
            )
            if value is not None
        ]
        if ignored:
            click.echo(
                f"note: {', '.join(ignored)} set the PTV cases, which --mode piv does not run; "
                "PIV frames take the [piv] keys (piv.pixels, piv.rays, piv.density)"
            )
    result = run_study(
        study,
        out_dir,
        force=force,
        figures=not no_figures,
        progress=not no_progress,
        report=click.echo,
    )
    echo_case_lines({"cases": [case for case in result.stats["cases"] if "velocity" in case]})
    echo_piv_case_lines(result.stats)
    if "lpt" in result.stats:
        from rimcl.lpt.run import summary_lines

        for line in summary_lines(result.stats["lpt"]):
            click.echo(line)
    else:
        from rimcl.study.answer import answer_lines, scene_warnings

        for line in answer_lines(result.stats)[2:]:
            if line:
                click.echo(line)
        for warning in scene_warnings(result.stats, study):
            click.echo(f"warning: {warning}")
    click.echo(
        f"{len(result.ran)} cases measured, {len(result.skipped)} kept; "
        f"{Path(out_dir) / 'summary.md'} and stats.json "
        + ("written" if result.stats_redone else "up to date")
        + f"; {result.wall_seconds:.1f} s"
    )

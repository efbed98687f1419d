"""``rimcl lpt``: 3-D Lagrangian particle tracking through the field (several cameras)."""

import click

from rimcl.cli.options import (
    COUNT,
    INDEX,
    POSITIVE,
    device_option,
    handle_errors,
    overwrite_option,
)

#: ``rimcl lpt run`` and ``render`` option -> scene key it overrides (as in rimcl study)
SCENE_KEYS = {
    "field_path": "field.path",
    "cases": "cases.names",
    "tracers": "tracers.count",
    "seed": "tracers.seed",
    "time_s": "field.time_s",
}


def _run(scene_path, output, device, overwrite, dataset, options):
    from pathlib import Path

    from rimcl.lpt.config import load_lpt_scene
    from rimcl.lpt.run import run_lpt, summary_lines

    overrides = {SCENE_KEYS[name]: value for name, value in options.items()}
    if overrides["field.path"]:
        # a field named on the command line is relative to where the command runs
        overrides["field.path"] = str(Path(overrides["field.path"]).resolve())
    if overrides["cases.names"] is not None:
        names = [name.strip() for name in overrides["cases.names"].split(",") if name.strip()]
        if not names:
            raise click.BadParameter("name at least one case, e.g. C1,C3", param_hint="--cases")
        overrides["cases.names"] = names
    scene = load_lpt_scene(scene_path, overrides)

    def progress(case, frame, frames):
        click.echo(f"{case}: frame {frame}/{frames}", err=True)

    document = run_lpt(
        scene,
        output,
        device=device or scene.measure.run.device,
        progress=progress,
        overwrite=overwrite,
        dataset=dataset,
    )
    for line in summary_lines(document):
        click.echo(line)
    click.echo(f"wrote {output}")


def _lpt_options(command):
    """The scene file, output and the options that override its keys (as rimcl study's)."""
    options = (
        click.argument("scene", required=False, type=click.Path(dir_okay=False)),
        click.option(
            "-o", "--output", default="lpt_out", show_default=True, help="Output directory."
        ),
        click.option(
            "--field",
            "field_path",
            type=click.Path(dir_okay=False),
            help="Field file with 3-D velocity [field.path; default: the built-in flow].",
        ),
        click.option(
            "--cases", help="Comma-separated cases, e.g. C1,C3 or dT=3 [cases.names; C1,C2,C3]."
        ),
        click.option("--tracers", type=COUNT, help="Tracers in the volume [tracers.count]."),
        click.option("--seed", type=INDEX, help="Random seed of the tracers [tracers.seed]."),
        click.option(
            "--time-s",
            type=POSITIVE,
            help="Seconds per field time unit: velocities in mm/s [field.time_s].",
        ),
        device_option,
        overwrite_option,
    )
    for option in reversed(options):
        command = option(command)
    return command


@click.group()
def lpt():
    """3-D particle tracking: camera rigs, calibration, triangulation, tracks, datasets."""


@lpt.command("run")
@_lpt_options
@handle_errors
def run_command(scene, output, device_spec, overwrite, **options):
    """Measure an LPT scene (default: the lpt-challenge rig on the built-in flow).

    Options override the scene's keys (named in brackets); keys LPT does not use are
    refused (docs: reference/scene).

    \b
    Example:
      rimcl lpt run --tracers 50 --cases C3 -o lpt_small
    """
    _run(scene, output, device_spec, overwrite, False, options)


@lpt.command("render")
@_lpt_options
@handle_errors
def render_command(scene, output, device_spec, overwrite, **options):
    """Measure an LPT scene and write datasets for LPT codes: 16-bit TIFFs per camera and
    frame (through the field and the uniform fluid), calibration points, pinhole
    parameters and truth tracks. Options as rimcl lpt run."""
    _run(scene, output, device_spec, overwrite, True, options)


@lpt.command("track")
@click.argument("dataset", type=click.Path(file_okay=False, exists=True))
@click.option(
    "--with",
    "tracker",
    type=click.Choice(["openlpt"]),
    default="openlpt",
    show_default=True,
    help="The LPT code to run (OpenLPT's Shake-the-Box: pip install 'rimcl[openlpt]').",
)
@click.option(
    "--frames",
    "kinds",
    type=click.Choice(["both", "uniform", "field"]),
    default="both",
    show_default=True,
    help="Which frames to track: through the uniform fluid, through the field, or both "
    "(both gives the refraction error the tracker sees).",
)
@click.option(
    "--timeout", default=3600.0, show_default=True, help="Longest tracker run (s) per kind."
)
@handle_errors
def track_command(dataset, tracker, kinds, timeout):
    """Track a dataset of 'rimcl lpt render' (OUT/dataset/<case>) with an LPT code and
    compare its tracks with the truth: tracks found, ghosts, position, velocity and
    acceleration errors (written to DATASET/openlpt/track_stats.json)."""
    from rimcl.lpt.openlpt_track import summary_lines, track_dataset

    chosen = ("uniform", "field") if kinds == "both" else (kinds,)
    stats = track_dataset(
        dataset, chosen, timeout_s=timeout, progress=lambda line: click.echo(line, err=True)
    )
    for line in summary_lines(stats):
        click.echo(line)

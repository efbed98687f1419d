"""``rimcl lpt``: 3-D Lagrangian particle tracking through the field (several cameras)."""

import click

from rimcl.cli.options import device_option, handle_errors, overwrite_option


def _run(scene_path, output, device, overwrite, dataset):
    from rimcl.lpt.config import load_lpt_scene
    from rimcl.lpt.run import run_lpt, summary_lines

    scene = load_lpt_scene(scene_path)

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


@click.group()
def lpt():
    """3-D particle tracking: camera rigs, calibration, triangulation, tracks, datasets."""


@lpt.command("run")
@click.argument("scene", required=False, type=click.Path(dir_okay=False))
@click.option("-o", "--output", default="lpt_out", show_default=True, help="Output directory.")
@device_option
@overwrite_option
@handle_errors
def run_command(scene, output, device_spec, overwrite):
    """Measure an LPT scene (default: the lpt-challenge rig on the built-in flow)."""
    _run(scene, output, device_spec, overwrite, dataset=False)


@lpt.command("render")
@click.argument("scene", required=False, type=click.Path(dir_okay=False))
@click.option("-o", "--output", default="lpt_out", show_default=True, help="Output directory.")
@device_option
@overwrite_option
@handle_errors
def render_command(scene, output, device_spec, overwrite):
    """Measure an LPT scene and write datasets for LPT codes: 16-bit TIFFs per camera and
    frame (through the field and the uniform fluid), calibration points, pinhole
    parameters and truth tracks."""
    _run(scene, output, device_spec, overwrite, dataset=True)


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

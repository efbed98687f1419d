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

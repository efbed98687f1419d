"""``rimcl stats``: error statistics and figures from ``rimcl render`` files."""

import click

from rimcl.cli.options import handle_errors, overwrite_option
from rimcl.summary import number, percent


def echo_case_lines(stats):
    """One line per case: tracers used, position-error peak, u3 and a3 errors."""
    for case in stats["cases"]:
        velocity, acceleration = case["velocity"]["u3"], case["acceleration"]["a3"]
        click.echo(
            f"{case['name']:>8}  G = {case['G']:.3g}: {case['n_used']}/{case['n_tracers']} "
            f"tracers, |ε_x| peak {number(case['position_error_peak_over_L'])} L, "
            f"u3 {percent(velocity['systematic'])} ± {percent(velocity['random'])}, "
            f"a3 {percent(acceleration['systematic'])} ± {percent(acceleration['random'])}"
        )


@click.command()
@click.argument("render_files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False),
    help="Output directory: stats.json and figures/ (created if missing).",
)
@click.option("--no-figures", is_flag=True, help="Write stats.json only.")
@overwrite_option
@handle_errors
def stats(render_files, out_dir, no_figures, overwrite):
    """Error statistics (stats.json) and figures from rimcl render files, one per case.

    Relative errors are fractions; positions are in units of the traced depth L. Lines
    printed per case: systematic ± random relative error (mean ± std of ε/truth).
    """
    from rimcl.stats import run_stats

    document = run_stats(render_files, out_dir, overwrite=overwrite, figures=not no_figures)
    echo_case_lines(document)
    click.echo(f"wrote {out_dir}/stats.json" + ("" if no_figures else f" and {out_dir}/figures/"))

"""``rimcl stats``: error statistics and figures from ``rimcl render`` files."""

import click

from rimcl.cli.options import handle_errors, overwrite_option
from rimcl.study.summary import number, percent


def echo_case_lines(stats):
    """One line per case: tracers used, position-error peak, and the converging headline
    rms(ε)/rms(truth) of u3 and a3 (fitted where the tracks allow) with 95 % intervals."""
    for case in stats["cases"]:
        g = "" if case["G"] is None else f"G = {case['G']:.3g}, "
        if case.get("not_resolved"):
            click.echo(
                f"{case['name']:>8}  {g}Δn_max = {number(case['delta_n_max'])}: "
                f"{case['n_used']}/{case['n_tracers']} tracers, errors n/a: {case['not_resolved']}"
            )
            continue
        parts, floor = _headline_parts(case), _headline_parts(case.get("noise_floor"))
        click.echo(
            f"{case['name']:>8}  {g}Δn_max = {number(case['delta_n_max'])}: "
            f"{case['n_used']}/{case['n_tracers']} tracers, |ε_x| peak "
            f"{number(case['position_error_peak_over_L'])} L, rms(ε)/rms(truth): "
            + ", ".join(parts)
            + (f"; noise floor (camera alone): {', '.join(floor)}" if floor else "")
        )


def _headline_parts(block):
    """``u3 0.1 % [lo, hi] (fit)`` and the same for ``a3`` of a stats block (a case, or its
    ``noise_floor``), fitted where the tracks allow; [] for no block."""
    parts = []
    for group, component in (
        ("velocity_fit", "u3"),
        ("velocity", "u3"),
        ("acceleration_fit", "a3"),
        ("acceleration", "a3"),
    ):
        if group not in (block or {}) or any(p.startswith(component) for p in parts):
            continue
        summary = block[group][component]
        interval = summary.get("ci95", {}).get("rms_normalized")
        shown = percent(summary["rms_normalized"])
        if interval is not None and None not in interval:
            shown += f" [{percent(interval[0])}, {percent(interval[1])}]"
        parts.append(f"{component} {shown}" + (" (fit)" if group.endswith("_fit") else ""))
    return parts


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
@click.option(
    "--mixed-scenes",
    is_flag=True,
    help="Compare render files of different scenes (pixels, tracers, fan, frames...); "
    "refused otherwise.",
)
@overwrite_option
@handle_errors
def stats(render_files, out_dir, no_figures, mixed_scenes, overwrite):
    """Error statistics (stats.json) and figures from rimcl render files, one per case.

    Relative errors are fractions; positions are in units of the traced depth L. Lines
    printed per case: systematic ± random relative error (mean ± std of ε/truth).
    """
    from rimcl.stats.document import run_stats

    document = run_stats(
        render_files, out_dir, overwrite=overwrite, figures=not no_figures, mixed=mixed_scenes
    )
    echo_case_lines(document)
    click.echo(f"wrote {out_dir}/stats.json" + ("" if no_figures else f" and {out_dir}/figures/"))

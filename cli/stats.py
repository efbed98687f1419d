"""``rimcl stats``: error statistics and figures from ``rimcl render`` files."""

import click

from rimcl.cli.options import handle_errors, overwrite_option
from rimcl.study.summary_format import number, percent

#: What a user can change when a case keeps no tracer, by the flag that excluded them.
_REMEDIES = {
    "no_rays": "no ray reached the image: more rays per tracer (--fan, camera.pupil_rays)",
    "below_threshold": "no pixel above the grey threshold: a lower threshold (--threshold, "
    "cases.thresholds) or brighter tracers (sensor.peak_electrons)",
    "split": "each image broke into pieces (the caustics of strong refraction): more rays per "
    "tracer (a larger --fan; the paper's fan is 100) or the lens camera (--camera lens)",
    "touches_edge": "images wider than their window: a larger renderer.max_window",
    "rays_outside_window": "images wider than their window: a larger renderer.max_window",
    "outside_field": "tracers left the field of view: a larger tracers.margin or fewer time.frames",
}


def no_tracer_hint(case):
    """The line that says why a case kept no tracer and what to change, or None."""
    if case.get("n_used") or not case.get("n_tracers"):
        return None
    counts = {name: n for name, n in (case.get("n_excluded") or {}).items() if n}
    causes = sorted(counts, key=counts.get, reverse=True)
    reasons = "; ".join(
        f"{counts[name]} {name}: {_REMEDIES[name]}" for name in causes if name in _REMEDIES
    )
    return f"{'':>8}  {case['name']} kept no tracer, so its errors are n/a" + (
        f" ({reasons})" if reasons else ""
    )


def echo_case_lines(stats):
    """One line per case: tracers used, position-error peak, and rms(ε)/rms(truth) of u3
    and a3 (fitted where the tracks allow) with 95 % intervals; one that has not converged
    (a jump, a few tracers or a heavy tail) is marked † with the median and IQR of
    ε/truth beside it."""
    for case in stats["cases"]:
        g = "" if case["G"] is None else f"G = {case['G']:.3g}, "
        if case.get("not_resolved"):
            click.echo(
                f"{case['name']:>8}  {g}Δn_max = {number(case['delta_n_max'])}: "
                f"{case['n_used']}/{case['n_tracers']} tracers, errors n/a: {case['not_resolved']}"
            )
            hint = no_tracer_hint(case)
            if hint:
                click.echo(hint)
            continue
        parts, floor = _headline_parts(case), _headline_parts(case.get("noise_floor"))
        click.echo(
            f"{case['name']:>8}  {g}Δn_max = {number(case['delta_n_max'])}: "
            f"{case['n_used']}/{case['n_tracers']} tracers, |ε_x| peak "
            f"{number(case['position_error_peak_over_L'])} L, rms(ε)/rms(truth): "
            + "; ".join(parts)
            + (f"; noise floor (camera alone): {'; '.join(floor)}" if floor else "")
        )
        hint = no_tracer_hint(case)
        if hint:
            click.echo(hint)


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
        shown += " (fit)" if group.endswith("_fit") else ""
        convergence = block.get("convergence", {})
        path = f"{group}.{component}.rms_normalized"
        if path in convergence.get("not_converged", []):
            # a few tracers or a heavy tail carry it: the robust numbers beside it
            reasons = ", ".join(convergence.get("reasons", {}).get(path, []))
            shown += (
                f" † not converged ({reasons}); median ε/{component} "
                f"{percent(summary['median'])}, IQR {percent(summary['iqr'])}"
            )
        parts.append(f"{component} {shown}")
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

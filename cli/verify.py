"""``rimcl verify``: the closed-form verification suite."""

import json

import click

from rimcl.cli.options import COUNT, device_option, handle_errors

_COLUMNS = ("case", "interp", "precision", "step", "grid", "max error", "tolerance", "pass")


def _cells(row):
    return (
        row["case"],
        row["interpolation"],
        row["precision"],
        f"{row['step']:.3g}",
        row["grid"],
        f"{row['max_error']:.2e}",
        f"{row['tolerance']:.1e}",
        "yes" if row["passed"] else "NO",
    )


@click.command()
@device_option
@click.option("--rays", type=COUNT, default=16, show_default=True, help="Rays per case.")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON.")
@handle_errors
def verify(device_spec, rays, as_json):
    """Trace rays with known exact paths (uniform, GRIN rod, Maxwell fish-eye, linear
    medium), analytic in the kernel and sampled on grids, and compare.

    Exits with status 1 if any case misses its tolerance. Errors are the largest
    distance (field length units) between traced and exact exit points (image points
    for the uniform medium).
    """
    from rimcl.optics.verify import run_verification

    widths = (20, 9, 9, 8, 10, 10, 9, 4)

    def show(row):
        if not as_json:
            cells = _cells(row)
            click.echo("  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)))

    if not as_json:
        click.echo("  ".join(c.ljust(w) for c, w in zip(_COLUMNS, widths, strict=True)))
    report = run_verification(device=device_spec, rays=rays, progress=show)
    if as_json:
        click.echo(json.dumps(report, indent=2))
    else:
        conv = report["convergence"]
        ratios = ", ".join(f"{r:.1f}" for r in conv["ratios"])
        click.echo(
            f"\nconvergence ({conv['case']}, {conv['precision']}): steps {conv['steps']} -> "
            f"errors {', '.join(f'{e:.2e}' for e in conv['errors'])}; error ratio per halving "
            f"{ratios} (4th order: 16; required >= {conv['required_ratio']:g})"
        )
        drift = report["f32_drift"]
        click.echo(
            f"plain f32 drift in a uniform medium (step {drift['step']:g}, L = "
            f"{drift['length']:.4g}): |r' - r0| = {drift['f32']:.2e} (f32c: {drift['f32c']:.2e}); "
            "information only"
        )
        click.echo(f"device: {report['device']}")
        click.echo("all cases passed" if report["passed"] else "SOME CASES FAILED")
    if not report["passed"]:
        raise SystemExit(1)

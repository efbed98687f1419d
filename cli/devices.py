"""``rimcl devices``: list OpenCL devices."""

import json

import click

from rimcl.cli.options import handle_errors


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@handle_errors
def devices(as_json):
    """List OpenCL platforms and devices with their P:D index (for --device)."""
    from rimcl.core.device import list_devices

    found = list_devices()
    if as_json:
        click.echo(json.dumps(found, indent=2))
        return
    header = ("index", "platform", "device", "OpenCL", "CUs", "memory", "fp64", "images", "usable")
    rows = [header]
    for entry in found:
        mark = "*" if entry["default"] else " "
        rows.append(
            (
                mark + entry["index"],
                entry["platform"],
                entry["device"],
                entry["opencl_version"],
                str(entry["compute_units"]),
                f"{entry['global_memory_mib']} MiB",
                "yes" if entry["fp64"] else "no",
                "yes" if entry["images"] else "no",
                "yes" if entry["usable"] else f"no: {entry['problem']}",
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    for row in rows:
        click.echo(
            "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip()
        )
    click.echo(
        "* = default choice (RIMCL_DEVICE, then a usable GPU, then a usable CPU; "
        "PoCL first, newest PoCL and LLVM first)"
    )

"""``rimcl devices``: list OpenCL devices."""

import json

import click

from rimcl.cli.options import handle_errors


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@handle_errors
def devices(as_json):
    """List OpenCL platforms and devices with their P:D index (for --device)."""
    from rimcl.core.device import list_devices, select_device
    from rimcl.optics.shapes import shape_in_use

    found = list_devices()
    for entry in found:  # the trace kernels' shape: measured on first use, or the rule
        entry["kernel_shape"] = (
            shape_in_use(select_device(entry["index"])) if entry["usable"] else None
        )
    if as_json:
        click.echo(json.dumps(found, indent=2))
        return
    header = (
        "index",
        "platform",
        "device",
        "driver",
        "CUs",
        "memory",
        "fp64",
        "images",
        "usable",
        "kernel shape",
    )
    rows = [header]
    for entry in found:
        mark = "*" if entry["default"] else " "
        rows.append(
            (
                mark + entry["index"],
                entry["platform"],
                entry["device"],
                driver_text(entry),
                str(entry["compute_units"]),
                f"{entry['global_memory_mib']} MiB",
                "yes" if entry["fp64"] else "no",
                "yes" if entry["images"] else "no",
                "yes" if entry["usable"] else f"no: {entry['problem']}",
                _shape_text(entry["kernel_shape"]),
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
    click.echo(
        "kernel shape: rays per work-item, PoCL switch, work-group size of the trace kernels "
        "(and of the image kernel where measured); measured once per device on first use "
        "(rimcl bench --tune measures again), 'rule' until then"
    )


def driver_text(entry):
    """The driver of a device entry: ``PoCL 3.1+debian, LLVM 15.0.6`` for PoCL (its
    version decides the default device and the kernels' speed), else the driver version."""
    import re

    text = entry.get("platform_version", "")
    pocl = re.search(r"PoCL (\S+)", text)
    if pocl is None:
        return entry["driver_version"]
    llvm = re.search(r"LLVM ([\w.+-]+)", text)
    return f"PoCL {pocl.group(1)}" + (f", LLVM {llvm.group(1)}" if llvm else "")


def _shape_text(shape):
    if shape is None:
        return "n/a"
    from rimcl.optics.shapes import describe_shape

    return f"{describe_shape(shape)} ({shape['source']})"

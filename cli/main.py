"""Entry point of the ``rimcl`` command.

Subcommands live in their own modules and are imported only when run, so
``rimcl --help`` needs neither OpenCL nor the heavier libraries.
"""

import importlib
import logging

import click

from rimcl import __version__
from rimcl.cli.options import run_reporting_errors

# command name -> (module, attribute, one-line help)
COMMANDS = {
    "devices": ("rimcl.cli.devices", "devices", "List OpenCL platforms and devices."),
    "verify": ("rimcl.cli.verify", "verify", "Check the tracer against closed-form rays."),
    "trace": ("rimcl.cli.trace", "trace", "Trace ray fans through a field to an HDF5 file."),
    "field": ("rimcl.cli.field", "field", "Make, import, inspect and plot flow fields."),
    "render": ("rimcl.cli.render", "render", "Synthetic PTV: tracer images, centroids, tracks."),
    "stats": ("rimcl.cli.stats", "stats", "Error statistics and figures from render outputs."),
    "study": ("rimcl.cli.study", "study", "The whole chain over refractive-index cases."),
    "bench": ("rimcl.cli.bench", "bench", "Speed against accuracy of the tracing methods."),
    "piv": ("rimcl.cli.piv", "piv", "PIV: correlate image pairs; render pairs through a field."),
    "lpt": ("rimcl.cli.lpt", "lpt", "3-D particle tracking: camera rigs, calibration, datasets."),
}


class LazyGroup(click.Group):
    """A group whose subcommands are imported on first use."""

    def list_commands(self, ctx):
        return list(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        module, attr, _ = COMMANDS[name]
        return getattr(importlib.import_module(module), attr)

    def invoke(self, ctx):
        # every command, and anything between click and the command, reports failures
        # as one line (tracebacks with -v)
        return run_reporting_errors(ctx, lambda: super(LazyGroup, self).invoke(ctx))

    def format_commands(self, ctx, formatter):
        rows = [(name, help_text) for name, (_, _, help_text) in COMMANDS.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rimcl")
@click.option("-v", "--verbose", is_flag=True, help="Show tracebacks and debug logging.")
@click.pass_context
def cli(ctx, verbose):
    """rimcl: how wrong tracer measurements (PTV/PIV) become when light crosses a fluid
    whose refractive index varies in space and time.

    Select the OpenCL device with --device on each command or the RIMCL_DEVICE
    environment variable (see 'rimcl devices').
    """
    ctx.ensure_object(dict)
    ctx.obj["verbose"] = verbose
    logging.basicConfig(level=logging.DEBUG if verbose else logging.WARNING)

"""``python -m rimcl``: the same as the ``rimcl`` command."""

from rimcl.cli.main import cli

cli(prog_name="rimcl")

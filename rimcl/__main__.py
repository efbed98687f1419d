"""``python -m rimcl``: the same as the ``rimcl`` command."""

from rimcl.cli.main import cli

if __name__ == "__main__":  # not when a documentation tool imports every module
    cli(prog_name="rimcl")

"""The command line: one module per command family."""

from gpquad.cli.commands import main

__all__ = ["main"]

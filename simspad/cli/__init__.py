"""The ``simspad`` command line: every click command, option parsing and text formatting lives here."""

from simspad.cli.app import cli, main

__all__ = ["cli", "main"]

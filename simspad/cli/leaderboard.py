"""``simspad leaderboard``: build the leaderboard and print where it is."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.analysis.preview import write_short_preview
from simspad.evaluate.leaderboard import build_leaderboard


def leaderboard_from_cli(results_dirs, out_dir=None) -> Path:
    """The ``simspad leaderboard`` command (with a short GIF preview of each strip's recording, where the
    recording is found); prints the leaderboard's path last."""
    path = build_leaderboard(results_dirs, out_dir, preview=write_short_preview)
    click.echo(f"wrote {path.with_suffix('.md')} and {path.with_suffix('.csv')}")
    click.echo(f"leaderboard: {path}")
    return path

"""``simspad snr``: draw the analytic SNR-versus-flux figure."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.analysis.snr import plot_snr
from simspad.io.atomic import PNG_MAGIC, check_output_file, starts_with


def snr_from_cli(out_path) -> Path:
    """The ``simspad snr`` command."""
    path = plot_snr(check_output_file(Path(out_path), recognise=starts_with(PNG_MAGIC), what="a PNG image"))
    click.echo(f"wrote {path}")
    return path

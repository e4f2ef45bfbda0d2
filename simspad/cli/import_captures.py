"""``simspad import``: build a recording from real captures and a calibration file, say what was written."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.captures.build import import_captures
from simspad.errors import SimSpadError


def import_from_cli(calibration, out, *, compression: str = "zstd", progress: bool = True) -> Path:
    """The ``simspad import`` command: check the paths, import, print a one-line summary per sensor."""
    calibration, out = Path(calibration), Path(out)
    if out.suffix.lower() not in (".h5", ".hdf5"):
        raise SimSpadError("a recording is an HDF5 file: name it *.h5", path=out, field="--out")
    if out.exists() and out.is_dir():
        raise SimSpadError("a directory of that name exists", path=out, field="--out")
    s = import_captures(calibration, out, progress=progress, compression=compression)
    parts = [f"{s.width}x{s.height} px, {s.duration_s:.6g} s"]
    if s.n_bins:
        parts.append(f"{s.n_bins} SPAD bins")
    if s.n_frames:
        parts.append(f"{s.n_frames} frames")
    if s.n_events or s.n_events_dropped:
        parts.append(f"{s.n_events} events ({s.n_events_dropped} outside the span or the valid region)")
    parts.append(f"valid region {100 * s.valid_fraction:.1f} % of the grid")
    click.echo(f"wrote {s.path}: " + ", ".join(parts))
    return s.path

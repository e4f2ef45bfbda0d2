"""``simspad export``: write a recording in a format that event-camera and SPAD tools read.

The formats and what each writes are :data:`simspad.io.export.FORMATS`; the exporters live in
:mod:`simspad.io.export` (one module per format), dispatched by :func:`simspad.io.export.dispatch.export_recording`.
"""

from __future__ import annotations

from pathlib import Path

import click

from simspad.errors import SimSpadError
from simspad.io.export import DIRECTORY_FORMATS
from simspad.io.export.dispatch import export_recording


def export_from_cli(recording, fmt: str, out, *, packing: str, frames_format: str, flow_stride: int = 1) -> Path:
    """The ``simspad export`` command: check the paths, export, say what was written."""
    recording, out = Path(recording), Path(out)
    if not recording.is_file():
        raise SimSpadError("no such recording file", path=recording)
    if out.resolve() == recording.resolve():
        raise SimSpadError("--out would overwrite the recording being exported", path=out, field="--out")
    if fmt in DIRECTORY_FORMATS and out.exists() and not out.is_dir():
        raise SimSpadError(f"{fmt} export writes a directory, and a file of that name exists", path=out,
                           field="--out")
    if fmt not in DIRECTORY_FORMATS and out.is_dir():
        raise SimSpadError(f"{fmt} export writes a file, and a directory of that name exists", path=out,
                           field="--out")
    options = {"packing": packing, "frames_format": frames_format} if fmt == "npz" else {}
    if fmt == "dsec-flow":
        options = {"stride": flow_stride}
    path = export_recording(recording, fmt, out, **options)
    click.echo(f"wrote {path}")
    return path

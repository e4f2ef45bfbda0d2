"""Open a recording and run the exporter of the requested format (its row of :data:`simspad.io.export.EXPORTERS`)."""

from __future__ import annotations

import importlib
from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.export import EXPORTERS
from simspad.io.recording import open_recording


def exporter(fmt: str):
    """The exporter function of format ``fmt`` (its module imported now); SimSpadError naming ``--to`` and the
    known formats for another name."""
    if fmt not in EXPORTERS:
        raise SimSpadError(f"unknown export format {fmt!r} (expected one of {', '.join(EXPORTERS)})", field="--to")
    module, _, function = EXPORTERS[fmt].exporter.partition(":")
    return getattr(importlib.import_module(f"{__package__}.{module}"), function)


def export_recording(recording: str | Path, fmt: str, out: str | Path, **options) -> Path:
    """Export the recording file ``recording`` to ``out`` in format ``fmt`` (a key of ``EXPORTERS``).

    ``options`` go to the format's exporter (``chunk_events``; for npz ``packing``, ``frames_format``,
    ``chunk_bins``; for dsec-flow ``stride``).

    Raises
    ------
    SimSpadError
        Unknown format, an unreadable recording (naming file and field), or a recording without the sensor the
        format needs.
    """
    write = exporter(fmt)
    with open_recording(recording) as rec:
        return write(rec, Path(out), **options)

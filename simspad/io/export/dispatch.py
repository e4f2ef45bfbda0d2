"""Open a recording and run the exporter of the requested format (:data:`simspad.io.export.FORMATS`)."""

from __future__ import annotations

from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.export import FORMATS
from simspad.io.export.aedat4 import export_aedat4
from simspad.io.export.dsec import export_dsec
from simspad.io.export.dsec_flow import export_dsec_flow
from simspad.io.export.evt3 import export_evt3
from simspad.io.export.spad_frames import export_spad_frames
from simspad.io.recording import open_recording

_WRITERS = {"dsec": export_dsec, "aedat4": export_aedat4, "evt3": export_evt3, "npz": export_spad_frames,
            "dsec-flow": export_dsec_flow}


def export_recording(recording: str | Path, fmt: str, out: str | Path, **options) -> Path:
    """Export the recording file ``recording`` to ``out`` in format ``fmt`` (a key of ``FORMATS``).

    ``options`` go to the format's exporter (``chunk_events``; for npz ``packing``, ``frames_format``,
    ``chunk_bins``; for dsec-flow ``stride``).

    Raises
    ------
    SimSpadError
        Unknown format, an unreadable recording (naming file and field), or a recording without the sensor the
        format needs.
    """
    if fmt not in FORMATS:
        raise SimSpadError(f"unknown export format {fmt!r} (expected one of {', '.join(FORMATS)})", field="--to")
    with open_recording(recording) as rec:
        return _WRITERS[fmt](rec, Path(out), **options)

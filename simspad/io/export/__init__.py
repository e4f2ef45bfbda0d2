"""Export a recording to the formats that event-camera and SPAD tools read (``simspad export``).

One module per format, each with ``export_<format>(rec, out, …)`` that streams the recording in chunks (memory
does not grow with its length) and writes atomically (a temporary name renamed on success):

- :mod:`.dsec`: DSEC ``events.h5`` (``/events/{p,t,x,y}``, root ``ms_to_idx`` and ``t_offset``), read by DSEC's
  ``EventSlicer`` and tonic's DSEC loader;
- :mod:`.aedat4`: AEDAT 4 through the ``dv-processing`` library (optional dependency, ``simspad[export]``);
- :mod:`.evt3`: Prophesee EVT 3.0 ``.raw``, encoded here from the public format description;
- :mod:`.spad_frames`: a directory of SPAD binary frames (``.npz``, packed or unpacked), conventional frames as
  16-bit PNG or a TIFF stack, ground truth as OpenEXR.

:data:`FORMATS` lists the names; :func:`export_recording` opens a recording and dispatches.
"""

from __future__ import annotations

from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.export.aedat4 import export_aedat4
from simspad.io.export.dsec import export_dsec
from simspad.io.export.evt3 import export_evt3
from simspad.io.export.spad_frames import export_spad_frames
from simspad.io.recording import open_recording

#: Export format name → (writer, what it writes).
FORMATS = {
    "dsec": (export_dsec, "DSEC events.h5 (events/{p,t,x,y}, ms_to_idx, t_offset)"),
    "aedat4": (export_aedat4, "AEDAT 4 event stream via dv-processing"),
    "evt3": (export_evt3, "Prophesee EVT 3.0 .raw"),
    "npz": (export_spad_frames, "directory: SPAD bits .npz, frames 16-bit PNG/TIFF, ground truth EXR"),
}


def export_recording(recording: str | Path, fmt: str, out: str | Path, **options) -> Path:
    """Export the recording file ``recording`` to ``out`` in format ``fmt`` (a key of :data:`FORMATS`).

    Raises
    ------
    SimSpadError
        Unknown format, an unreadable recording (naming file and field), or a recording without the sensor the
        format needs.
    """
    if fmt not in FORMATS:
        raise SimSpadError(f"unknown export format {fmt!r} (expected one of {', '.join(FORMATS)})", field="--to")
    writer, _ = FORMATS[fmt]
    with open_recording(recording) as rec:
        return writer(rec, Path(out), **options)

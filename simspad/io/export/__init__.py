"""Export a recording to the formats that event-camera and SPAD tools read (``simspad export``).

One module per format, each with ``export_<format>(rec, out, …)`` that streams the recording in chunks (memory
does not grow with its length) and writes atomically (a temporary name renamed on success):

- :mod:`.dsec`: DSEC ``events.h5`` (``/events/{p,t,x,y}``, root ``ms_to_idx`` and ``t_offset``), read by DSEC's
  ``EventSlicer`` and tonic's DSEC loader;
- :mod:`.aedat4`: AEDAT 4 through the ``dv-processing`` library (optional dependency, ``simspad[export]``);
- :mod:`.evt3`: Prophesee EVT 3.0 ``.raw``, encoded here from the public format description;
- :mod:`.spad_frames`: a directory of SPAD binary frames (``.npz``, packed or unpacked), conventional frames as
  16-bit PNG or a TIFF stack, ground truth as OpenEXR, its geometry (instances, flow, poses) as ``.npz`` and the
  camera model in ``metadata.json``;
- :mod:`.dsec_flow`: the ground-truth motion field as DSEC's forward optical flow (16-bit PNG maps + timestamps).

:data:`EXPORTERS` is the one table of formats: name → what it writes, its exporter (``module:function`` in this
package, imported only when the format is used, so this package stays light for the command line's ``--help``)
and whether it writes a directory; :data:`FORMATS` and :data:`DIRECTORY_FORMATS` are read from it.
:func:`simspad.io.export.dispatch.export_recording` opens a recording and runs the format's exporter.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ExportFormat:
    """One export format: ``description`` (what it writes, for ``--help``), ``exporter`` (``"module:function"``
    inside :mod:`simspad.io.export`, called as ``function(rec, out, **options)``), ``directory`` (it writes a
    directory, not one file)."""

    description: str
    exporter: str
    directory: bool = False


#: Export format name → its row.
EXPORTERS: dict[str, ExportFormat] = {
    "dsec": ExportFormat("DSEC events.h5 (events/{p,t,x,y}, ms_to_idx, t_offset)", "dsec:export_dsec"),
    "aedat4": ExportFormat("AEDAT 4 event stream, through dv-processing", "aedat4:export_aedat4"),
    "evt3": ExportFormat("Prophesee EVT 3.0 .raw", "evt3:export_evt3"),
    "npz": ExportFormat("directory: SPAD bits .npz, frames as 16-bit PNG/TIFF, ground truth as OpenEXR (+ flow, "
                        "masks, camera)", "spad_frames:export_spad_frames", directory=True),
    "dsec-flow": ExportFormat("directory: ground-truth forward optical flow as DSEC's 16-bit PNG maps + timestamps",
                              "dsec_flow:export_dsec_flow", directory=True),
}
#: Export format name → what it writes (from :data:`EXPORTERS`).
FORMATS = {name: row.description for name, row in EXPORTERS.items()}
#: Formats that write a directory (the others write one file).
DIRECTORY_FORMATS = tuple(name for name, row in EXPORTERS.items() if row.directory)
#: SPAD bit layouts of the npz export: 8 pixels a byte along x, or one uint8 0/1 per pixel.
PACKINGS = ("packed", "unpacked")
#: Frame image formats of the npz export: one 16-bit PNG per frame, or one multi-page TIFF stack.
FRAME_FORMATS = ("png", "tiff")

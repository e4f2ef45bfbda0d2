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

:data:`FORMATS` names the formats (this package imports nothing heavy, so the command line can list them);
:func:`simspad.io.export.dispatch.export_recording` opens a recording and runs the right exporter.
"""

from __future__ import annotations

#: Export format name → what it writes.
FORMATS = {
    "dsec": "DSEC events.h5 (events/{p,t,x,y}, ms_to_idx, t_offset)",
    "aedat4": "AEDAT 4 event stream, through dv-processing",
    "evt3": "Prophesee EVT 3.0 .raw",
    "npz": "directory: SPAD bits .npz, frames as 16-bit PNG/TIFF, ground truth as OpenEXR (+ flow, masks, camera)",
    "dsec-flow": "directory: ground-truth forward optical flow as DSEC's 16-bit PNG maps + timestamps",
}
#: Formats that write a directory (the others write one file).
DIRECTORY_FORMATS = ("npz", "dsec-flow")
#: SPAD bit layouts of the npz export: 8 pixels a byte along x, or one uint8 0/1 per pixel.
PACKINGS = ("packed", "unpacked")
#: Frame image formats of the npz export: one 16-bit PNG per frame, or one multi-page TIFF stack.
FRAME_FORMATS = ("png", "tiff")

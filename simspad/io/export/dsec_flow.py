"""DSEC optical-flow ground truth: forward flow maps as 16-bit PNG, as the DSEC dataset distributes them.

Layout (DSEC, Gehrig et al. 2021, dsec.ifi.uzh.ch "Data Format", optical flow)::

    flow/forward/000000.png …      one 3-channel 16-bit PNG per flow map:
                                   channel 1 = round(flow_x · 128 + 2¹⁵), channel 2 = round(flow_y · 128 + 2¹⁵),
                                   channel 3 = 1 where the flow is valid, 0 elsewhere (x right, y down, px)
    flow/forward_timestamps.txt    "# from_timestamp_us, to_timestamp_us" then one line per map

DSEC's own reader decodes a map as ``flow_x = (png[..., 0] − 2¹⁵) / 128``, likewise y, ``valid = png[..., 2] > 0``.
The encoding spans ±256 px in steps of 1/128 px; larger or undefined flow is stored as invalid (0 and valid = 0).
Each map is the recording's ``/gt/flow`` (the motion field of surfaces over one ground-truth interval) or, with
``stride`` k > 1, the exact motion field from instant i to instant i + k (:meth:`GroundTruthView.flow_between`);
maps start at every k-th instant. Timestamps are µs on the recording's own time base (µs since the timeline's
t = 0), the clock of the ``dsec`` events export's ``t + t_offset``.

PNG writing goes through ``pypng`` (DSEC's readers use FreeImage or OpenCV; Pillow keeps only 8 bits of an RGB
PNG). Maps are written one at a time; the directory is built under a temporary name and renamed when complete.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import png

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path

#: DSEC's scale and offset of the 16-bit flow channels.
FLOW_SCALE = 128.0
FLOW_OFFSET = 2**15


def encode_dsec_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``[H, W, 3]`` uint16 DSEC flow image of ``flow`` (px, x right, y down) and ``valid``."""
    flow = np.asarray(flow, dtype=np.float64)
    scaled = np.rint(flow * FLOW_SCALE) + FLOW_OFFSET
    ok = np.asarray(valid, bool) & np.all(np.isfinite(scaled), axis=-1) & np.all((scaled >= 0) & (scaled <= 65535),
                                                                                  axis=-1)
    out = np.zeros(flow.shape[:2] + (3,), dtype=np.uint16)
    out[..., :2] = np.where(ok[..., None], scaled, 0).astype(np.uint16)
    out[..., 2] = ok
    return out


def _write_png16(path: Path, image: np.ndarray) -> None:
    h, w, _ = image.shape
    writer = png.Writer(width=w, height=h, greyscale=False, bitdepth=16, compression=6)
    with open(path, "wb") as f:
        writer.write(f, image.reshape(h, w * 3))


def export_dsec_flow(rec, out: Path, *, stride: int = 1) -> Path:
    """Write the recording's ground-truth motion field as DSEC forward optical flow in the directory ``out``.

    Parameters
    ----------
    rec : Recording
        An open recording whose ``/gt`` has the motion field (rendered with geometry passes).
    out : Path
        The directory to create.
    stride : int
        Ground-truth intervals per flow map (DSEC's maps span 100 ms; at 1 kHz, ``stride=100``).
    """
    if not rec.gt.has_geometry:
        raise SimSpadError("the recording has no ground-truth motion field (/gt/flow): its render had no geometry "
                           "passes", path=rec.path, field="gt/flow")
    if not (isinstance(stride, int) and stride >= 1):
        raise SimSpadError(f"must be an integer >= 1, got {stride!r}", field="--flow-stride")
    t = rec.gt.t
    starts = list(range(0, len(t) - stride, stride))
    if not starts:
        raise SimSpadError(f"the recording has {len(t)} ground-truth instants: none is followed by one {stride} "
                           "intervals later", path=rec.path, field="--flow-stride")
    with atomic_path(out) as tmp:
        forward = tmp / "flow" / "forward"
        forward.mkdir(parents=True)
        lines = ["# from_timestamp_us, to_timestamp_us"]
        for n, i in enumerate(starts):
            flow, valid = (rec.gt.flow(i), rec.gt.flow_valid(i)) if stride == 1 else rec.gt.flow_between(i, i + stride)
            _write_png16(forward / f"{n:06d}.png", encode_dsec_flow(flow, valid))
            lines.append(f"{int(round(t[i] * 1e6))}, {int(round(t[i + stride] * 1e6))}")
        (tmp / "flow" / "forward_timestamps.txt").write_text("\n".join(lines) + "\n")
    return out

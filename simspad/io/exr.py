"""OpenEXR keyframes of a render directory (docs/format.md): linear radiance R,G,B (or Y) plus optional depth Z.

Files are written atomically (temporary name, then rename) so an interrupted render never leaves a truncated
frame. Reading accepts what other renderers write: half or float pixels, ``Y`` or ``R,G,B`` channels, and a
depth channel named ``Z`` (or ``depth.Z`` / ``depth.Y`` / ``depth.T`` as written by Mitsuba's AOV film).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenEXR

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.native_output import NativeOutput, captured_native_output

RGB_CHANNELS = ("R", "G", "B")
LUMINANCE_CHANNEL = "Y"
DEPTH_CHANNELS = ("Z", "depth.Z", "depth.Y", "depth.T", "depth")
#: Optional per-pixel object id (0: static scene or no hit; k: k-th animated object), see
#: :mod:`simspad.render.reprojection`. Readers that do not need it ignore it.
OBJECT_ID_CHANNEL = "object_id"


@dataclass(frozen=True)
class ExrInfo:
    """What an EXR header says, without reading pixels.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    channels : tuple of str
        Channel names as stored.
    radiance : str
        ``"rgb"`` or ``"y"``: which radiance channels the file carries.
    depth_channel : str or None
        Name of the depth channel, if any.
    """

    width: int
    height: int
    channels: tuple[str, ...]
    radiance: str
    depth_channel: str | None


#: ZIP (lossless) must make a keyframe at least this much smaller than its raw pixels, or it is stored uncompressed.
#: Path-traced radiance is float32 noise to ZIP: on the bundled scenes it saves 1–2 % (512 × 512 office: 3.85 against
#: 4.01 MB) while decoding takes 21 ms against 2.7 ms, and every sensor pass of every lux level decodes every
#: keyframe. Flat synthetic scenes (siemens-star, fan) still shrink 1.2–1.9× and keep ZIP.
ZIP_MIN_SAVING = 0.10


def write_exr(path: str | Path, channels: dict[str, np.ndarray]) -> Path:
    """Write float32 channels ``{name: [H, W]}`` to ``path`` atomically, lossless: ZIP where it saves at least
    :data:`ZIP_MIN_SAVING` of the raw size, else uncompressed (the same pixels either way, faster to read).

    Parameters
    ----------
    path : str or Path
        Destination ``.exr`` file.
    channels : dict of str to ndarray
        Each a 2-D array of the same shape; stored as 32-bit float.
    """
    path = Path(path)
    data = {name: np.ascontiguousarray(a, dtype=np.float32) for name, a in channels.items()}
    shapes = {a.shape for a in data.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"all channels must be 2-D arrays of one shape, got {sorted(shapes)}")
    raw_bytes = sum(a.nbytes for a in data.values())
    with atomic_path(path) as tmp:
        for compression in (OpenEXR.ZIP_COMPRESSION, OpenEXR.NO_COMPRESSION):
            with OpenEXR.File({"compression": compression, "type": OpenEXR.scanlineimage}, data) as f:
                f.write(str(tmp))
            if os.path.getsize(tmp) <= (1.0 - ZIP_MIN_SAVING) * raw_bytes:
                break
    return path


def _classify(path: Path, names: tuple[str, ...]) -> tuple[str, str | None]:
    if all(c in names for c in RGB_CHANNELS):
        radiance = "rgb"
    elif LUMINANCE_CHANNEL in names:
        radiance = "y"
    else:
        raise InputError(f"no radiance channels: expected R,G,B or Y, found {', '.join(names) or 'none'}",
                         path=path, field="channels")
    depth = next((c for c in DEPTH_CHANNELS if c in names), None)
    return radiance, depth


def _unreadable(path: Path, exc: Exception, native: NativeOutput) -> str:
    """One line for an EXR the library refused: its own diagnostic (the cause) when it printed one."""
    cause = native.first_line("EXR_ERR") or native.first_line()
    cause = cause.removeprefix(f"{path}: ").strip() or str(exc)
    cause = re.sub(r"^\((EXR_ERR_\w+)\)\s*", r"\1: ", cause)  # "(EXR_ERR_X) text" → "EXR_ERR_X: text"
    return f"not a readable OpenEXR file ({cause})"


def read_exr_info(path: str | Path) -> ExrInfo:
    """Read an EXR header only. Raises :class:`InputError` if the file is missing or not an EXR."""
    path = Path(path)
    if not path.is_file():
        raise InputError("keyframe file is missing", path=path, field="file")
    error = None
    with captured_native_output() as native:  # the library prints its diagnostics itself (stdout included)
        try:
            f = OpenEXR.File(str(path), separate_channels=True, header_only=True)
            header = f.header()
        except Exception as exc:  # OpenEXR raises plain RuntimeError for corrupt or foreign files
            error = exc
    if error is not None:
        raise InputError(_unreadable(path, error, native), path=path, field="file") from None
    (x0, y0), (x1, y1) = (np.asarray(v) for v in header["dataWindow"])
    names = tuple(sorted(ch.name for ch in header["channels"]))
    radiance, depth = _classify(path, names)
    return ExrInfo(width=int(x1 - x0 + 1), height=int(y1 - y0 + 1), channels=names, radiance=radiance,
                   depth_channel=depth)


def read_exr(path: str | Path, *, rgb_planes: bool = False) -> dict[str, np.ndarray]:
    """Read an EXR keyframe as float32 arrays.

    Parameters
    ----------
    path : str or Path
    rgb_planes : bool
        Return R, G and B as the planes ``"r"``, ``"g"``, ``"b"`` the file holds instead of interleaving them
        into ``"rgb"`` (a copy of the whole image that a reader of luminance alone does not need).

    Returns
    -------
    dict
        ``"rgb"``: [H, W, 3] linear radiance (present if the file has R,G,B; or ``"r"``, ``"g"``, ``"b"``,
        [H, W] each, with ``rgb_planes``), ``"y"``: [H, W] (present if it has only Y), ``"z"``: [H, W] depth in
        scene units (m) if the file has a depth channel, ``"object_id"``: [H, W] per-pixel object id if the file
        has :data:`OBJECT_ID_CHANNEL`.
    """
    path = Path(path)
    error = None
    with captured_native_output() as native:
        try:
            f = OpenEXR.File(str(path), separate_channels=True)
            channels = {name: ch.pixels for name, ch in f.channels().items()}
        except Exception as exc:
            error = exc
    if error is not None:
        raise InputError(_unreadable(path, error, native), path=path, field="file") from None
    radiance, depth = _classify(path, tuple(channels))
    out: dict[str, np.ndarray] = {}
    if radiance == "rgb":
        planes = [channels[c].astype(np.float32, copy=False) for c in RGB_CHANNELS]
        if rgb_planes:
            out.update(zip("rgb", planes))
        else:
            out["rgb"] = np.stack(planes, axis=-1)
    else:
        out["y"] = channels[LUMINANCE_CHANNEL].astype(np.float32, copy=False)
    if depth is not None:
        out["z"] = channels[depth].astype(np.float32, copy=False)
    if OBJECT_ID_CHANNEL in channels:
        out["object_id"] = channels[OBJECT_ID_CHANNEL].astype(np.float32, copy=False)
    return out

"""Render directories (docs/format.md): ``timeline.json`` plus one OpenEXR file of linear radiance per keyframe.

``timeline.json`` holds ``format`` (:data:`TIMELINE_FORMAT`), ``version`` (:data:`TIMELINE_VERSION`), ``width``
and ``height`` in pixels, and ``keyframes = [{t (s), file (relative path), camera_to_world (4x4, optional)}]``
with strictly increasing ``t``, plus whatever a renderer records (``scene``, ``trajectory``, ``renderer``, ...;
SimSPAD's renderer adds ``source``: ``"render"`` or ``"warp"`` (synthesized by reprojection) per keyframe, and
``object_to_world`` per keyframe when the scene animates objects).
It is written last, so its presence marks a complete directory. Each keyframe EXR carries ``R,G,B`` (or ``Y``)
radiance and optionally depth ``Z`` in metres and a per-pixel ``object_id`` (:mod:`simspad.io.exr`).

:func:`read_render_dir` validates the index and every frame header; :func:`read_keyframe` reads one frame's
pixels and checks them (finite, non-negative). The interpolation in time is
:class:`simspad.radiance.timeline.Timeline`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.exr import read_exr, read_exr_info, write_exr
from simspad.io.safe_paths import confined_path

TIMELINE_FORMAT = "simspad-timeline"
TIMELINE_VERSION = 1
TIMELINE_FILE = "timeline.json"


@dataclass(frozen=True)
class RenderDirIndex:
    """What ``timeline.json`` and the frame headers of a render directory say (pixels not read).

    Attributes
    ----------
    render_dir : Path
    meta : dict
        The ``timeline.json`` content.
    width, height : int
        Image size in pixels.
    times_s : list of float
        Keyframe instants, strictly increasing, seconds.
    files : list of Path
        Keyframe EXR files, one per instant.
    poses : ndarray (K, 4, 4) or None
        Camera-to-world of each keyframe, if given.
    has_depth : bool
        Whether every keyframe carries depth.
    """

    render_dir: Path
    meta: dict
    width: int
    height: int
    times_s: list
    files: list
    poses: np.ndarray | None
    has_depth: bool


# ---------------------------------------------------------------------- reading render directories
def read_render_dir(render_dir: str | Path) -> RenderDirIndex:
    """Open and validate a render directory (docs/format.md).

    Checks ``timeline.json`` (format, version, size, keyframe instants and files, optional poses) and every
    frame's EXR header (size, channels). Pixel values (NaN, negative radiance) are checked by
    :func:`read_keyframe` as each frame is read.

    Raises
    ------
    InputError
        Naming the file and the field at fault.
    """
    render_dir = Path(render_dir)
    meta_path = render_dir / TIMELINE_FILE
    if not render_dir.is_dir():
        raise InputError("render directory does not exist", path=render_dir)
    if not meta_path.is_file():
        raise InputError(f"missing {TIMELINE_FILE}: not a render directory", path=render_dir)
    try:
        meta = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({exc})", path=meta_path) from None
    if not isinstance(meta, dict):
        raise InputError("expected a JSON object", path=meta_path)
    if meta.get("format") != TIMELINE_FORMAT:
        raise InputError(f"expected {TIMELINE_FORMAT!r}, got {meta.get('format')!r}", path=meta_path,
                         field="format")
    if meta.get("version") != TIMELINE_VERSION:
        raise InputError(f"unsupported version {meta.get('version')!r} (this reader knows {TIMELINE_VERSION})",
                         path=meta_path, field="version")
    width, height = (_positive_int(meta, key, meta_path) for key in ("width", "height"))
    keyframes = meta.get("keyframes")
    if not isinstance(keyframes, list) or not keyframes:
        raise InputError("expected a non-empty list of {t, file}", path=meta_path, field="keyframes")
    if len(keyframes) < 2:
        raise InputError("one keyframe: radiance is interpolated between keyframes, so a render directory needs at "
                         "least two (render a duration > 0)", path=meta_path, field="keyframes")

    times, files, poses = [], [], []
    for i, kf in enumerate(keyframes):
        field = f"keyframes[{i}]"
        if not isinstance(kf, dict):
            raise InputError("expected an object {t, file}", path=meta_path, field=field)
        t = kf.get("t")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise InputError(f"expected a finite time in seconds, got {t!r}", path=meta_path, field=f"{field}.t")
        if times and t <= times[-1]:
            raise InputError(f"times must be strictly increasing: {t!r} follows {times[-1]!r}", path=meta_path,
                             field=f"{field}.t")
        name = kf.get("file")
        if not isinstance(name, str) or not name:
            raise InputError("expected a frame file name", path=meta_path, field=f"{field}.file")
        file = confined_path(render_dir, name, source=meta_path, field=f"{field}.file")
        if not file.is_file():
            raise InputError(f"frame file {name!r} is missing", path=meta_path, field=f"{field}.file")
        info = read_exr_info(file)
        if (info.width, info.height) != (width, height):
            raise InputError(f"size {info.width}x{info.height} differs from timeline.json's {width}x{height}",
                             path=file, field="dataWindow")
        if "camera_to_world" in kf:
            pose = np.asarray(kf["camera_to_world"], dtype=object)
            try:
                pose = pose.astype(np.float64)
            except (TypeError, ValueError):
                pose = None
            if pose is None or pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
                raise InputError("expected a finite 4x4 matrix", path=meta_path, field=f"{field}.camera_to_world")
            poses.append(pose)
        times.append(float(t))
        files.append((file, info))
    if poses and len(poses) != len(times):
        raise InputError("camera_to_world must be given for every keyframe or for none", path=meta_path,
                         field="keyframes[].camera_to_world")
    has_depth = all(info.depth_channel is not None for _, info in files)
    return RenderDirIndex(render_dir, meta, width, height, times, [file for file, _ in files],
                          np.stack(poses) if poses else None, has_depth)


def read_keyframe(file: Path, width: int, height: int, *, rgb_planes: bool = False) -> dict[str, np.ndarray]:
    """Pixels of one keyframe EXR as :func:`simspad.io.exr.read_exr` returns them (``rgb`` or ``y``, ``z``; with
    ``rgb_planes``, ``r``, ``g``, ``b`` instead of ``rgb``).

    Raises
    ------
    InputError
        The frame's size differs from ``width`` x ``height``, its radiance is NaN, infinite or negative, or its
        depth is NaN or negative.
    """
    data = read_exr(file, rgb_planes=rgb_planes)
    radiance = [data[k] for k in ("rgb", "r", "g", "b", "y") if k in data]
    if radiance[0].shape[:2] != (height, width):
        raise InputError(f"size {radiance[0].shape[1]}x{radiance[0].shape[0]} differs from timeline.json's "
                         f"{width}x{height}", path=file, field="dataWindow")
    for values in radiance:
        _check_radiance(values, file, "Y" if "y" in data else "R,G,B")
    depth = data.get("z")
    # min ≥ 0 is False for a NaN as for a negative value: one reduction passes a good frame, the search runs after
    if depth is not None and not np.min(depth) >= 0 and (np.isnan(depth).any() or (depth < 0).any()):
        row, col = np.argwhere(np.isnan(depth) | (depth < 0))[0][:2]
        raise InputError(f"depth {depth[row, col]} at pixel (row {row}, col {col}) (expected ≥ 0 metres; 0 where "
                         "no surface)", path=file, field="Z")
    return data


def _positive_int(meta: dict, key: str, path: Path) -> int:
    value = meta.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise InputError(f"expected a positive integer, got {value!r}", path=path, field=key)
    return value


def _check_radiance(radiance: np.ndarray, file: Path, channels: str) -> None:
    if np.min(radiance) >= 0 and np.max(radiance) < np.inf:  # False for any NaN: finite and ≥ 0 everywhere
        return
    bad = ~np.isfinite(radiance)
    if bad.any():
        row, col = np.argwhere(bad)[0][:2]
        raise InputError(f"radiance is NaN or infinite at pixel (row {row}, col {col})", path=file, field=channels)
    if (radiance < 0).any():
        row, col = np.argwhere(radiance < 0)[0][:2]
        raise InputError(f"negative radiance {radiance[row, col]} at pixel (row {row}, col {col})", path=file,
                         field=channels)



# ---------------------------------------------------------------------- writing render directories
def keyframe_filename(index: int) -> str:
    """Relative path of keyframe ``index`` inside a render directory."""
    return f"frames/{index:06d}.exr"


def write_timeline_json(render_dir: str | Path, *, width: int, height: int, keyframes: list[dict],
                        **meta) -> Path:
    """Write ``timeline.json`` atomically (the last step of a render: its presence marks the directory complete).

    Parameters
    ----------
    keyframes : list of dict
        ``{"t": seconds, "file": relative path, "camera_to_world": 4x4 list (optional)}``, strictly increasing t.
    **meta
        Further top-level fields (``scene``, ``trajectory``, ``renderer``, ...); must be JSON-serialisable.
    """
    doc = {"format": TIMELINE_FORMAT, "version": TIMELINE_VERSION, "width": int(width), "height": int(height),
           "keyframes": keyframes, "radiance_units": meta.pop("radiance_units", "relative"), **meta}
    path = Path(render_dir) / TIMELINE_FILE
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    return path


def write_render_dir(render_dir: str | Path, times_s, frames, depth=None, poses=None, **meta) -> Path:
    """Write a complete render directory from arrays (tests, converters, other renderers' output).

    Parameters
    ----------
    times_s : array (K,)
        Strictly increasing instants, seconds.
    frames : array (K, H, W, 3) linear sRGB, or (K, H, W) luminance Y
    depth : array (K, H, W), optional
        Depth in metres, stored as channel ``Z``.
    poses : array (K, 4, 4), optional
        Camera-to-world matrices.
    """
    render_dir = Path(render_dir)
    times = np.asarray(times_s, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.float32)
    if np.any(np.diff(times) <= 0):
        raise ValueError("times_s must be strictly increasing")
    keyframes = []
    for i, t in enumerate(times):
        channels = ({"R": frames[i, ..., 0], "G": frames[i, ..., 1], "B": frames[i, ..., 2]} if frames.ndim == 4
                    else {"Y": frames[i]})
        if depth is not None:
            channels["Z"] = np.asarray(depth[i], dtype=np.float32)
        name = keyframe_filename(i)
        write_exr(render_dir / name, channels)
        kf = {"t": float(t), "file": name}
        if poses is not None:
            kf["camera_to_world"] = np.asarray(poses[i], dtype=np.float64).tolist()
        keyframes.append(kf)
    return write_timeline_json(render_dir, width=frames.shape[2], height=frames.shape[1], keyframes=keyframes,
                               **meta)

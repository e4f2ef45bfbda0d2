"""Geometry passes of a render directory (docs/format.md, section 2): depth and instance ids at the pixel centres,
one file per ground-truth instant, and the ``geometry`` block of ``timeline.json`` that lists them.

Ground-truth instants are the sensors' (a fixed rate from the start of the span), not keyframes, and instance
masks and motion fields cannot be interpolated between keyframes; so the renderer renders a cheap geometry pass
(1 sample per pixel, at its centre) at every ground-truth instant. Each pass is ``geometry/<index>-<key>.npz``
holding ``depth_z`` (float32 [H, W], m along the optical axis, ``inf`` where nothing is hit) and ``instance``
(uint16 [H, W], 0 where nothing is hit, k for the k-th name of ``geometry.instances``).

:func:`gt_times` is the one definition of the ground-truth grid, shared by the renderer (which renders the
passes) and the sensors (which write ``/gt``), so both land on the same instants.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.safe_paths import confined_path

#: Folder of the geometry passes inside a render directory.
GEOMETRY_DIR = "geometry"
#: Bytes per pixel of one geometry pass (float32 depth + uint16 instance, stored uncompressed).
GEOMETRY_BYTES_PER_PX = 6
#: How instants of the recording and of the render are matched, s.
TIME_MATCH_S = 1e-9


def gt_times(t0: float, t1: float, rate_hz: float) -> np.ndarray:
    """Instants ``t0 + i/rate_hz`` inside ``[t0, t1]``, s (float64; the end is included when it falls on the grid)."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise ValueError(f"gt rate must be a finite number > 0, got {rate_hz!r}")
    n = int(math.floor((t1 - t0) * rate_hz * (1 + 1e-12) + 1e-9)) + 1
    return t0 + np.arange(max(n, 0)) / rate_hz


def geometry_names(base_key: dict, times) -> list[str]:
    """Relative paths of the geometry passes at ``times`` (s): ``geometry/<index>-<16 hex of a SHA-256 over
    base_key and the instant>.npz``."""
    names = []
    for i, t in enumerate(times):
        doc = dict(base_key, t=repr(float(t)))
        key = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]
        names.append(f"{GEOMETRY_DIR}/{i:06d}-{key}.npz")
    return names


def write_geometry(path: str | Path, depth_z: np.ndarray, instance: np.ndarray) -> Path:
    """Write one geometry pass atomically (uncompressed ``.npz``: ``depth_z`` float32, ``instance`` uint16)."""
    path = Path(path)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name, a in (("depth_z", np.ascontiguousarray(depth_z, dtype=np.float32)),
                        ("instance", np.ascontiguousarray(instance, dtype=np.uint16))):
            # a fixed entry time (np.savez stamps the current one), so the same pass gives the same bytes
            with zf.open(zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0)), "w") as f:
                np.lib.format.write_array(f, a, allow_pickle=False)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(buf.getvalue())
    return path


def read_geometry(path: str | Path, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """``(depth_z, instance)`` of one geometry pass, checked: [H, W] float32 depth ≥ 0 (or ``inf``), uint16 ids.

    Raises
    ------
    InputError
        Missing, unreadable, or the wrong shape, dtype or values (naming the file and the array).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("geometry pass is missing", path=path, field="file")
    try:
        with np.load(path, allow_pickle=False) as data:
            depth, instance = data["depth_z"], data["instance"]
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"not a readable geometry pass ({exc})", path=path, field="file") from None
    for name, a, dtype in (("depth_z", depth, np.float32), ("instance", instance, np.uint16)):
        if a.shape != (height, width) or a.dtype != dtype:
            raise InputError(f"expected {np.dtype(dtype).name} [{height}, {width}], got {a.dtype} {list(a.shape)}",
                             path=path, field=name)
    if not np.all((depth >= 0) | (depth == np.inf)):
        raise InputError("depth must be ≥ 0 m or inf (nothing hit)", path=path, field="depth_z")
    return depth, instance


def geometry_is_intact(path: str | Path, width: int, height: int) -> bool:
    """True when the geometry pass at ``path`` reads back whole (a damaged one is rendered again)."""
    try:
        read_geometry(path, width, height)
    except InputError:
        return False
    return True


@dataclass(frozen=True)
class GeometryIndex:
    """The ``geometry`` block of a render directory's ``timeline.json``, checked.

    Attributes
    ----------
    rate_hz : float
        Ground-truth rate the passes were rendered at, Hz.
    times_s : ndarray [N]
        Their instants, s.
    files : list of Path
        One ``.npz`` per instant.
    camera_to_world : ndarray [N, 4, 4]
    camera_velocity : ndarray [N, 6]
        Linear (m s⁻¹) then angular (rad s⁻¹) velocity of the camera, world frame.
    instances : list of str
        Instance names: id k ≥ 1 is ``instances[k − 1]``; 0 is nothing hit.
    objects : list of str
        Animated objects (each one of ``instances``).
    object_to_world : ndarray [N, K, 4, 4]
        Pose of each animated object at each instant.
    object_velocity : ndarray [N, K, 6]
    """

    rate_hz: float
    times_s: np.ndarray
    files: list
    camera_to_world: np.ndarray
    camera_velocity: np.ndarray
    instances: list
    objects: list
    object_to_world: np.ndarray
    object_velocity: np.ndarray

    def instance_of(self, name: str) -> int:
        """Instance id of the scene object ``name``."""
        return self.instances.index(name) + 1


def read_geometry_index(meta: dict, render_dir: str | Path, source: str | Path) -> GeometryIndex | None:
    """Parse ``meta["geometry"]`` (None when the render has no geometry passes).

    Raises
    ------
    InputError
        A malformed block, naming ``timeline.json`` and the field.
    """
    block = meta.get("geometry")
    if block is None:
        return None
    render_dir = Path(render_dir)

    def bad(field, message):
        raise InputError(message, path=source, field=f"geometry.{field}")

    if not isinstance(block, dict):
        bad("", "expected an object")
    rate = block.get("rate_hz")
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (math.isfinite(rate) and rate > 0):
        bad("rate_hz", f"expected a rate in Hz > 0, got {rate!r}")
    instances, objects = block.get("instances"), block.get("objects", [])
    if not isinstance(instances, list) or not all(isinstance(n, str) for n in instances) or \
            len(set(instances)) != len(instances) or len(instances) >= 2**16:
        bad("instances", "expected a list of distinct names (at most 65535)")
    if not isinstance(objects, list) or not all(isinstance(n, str) and n in instances for n in objects):
        bad("objects", "expected a list of names from geometry.instances")
    instants = block.get("instants")
    if not isinstance(instants, list) or not instants:
        bad("instants", "expected a non-empty list of {t, file, camera_to_world}")
    times, files, cams, cam_v, obj, obj_v = [], [], [], [], [], []

    def matrix(value, field, shape):
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != shape or not np.all(np.isfinite(a)):
            bad(field, f"expected a finite {'x'.join(map(str, shape))} array")
        return a

    for i, inst in enumerate(instants):
        where = f"instants[{i}]"
        if not isinstance(inst, dict):
            bad(where, "expected an object")
        t = inst.get("t")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or (times and t <= times[-1]):
            bad(f"{where}.t", f"expected strictly increasing finite times, got {t!r}")
        name = inst.get("file")
        if not isinstance(name, str) or not name:
            bad(f"{where}.file", "expected a file name")
        files.append(confined_path(render_dir, name, source=source, field=f"geometry.{where}.file"))
        times.append(float(t))
        cams.append(matrix(inst.get("camera_to_world"), f"{where}.camera_to_world", (4, 4)))
        cam_v.append(matrix(inst.get("camera_velocity", [0.0] * 6), f"{where}.camera_velocity", (6,)))
        poses = inst.get("object_to_world", {})
        vels = inst.get("object_velocity", {})
        if not isinstance(poses, dict) or sorted(poses) != sorted(objects):
            bad(f"{where}.object_to_world", "expected one 4x4 matrix per animated object")
        obj.append([matrix(poses[n], f"{where}.object_to_world.{n}", (4, 4)) for n in objects])
        obj_v.append([matrix(vels.get(n, [0.0] * 6) if isinstance(vels, dict) else None,
                             f"{where}.object_velocity.{n}", (6,)) for n in objects])
    n, k = len(times), len(objects)
    return GeometryIndex(float(rate), np.asarray(times), files, np.stack(cams), np.stack(cam_v), list(instances),
                         list(objects), np.asarray(obj, np.float64).reshape(n, k, 4, 4),
                         np.asarray(obj_v, np.float64).reshape(n, k, 6))

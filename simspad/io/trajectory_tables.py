"""Trajectory documents: the ``[camera]`` and ``[objects.<id>]`` tables of TOML and JSON trajectory files.

Each body table holds either ``keyframes = [{t, position, quaternion_xyzw} | {t, look_at = {origin, target,
up}}, ...]`` or ``generator = "<name>"`` plus that generator's parameters (see :data:`GENERATORS` and
:mod:`simspad.motion.generators`). Every malformed value raises :class:`~simspad.errors.InputError` naming the
file and the field (``camera.keyframes[3].t``, ``objects.fan.rpm``).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from simspad.errors import InputError
from simspad.motion.generators import Tremor, handheld_shake, linear_pan, object_rotation, orbit, static_pose
from simspad.motion.trajectory import (
    CAMERA_BODY,
    QUATERNION_NORM_TOLERANCE,
    Trajectory,
    TrajectorySet,
    check_keyframes,
    look_at,
)

_DOC_KEYS = {"camera", "objects", "description", "format", "time_offset_s"}


def trajectory_set_from_document(doc: dict, source: str) -> TrajectorySet:
    """The bodies of a parsed TOML or JSON trajectory document (``source`` names the file in errors)."""
    unknown = set(doc) - _DOC_KEYS
    if unknown:
        raise InputError(f"unknown top-level key(s) {', '.join(sorted(unknown))} (expected camera, objects, "
                         "description, time_offset_s)", path=source, field=sorted(unknown)[0])
    if "camera" not in doc and "objects" not in doc:
        raise InputError("no [camera] or [objects.<id>] table (expected at least one body)", path=source)
    camera = None
    if "camera" in doc:
        camera = _body_from_table(doc["camera"], CAMERA_BODY, source)
    objects = {}
    objs = doc.get("objects", {})
    if not isinstance(objs, dict):
        raise InputError("must be a table of object tables ([objects.<id>])", path=source, field="objects")
    for name, table in objs.items():
        if not name.strip():  # TOML allows [objects.""]; no shape has an empty id
            raise InputError("an object with an empty id (expected [objects.<shape id>])", path=source,
                             field="objects")
        objects[name] = _body_from_table(table, f"objects.{name}", source)
    offset = doc.get("time_offset_s", 0.0)
    if not isinstance(offset, (int, float)) or isinstance(offset, bool) or not math.isfinite(offset):
        raise InputError(f"got {offset!r} (expected a number of seconds)", path=source, field="time_offset_s")
    return TrajectorySet(camera, objects, source, float(offset))


def _body_from_table(table, where: str, source: str) -> Trajectory:
    if not isinstance(table, dict):
        raise InputError("must be a table with 'keyframes' or 'generator'", path=source, field=where)
    if "generator" in table:
        name = table["generator"]
        if not isinstance(name, str) or name not in GENERATORS:
            raise InputError(f"unknown generator {name!r} (expected one of {', '.join(GENERATORS)})", path=source,
                             field=f"{where}.generator")
        builder, allowed = GENERATORS[name]
        unknown = set(table) - allowed - {"generator"}
        if unknown:
            raise InputError(f"unknown parameter(s) {', '.join(sorted(unknown))} for generator {name!r} "
                             f"(expected {', '.join(sorted(allowed))})", path=source, field=where)
        try:
            return builder(table, where, source)
        except ValueError as exc:
            raise InputError(str(exc), path=source, field=where) from None
    if "keyframes" not in table:
        raise InputError("needs 'keyframes' or 'generator'", path=source, field=where)
    unknown = set(table) - {"keyframes"}
    if unknown:
        raise InputError(f"unknown key(s) {', '.join(sorted(unknown))} beside keyframes", path=source, field=where)
    frames = table["keyframes"]
    if not isinstance(frames, list) or not all(isinstance(f, dict) for f in frames):
        raise InputError("must be a list of tables {t, position, quaternion_xyzw} or {t, look_at}", path=source,
                         field=f"{where}.keyframes")
    if len(frames) < 2:
        raise InputError(f"{len(frames)} keyframe(s) (expected at least 2; use generator = \"static_pose\" for a "
                         "body that does not move)", path=source, field=f"{where}.keyframes")
    times, positions, quats, rows = [], [], [], []
    for i, frame in enumerate(frames):
        kw = f"{where}.keyframes[{i}]"
        unknown = set(frame) - {"t", "position", "quaternion_xyzw", "look_at"}
        if unknown:
            raise InputError(f"unknown key(s) {', '.join(sorted(unknown))} (expected t, position, quaternion_xyzw "
                             "or t, look_at)", path=source, field=kw)
        if "look_at" in frame and ({"position", "quaternion_xyzw"} & set(frame)):
            raise InputError("give either look_at or position/quaternion_xyzw, not both", path=source, field=kw)
        times.append(_number(frame, "t", kw, source))
        p, q = _pose_from_table(frame, kw, source)
        positions.append(p)
        quats.append(q)
        rows.append(kw)
    times_a, pos_a, quat_a = np.array(times), np.array(positions), np.array(quats)
    check_keyframes(times_a, pos_a, quat_a, source, rows)
    return Trajectory(times_a, pos_a, quat_a, source=f"{source}:{where}")



def _pose_from_table(table: dict, where: str, source: str) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), quaternion_xyzw (4,)) from ``position`` + ``quaternion_xyzw`` or ``look_at``."""
    if "look_at" in table:
        la = table["look_at"]
        if not isinstance(la, dict):
            raise InputError("must be a table {origin, target, up}", path=source, field=f"{where}.look_at")
        unknown = set(la) - {"origin", "target", "up"}
        if unknown:
            raise InputError(f"unknown key(s) {', '.join(sorted(unknown))} (expected origin, target, up)",
                             path=source, field=f"{where}.look_at")
        origin = _vector(la, "origin", 3, f"{where}.look_at", source)
        target = _vector(la, "target", 3, f"{where}.look_at", source)
        up = _vector(la, "up", 3, f"{where}.look_at", source, default=(0.0, 1.0, 0.0))
        try:
            m = look_at(origin, target, up)
        except ValueError as exc:
            raise InputError(str(exc), path=source, field=f"{where}.look_at") from None
        return m[:3, 3], Rotation.from_matrix(m[:3, :3]).as_quat()
    position = _vector(table, "position", 3, where, source)
    quat = _vector(table, "quaternion_xyzw", 4, where, source, default=(0.0, 0.0, 0.0, 1.0))
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise InputError(f"quaternion has norm {norm:.6g} (expected a unit quaternion, |norm - 1| ≤ "
                         f"{QUATERNION_NORM_TOLERANCE:g})", path=source, field=f"{where}.quaternion_xyzw")
    return position, quat / norm


def _vector(table: dict, key: str, n: int, where: str, source: str, default=None) -> np.ndarray:
    if key not in table:
        if default is None:
            raise InputError(f"missing (expected a list of {n} numbers)", path=source, field=f"{where}.{key}")
        return np.asarray(default, dtype=np.float64)
    value = table[key]
    if (not isinstance(value, (list, tuple)) or len(value) != n
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise InputError(f"got {value!r} (expected a list of {n} numbers)", path=source, field=f"{where}.{key}")
    arr = np.asarray(value, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise InputError(f"got {value!r} (expected finite numbers, no NaN or inf)", path=source,
                         field=f"{where}.{key}")
    return arr


def _number(table: dict, key: str, where: str, source: str, default=None, *, positive=False,
            non_negative=False) -> float:
    if key not in table:
        if default is None:
            raise InputError("missing (expected a number)", path=source, field=f"{where}.{key}")
        return float(default)
    value = table[key]
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise InputError(f"got {value!r} (expected a finite number)", path=source, field=f"{where}.{key}")
    if positive and not value > 0:
        raise InputError(f"got {value!r} (expected a number > 0)", path=source, field=f"{where}.{key}")
    if non_negative and value < 0:
        raise InputError(f"got {value!r} (expected a number ≥ 0)", path=source, field=f"{where}.{key}")
    return float(value)


# --------------------------------------------------------------------------------------------------------------
# Generator tables


def _gen_static(table, where, source):
    p, q = _pose_from_table(table, where, source)
    return static_pose(p, q, duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                       source=f"{source}:{where}")


def _gen_linear_pan(table, where, source):
    p, q = _pose_from_table(table, where, source)
    return linear_pan(p, q, velocity_m_s=_vector(table, "velocity_m_s", 3, where, source, (0.0, 0.0, 0.0)),
                      yaw_rate_deg_s=_number(table, "yaw_rate_deg_s", where, source, 0.0),
                      axis=_vector(table, "axis", 3, where, source, (0.0, 1.0, 0.0)),
                      duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                      rate_hz=_number(table, "rate_hz", where, source, 100.0, positive=True),
                      source=f"{source}:{where}")


def _gen_orbit(table, where, source):
    return orbit(_vector(table, "target", 3, where, source, (0.0, 0.0, 0.0)),
                 radius_m=_number(table, "radius_m", where, source, positive=True),
                 angular_speed_deg_s=_number(table, "angular_speed_deg_s", where, source, 30.0),
                 height_m=_number(table, "height_m", where, source, 0.0),
                 start_angle_deg=_number(table, "start_angle_deg", where, source, 0.0),
                 up=_vector(table, "up", 3, where, source, (0.0, 1.0, 0.0)),
                 duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                 rate_hz=_number(table, "rate_hz", where, source, 100.0, positive=True),
                 source=f"{source}:{where}")


def _gen_shake(table, where, source):
    p, q = _pose_from_table(table, where, source)
    seed = table.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise InputError(f"got {seed!r} (expected an integer ≥ 0)", path=source, field=f"{where}.seed")
    f_lo = _number(table, "f_lo_hz", where, source, 1.0, positive=True)
    f_hi = _number(table, "f_hi_hz", where, source, 12.0, positive=True)
    if f_hi < f_lo:
        raise InputError(f"{f_hi!r} is below f_lo_hz = {f_lo!r} (expected f_lo_hz ≤ f_hi_hz)", path=source,
                         field=f"{where}.f_hi_hz")
    tremor = Tremor(f_lo_hz=f_lo, f_hi_hz=f_hi,
                    translation_amplitude_m=_number(table, "translation_amplitude_m", where, source, 0.002,
                                                    non_negative=True),
                    rotation_amplitude_deg=_number(table, "rotation_amplitude_deg", where, source, 0.5,
                                                   non_negative=True))
    return handheld_shake(p, q, seed=seed, tremor=tremor,
                          duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                          rate_hz=_number(table, "rate_hz", where, source, 0.0, non_negative=True) or None,
                          yaw_rate_deg_s=_number(table, "yaw_rate_deg_s", where, source, 0.0),
                          start_yaw_deg=_number(table, "start_yaw_deg", where, source, 0.0),
                          axis=_vector(table, "axis", 3, where, source, (0.0, 1.0, 0.0)),
                          source=f"{source}:{where}")


def _gen_object_rotation(table, where, source):
    return object_rotation(_vector(table, "center", 3, where, source, (0.0, 0.0, 0.0)),
                           _vector(table, "axis", 3, where, source, (0.0, 0.0, 1.0)),
                           rpm=_number(table, "rpm", where, source),
                           start_angle_deg=_number(table, "start_angle_deg", where, source, 0.0),
                           duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                           rate_hz=_number(table, "rate_hz", where, source, 100.0, positive=True),
                           source=f"{source}:{where}")


_POSE_KEYS = {"position", "quaternion_xyzw", "look_at"}
GENERATORS: dict[str, tuple[Callable, set[str]]] = {
    "static_pose": (_gen_static, _POSE_KEYS | {"duration_s"}),
    "linear_pan": (_gen_linear_pan, _POSE_KEYS | {"velocity_m_s", "yaw_rate_deg_s", "axis", "duration_s", "rate_hz"}),
    "orbit": (_gen_orbit, {"target", "radius_m", "angular_speed_deg_s", "height_m", "start_angle_deg", "up",
                           "duration_s", "rate_hz"}),
    "handheld_shake": (_gen_shake, _POSE_KEYS | {"seed", "f_lo_hz", "f_hi_hz", "translation_amplitude_m",
                                                  "rotation_amplitude_deg", "duration_s", "rate_hz", "yaw_rate_deg_s",
                                                  "start_yaw_deg", "axis"}),
    "object_rotation": (_gen_object_rotation, {"center", "axis", "rpm", "start_angle_deg", "duration_s", "rate_hz"}),
}
"""Generator name → (builder from a table, accepted parameter names)."""

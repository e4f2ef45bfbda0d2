"""Timestamped rigid-body motion (SE(3)) of the camera and of named scene objects.

A :class:`Trajectory` interpolates keyframes: a C² cubic spline for positions and a C² rotation spline
(``scipy.spatial.transform.RotationSpline``) for orientations, so both the pose and its velocity (linear and
angular, world frame) are continuous. A :class:`TrajectorySet` is what a trajectory file holds: an optional
camera trajectory plus object trajectories by id.

Pose convention (docs/internals.md): 4×4 ``camera_to_world`` (or ``object_to_world``) float64 matrices in
Mitsuba's convention — the camera looks along its local +Z with +Y up and +X to the left, as
``mi.ScalarTransform4f.look_at``. Quaternions are scalar-last ``(x, y, z, w)`` and rotate body to world.

File formats (:func:`load_trajectory`, :func:`save_trajectory`):

- ``.toml`` / ``.json`` — ``[camera]`` and ``[objects.<id>]`` tables, each either ``keyframes = [{t, position,
  quaternion_xyzw} | {t, look_at = {origin, target, up}}, ...]`` or ``generator = "<name>"`` plus the
  generator's parameters (see :data:`GENERATORS`).
- ``.csv`` — header ``t,tx,ty,tz,qx,qy,qz,qw`` with an optional ``body`` column (``camera`` or an object id).
- ``.txt`` / ``.tum`` — the TUM RGB-D format ``t tx ty tz qx qy qz qw`` (whitespace separated, ``#`` comments);
  its absolute (epoch) timestamps are rebased to start at 0 and the offset is kept in
  :attr:`TrajectorySet.time_offset_s`.

Outside its keyframe span a trajectory holds its first / last pose (velocity zero there).
"""

from __future__ import annotations

import csv
import io
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from simspad.errors import InputError

QUATERNION_NORM_TOLERANCE = 1e-3
"""Quaternions whose norm differs from 1 by more than this are refused (larger errors mean a broken file)."""

CAMERA_BODY = "camera"
TUM_SUFFIXES = (".txt", ".tum")


# --------------------------------------------------------------------------------------------------------------
# Trajectory


class Trajectory:
    """Smooth rigid-body motion through timestamped keyframes.

    Parameters
    ----------
    times_s : array_like, shape (K,)
        Strictly increasing keyframe times in seconds. ``K = 1`` is a static pose (valid at all times).
    positions_m : array_like, shape (K, 3)
        Body origin in world coordinates, metres.
    quaternions_xyzw : array_like, shape (K, 4)
        Body-to-world orientation, scalar last; normalised on input (norm must be within
        :data:`QUATERNION_NORM_TOLERANCE` of 1).
    source : str, optional
        File (and body) the keyframes came from, used in error messages.
    """

    def __init__(self, times_s, positions_m, quaternions_xyzw, *, source: str = "<trajectory>"):
        # Own copies: they are made read-only below, which must not affect the caller's arrays.
        times_s = np.array(times_s, dtype=np.float64).reshape(-1)
        positions_m = _rows(positions_m, 3, "positions_m", source)
        quaternions_xyzw = _rows(quaternions_xyzw, 4, "quaternions_xyzw", source)
        _check_keyframes(times_s, positions_m, quaternions_xyzw, source)
        norms = np.linalg.norm(quaternions_xyzw, axis=1, keepdims=True)
        quats = _sign_continuous(quaternions_xyzw / norms)
        self.times_s = times_s
        self.positions_m = positions_m
        self.quaternions_xyzw = quats
        self.source = source
        for a in (self.times_s, self.positions_m, self.quaternions_xyzw):
            a.setflags(write=False)
        rotations = Rotation.from_quat(quats)
        if len(times_s) >= 2:
            self._position_spline = CubicSpline(times_s, positions_m, axis=0)
            self._velocity_spline = self._position_spline.derivative()
            self._rotation_spline = RotationSpline(times_s, rotations)
        else:
            self._position_spline = self._velocity_spline = self._rotation_spline = None
        self._rotations = rotations

    # -- construction helpers ----------------------------------------------------------------------------------
    @classmethod
    def from_matrices(cls, times_s, body_to_world, *, source: str = "<trajectory>") -> "Trajectory":
        """Build from 4×4 pose matrices, shape (K, 4, 4)."""
        m = np.asarray(body_to_world, dtype=np.float64).reshape(-1, 4, 4)
        return cls(times_s, m[:, :3, 3], Rotation.from_matrix(m[:, :3, :3]).as_quat(), source=source)

    # -- span ----------------------------------------------------------------------------------------------------
    @property
    def t_start(self) -> float:
        """First keyframe time, seconds."""
        return float(self.times_s[0])

    @property
    def t_end(self) -> float:
        """Last keyframe time, seconds."""
        return float(self.times_s[-1])

    @property
    def is_static(self) -> bool:
        """True when the pose never changes (one keyframe, or all keyframes equal)."""
        return bool((self.positions_m == self.positions_m[0]).all()
                    and (self.quaternions_xyzw == self.quaternions_xyzw[0]).all())

    # -- evaluation ----------------------------------------------------------------------------------------------
    def _clamped(self, t) -> tuple[np.ndarray, bool, np.ndarray]:
        t = np.asarray(t, dtype=np.float64)
        scalar = t.ndim == 0
        tt = np.atleast_1d(t).reshape(-1)
        inside = (tt >= self.times_s[0]) & (tt <= self.times_s[-1])
        return np.clip(tt, self.times_s[0], self.times_s[-1]), scalar, inside

    def position(self, t) -> np.ndarray:
        """Body origin (m) at ``t``: shape (3,) for a scalar, (N, 3) for an array."""
        tt, scalar, _ = self._clamped(t)
        p = (np.repeat(self.positions_m[:1], len(tt), axis=0) if self._position_spline is None
             else self._position_spline(tt))
        return p[0] if scalar else p

    def rotation(self, t) -> Rotation:
        """Body-to-world orientation at ``t`` as a ``scipy`` ``Rotation`` (single or stacked)."""
        tt, scalar, _ = self._clamped(t)
        if self._rotation_spline is None:
            r = Rotation.from_quat(np.repeat(self.quaternions_xyzw[:1], len(tt), axis=0))
        else:
            r = self._rotation_spline(tt)
        return r[0] if scalar else r

    def pose(self, t) -> np.ndarray:
        """Body-to-world 4×4 matrix at ``t`` (s): shape (4, 4) for a scalar, (N, 4, 4) for an array."""
        tt, scalar, _ = self._clamped(t)
        m = np.zeros((len(tt), 4, 4))
        m[:, :3, :3] = np.asarray(self.rotation(tt).as_matrix()).reshape(-1, 3, 3)
        m[:, :3, 3] = self.position(tt)
        m[:, 3, 3] = 1.0
        return m[0] if scalar else m

    def velocity(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Linear velocity (m/s) and angular velocity (rad/s), both in the world frame, at ``t`` (s).

        Returns arrays of shape (3,) for a scalar ``t`` and (N, 3) for an array; zero outside the keyframe span.
        """
        tt, scalar, inside = self._clamped(t)
        v = np.zeros((len(tt), 3))
        w = np.zeros((len(tt), 3))
        if self._position_spline is not None:
            v[inside] = self._velocity_spline(tt[inside])
            if inside.any():
                # RotationSpline's first derivative is the body-frame rate; rotate it into the world frame.
                w_body = np.asarray(self._rotation_spline(tt[inside], 1)).reshape(-1, 3)
                w[inside] = self._rotation_spline(tt[inside]).apply(w_body)
        return (v[0], w[0]) if scalar else (v, w)

    def __repr__(self) -> str:
        return f"Trajectory({len(self.times_s)} keyframes, {self.t_start:g}–{self.t_end:g} s, {self.source})"


@dataclass
class TrajectorySet:
    """What a trajectory file holds.

    Attributes
    ----------
    camera : Trajectory or None
        Camera motion (None: the scene's own camera stays put).
    objects : dict of str to Trajectory
        ``object_to_world`` motion of scene objects by id, applied to the object's rest pose.
    source : str
        File the set was read from (or a description).
    time_offset_s : float
        Seconds subtracted from the file's timestamps on reading (TUM epoch rebasing); 0 if none.
    """

    camera: Trajectory | None
    objects: dict[str, Trajectory] = field(default_factory=dict)
    source: str = "<memory>"
    time_offset_s: float = 0.0

    def bodies(self) -> dict[str, Trajectory]:
        """All trajectories by body name (``"camera"`` first)."""
        out = {} if self.camera is None else {CAMERA_BODY: self.camera}
        out.update(self.objects)
        return out

    @property
    def is_static(self) -> bool:
        """True when no body moves (then any time span is covered)."""
        return not self._moving()

    def _moving(self) -> list[Trajectory]:
        return [tr for tr in self.bodies().values() if not tr.is_static]

    @property
    def t_start(self) -> float:
        """Start of the span that all moving bodies cover (all bodies when none moves), seconds."""
        moving = self._moving() or list(self.bodies().values())
        return max(tr.t_start for tr in moving) if moving else 0.0

    @property
    def t_end(self) -> float:
        """End of the span that all moving bodies cover (all bodies when none moves), seconds."""
        moving = self._moving() or list(self.bodies().values())
        return min(tr.t_end for tr in moving) if moving else 0.0


# --------------------------------------------------------------------------------------------------------------
# Validation helpers


def _check_keyframes(times_s, positions_m, quats, source: str, rows: list[str] | None = None) -> None:
    """Raise InputError naming ``source`` and the offending keyframe (``rows[i]`` describes keyframe i)."""

    def where(i: int) -> str:
        return rows[i] if rows is not None else f"keyframe {i}"

    if not (len(times_s) == len(positions_m) == len(quats)):
        raise InputError(f"{len(times_s)} times, {len(positions_m)} positions and {len(quats)} quaternions "
                         "(expected one of each per keyframe)", path=source)
    if len(times_s) == 0:
        raise InputError("no keyframes (expected at least 2)", path=source)
    for name, arr in (("t", times_s), ("position", positions_m), ("quaternion", quats)):
        bad = ~np.isfinite(arr.reshape(len(arr), -1)).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"{name} is not finite (NaN or inf) (expected finite numbers)", path=source,
                             field=where(i))
    steps = np.diff(times_s)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        raise InputError(f"time {times_s[i]!r} s does not increase (previous keyframe at {times_s[i - 1]!r} s; "
                         "expected strictly increasing times)", path=source, field=where(i))
    norms = np.linalg.norm(quats, axis=1)
    bad = np.abs(norms - 1.0) > QUATERNION_NORM_TOLERANCE
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"quaternion has norm {norms[i]:.6g} (expected a unit quaternion, |norm - 1| ≤ "
                         f"{QUATERNION_NORM_TOLERANCE:g})", path=source, field=where(i))


def _rows(values, n: int, name: str, source: str) -> np.ndarray:
    """``values`` as a fresh (K, n) float64 array; a single row may be given flat."""
    a = np.array(values, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == n:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != n:
        raise InputError(f"{name} has shape {a.shape} (expected (K, {n}))", path=source)
    return a


def _sign_continuous(quats: np.ndarray) -> np.ndarray:
    """Flip signs so consecutive quaternions lie in the same hemisphere (q and −q are the same rotation)."""
    q = quats.copy()
    for i in range(1, len(q)):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return q


# --------------------------------------------------------------------------------------------------------------
# Poses


def look_at(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera-to-world 4×4 matrix of a camera at ``origin`` looking at ``target`` (Mitsuba convention).

    Same as ``mi.ScalarTransform4f.look_at``: local +Z points to the target, +Y is as close to ``up`` as
    possible, +X = ``up`` × +Z (to the camera's left).
    """
    origin = np.asarray(origin, dtype=np.float64)
    direction = np.asarray(target, dtype=np.float64) - origin
    norm = np.linalg.norm(direction)
    if not norm > 0:
        raise ValueError("look_at: target equals origin (expected distinct points)")
    direction /= norm
    left = np.cross(np.asarray(up, dtype=np.float64), direction)
    left_norm = np.linalg.norm(left)
    if not left_norm > 1e-12:
        raise ValueError("look_at: up is parallel to the viewing direction (expected a different up vector)")
    left /= left_norm
    new_up = np.cross(direction, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, direction, origin
    return m


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
# Generators


def _frame_count(duration_s: float, rate_hz: float) -> int:
    return max(2, int(math.ceil(duration_s * rate_hz - 1e-9)) + 1)


def static_pose(position_m=(0.0, 0.0, 0.0), quaternion_xyzw=(0.0, 0.0, 0.0, 1.0), *, duration_s: float = 1.0,
                source: str = "static_pose") -> Trajectory:
    """A body that does not move: two identical keyframes at 0 and ``duration_s`` seconds."""
    p = np.asarray(position_m, dtype=np.float64)
    q = np.asarray(quaternion_xyzw, dtype=np.float64)
    return Trajectory([0.0, duration_s], [p, p], [q, q], source=source)


def linear_pan(position_m=(0.0, 0.0, 0.0), quaternion_xyzw=(0.0, 0.0, 0.0, 1.0), *,
               velocity_m_s=(0.0, 0.0, 0.0), yaw_rate_deg_s: float = 0.0, axis=(0.0, 1.0, 0.0),
               duration_s: float = 1.0, rate_hz: float = 100.0, source: str = "linear_pan") -> Trajectory:
    """Constant translation velocity (world, m/s) and constant rotation rate about a world ``axis`` (deg/s).

    The rotation turns the body about ``axis`` through its own (moving) origin: a tripod pan when
    ``axis`` is the world up vector.
    """
    axis = _unit(axis)
    n = _frame_count(duration_s, max(rate_hz, 8 * abs(yaw_rate_deg_s) / 45.0))
    t = np.linspace(0.0, duration_s, n)
    p = np.asarray(position_m, dtype=np.float64) + t[:, None] * np.asarray(velocity_m_s, dtype=np.float64)
    spin = Rotation.from_rotvec(np.deg2rad(yaw_rate_deg_s) * t[:, None] * axis)
    q = (spin * Rotation.from_quat(quaternion_xyzw)).as_quat()
    return Trajectory(t, p, q, source=source)


def orbit(target_m=(0.0, 0.0, 0.0), *, radius_m: float = 1.0, angular_speed_deg_s: float = 30.0,
          height_m: float = 0.0, start_angle_deg: float = 0.0, up=(0.0, 1.0, 0.0), duration_s: float = 1.0,
          rate_hz: float = 100.0, source: str = "orbit") -> Trajectory:
    """Camera circling ``target_m`` at ``radius_m`` in the plane normal to ``up`` (raised by ``height_m``),
    always looking at the target; angle = start + speed·t (counter-clockwise about ``up``)."""
    up = _unit(up)
    ref = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = _unit(ref - np.dot(ref, up) * up)
    e2 = np.cross(up, e1)
    # Keep ≥ 64 keyframes per revolution so the spline follows the circle to ~1e-7 of the radius.
    n = _frame_count(duration_s, max(rate_hz, 64 * abs(angular_speed_deg_s) / 360.0))
    t = np.linspace(0.0, duration_s, n)
    angle = np.deg2rad(start_angle_deg + angular_speed_deg_s * t)
    target = np.asarray(target_m, dtype=np.float64)
    pos = target + height_m * up + radius_m * (np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2)
    mats = np.stack([look_at(p, target, up) for p in pos])
    return Trajectory.from_matrices(t, mats, source=source)


def handheld_shake(position_m=(0.0, 0.0, 0.0), quaternion_xyzw=(0.0, 0.0, 0.0, 1.0), *, seed: int = 0,
                   f_lo_hz: float = 1.0, f_hi_hz: float = 12.0, translation_amplitude_m: float = 0.002,
                   rotation_amplitude_deg: float = 0.5, duration_s: float = 1.0, rate_hz: float | None = None,
                   n_components: int = 24, source: str = "handheld_shake") -> Trajectory:
    """Hand tremor around a base pose: seeded band-limited noise.

    Each translation axis (world) and each rotation axis (body frame, small-angle rotation vector) is a sum of
    ``n_components`` sinusoids with frequencies drawn uniformly in ``[f_lo_hz, f_hi_hz]``, random phases and
    Rayleigh-distributed weights, scaled so that the per-axis RMS (over an infinite time) equals
    ``translation_amplitude_m`` (m) and ``rotation_amplitude_deg`` (deg). Deterministic for a given ``seed``.
    """
    if not 0 < f_lo_hz <= f_hi_hz:
        raise ValueError(f"handheld_shake: expected 0 < f_lo_hz ≤ f_hi_hz, got {f_lo_hz}, {f_hi_hz}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5A4E]))
    # 20 keyframes per period of the highest frequency: spline error ~ (2π/20)^4/384 ≈ 3e-5 of the amplitude.
    rate = max(rate_hz or 0.0, 20.0 * f_hi_hz)
    n = _frame_count(duration_s, rate)
    t = np.linspace(0.0, duration_s, n)

    def band_noise(rms: float) -> np.ndarray:
        freqs = rng.uniform(f_lo_hz, f_hi_hz, size=(3, n_components))
        phases = rng.uniform(0.0, 2 * np.pi, size=(3, n_components))
        weights = rng.rayleigh(1.0, size=(3, n_components))
        weights *= rms * np.sqrt(2.0) / np.sqrt((weights**2).sum(axis=1, keepdims=True))
        return np.einsum("ak,akn->na", weights,
                         np.sin(2 * np.pi * freqs[:, :, None] * t[None, None, :] + phases[:, :, None]))

    dp = band_noise(translation_amplitude_m)
    dr = band_noise(np.deg2rad(rotation_amplitude_deg))
    p = np.asarray(position_m, dtype=np.float64) + dp
    q = (Rotation.from_quat(quaternion_xyzw) * Rotation.from_rotvec(dr)).as_quat()
    return Trajectory(t, p, q, source=source)


def object_rotation(center_m=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), *, rpm: float = 60.0,
                    start_angle_deg: float = 0.0, duration_s: float = 1.0, rate_hz: float = 100.0,
                    source: str = "object_rotation") -> Trajectory:
    """``object_to_world`` of an object spinning about ``axis`` through ``center_m`` at ``rpm`` (right-handed)."""
    axis = _unit(axis)
    center = np.asarray(center_m, dtype=np.float64)
    n = _frame_count(duration_s, max(rate_hz, 64 * abs(rpm) / 60.0))
    t = np.linspace(0.0, duration_s, n)
    angle = np.deg2rad(start_angle_deg) + 2 * np.pi * rpm / 60.0 * t
    r = Rotation.from_rotvec(angle[:, None] * axis)
    # x' = R (x - c) + c  =>  translation c - R c
    p = center - r.apply(center)
    return Trajectory(t, p, r.as_quat(), source=source)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not n > 0:
        raise ValueError(f"expected a non-zero vector, got {v.tolist()}")
    return v / n


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
    return handheld_shake(p, q, seed=seed, f_lo_hz=f_lo, f_hi_hz=f_hi,
                          translation_amplitude_m=_number(table, "translation_amplitude_m", where, source, 0.002,
                                                          non_negative=True),
                          rotation_amplitude_deg=_number(table, "rotation_amplitude_deg", where, source, 0.5,
                                                         non_negative=True),
                          duration_s=_number(table, "duration_s", where, source, 1.0, positive=True),
                          rate_hz=_number(table, "rate_hz", where, source, 0.0, non_negative=True) or None,
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
                                                  "rotation_amplitude_deg", "duration_s", "rate_hz"}),
    "object_rotation": (_gen_object_rotation, {"center", "axis", "rpm", "start_angle_deg", "duration_s", "rate_hz"}),
}
"""Generator name → (builder from a table, accepted parameter names)."""


# --------------------------------------------------------------------------------------------------------------
# Loading


def load_trajectory(path, *, rebase: bool | None = None) -> TrajectorySet:
    """Read a trajectory file (format from the suffix; see the module docstring).

    Parameters
    ----------
    path : str or Path
    rebase : bool, optional
        Shift times so the earliest keyframe is at t = 0 (the shift is kept in ``time_offset_s``). Default:
        True for TUM files (their timestamps are epoch seconds), False otherwise.

    Raises
    ------
    InputError
        Unreadable or malformed file; the message names the file and the line or field.
    """
    path = Path(path)
    source = str(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json", ".csv") + TUM_SUFFIXES:
        raise InputError(f"unknown trajectory format {path.suffix!r} (expected .toml, .json, .csv, .txt or .tum)",
                         path=source)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("trajectory file not found", path=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read trajectory file ({exc})", path=source) from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"invalid TOML: {exc}", path=source) from None
        ts = _from_document(doc, source)
    elif suffix == ".json":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"invalid JSON: {exc.msg}", path=source, field=f"line {exc.lineno}") from None
        if not isinstance(doc, dict):
            raise InputError("expected a JSON object with 'camera' and/or 'objects'", path=source)
        ts = _from_document(doc, source)
    elif suffix == ".csv":
        ts = _from_csv(text, source)
    else:
        ts = _from_tum(text, source)
    if rebase is None:
        rebase = suffix in TUM_SUFFIXES
    return _rebased(ts) if rebase else ts


def _rebased(ts: TrajectorySet) -> TrajectorySet:
    bodies = ts.bodies()
    if not bodies:
        return ts
    offset = min(tr.t_start for tr in bodies.values())
    if offset == 0.0:
        return ts

    def shift(tr: Trajectory) -> Trajectory:
        return Trajectory(tr.times_s - offset, tr.positions_m, tr.quaternions_xyzw, source=tr.source)

    return TrajectorySet(None if ts.camera is None else shift(ts.camera),
                         {k: shift(v) for k, v in ts.objects.items()}, ts.source, ts.time_offset_s + offset)


_DOC_KEYS = {"camera", "objects", "description", "format", "time_offset_s"}


def _from_document(doc: dict, source: str) -> TrajectorySet:
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
        if name not in GENERATORS:
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
    _check_keyframes(times_a, pos_a, quat_a, source, rows)
    return Trajectory(times_a, pos_a, quat_a, source=f"{source}:{where}")


_CSV_COLUMNS = ("t", "tx", "ty", "tz", "qx", "qy", "qz", "qw")


def _from_csv(text: str, source: str) -> TrajectorySet:
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty CSV (expected a header t,tx,ty,tz,qx,qy,qz,qw and rows)", path=source)
    header_lineno, header_line = lines[0]
    header = [h.strip() for h in next(csv.reader([header_line]))]
    missing = [c for c in _CSV_COLUMNS if c not in header]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)} (expected header t,tx,ty,tz,qx,qy,qz,qw "
                         "[,body])", path=source, field=f"line {header_lineno}")
    unknown = [c for c in header if c not in _CSV_COLUMNS + ("body",)]
    if unknown:
        raise InputError(f"unknown column(s) {', '.join(unknown)} (expected t,tx,ty,tz,qx,qy,qz,qw [,body])",
                         path=source, field=f"line {header_lineno}")
    index = {c: header.index(c) for c in header}
    per_body: dict[str, list[tuple[int, list[float]]]] = {}
    for lineno, line in lines[1:]:
        cells = [c.strip() for c in next(csv.reader([line]))]
        if len(cells) != len(header):
            raise InputError(f"{len(cells)} values (expected {len(header)}: {','.join(header)})", path=source,
                             field=f"line {lineno}")
        body = cells[index["body"]] if "body" in index else CAMERA_BODY
        if not body:
            raise InputError("empty body name", path=source, field=f"line {lineno}")
        values = []
        for c in _CSV_COLUMNS:
            try:
                values.append(float(cells[index[c]]))
            except ValueError:
                raise InputError(f"column {c}: {cells[index[c]]!r} is not a number", path=source,
                                 field=f"line {lineno}") from None
        per_body.setdefault(body, []).append((lineno, values))
    if not per_body:
        raise InputError("no data rows (expected at least 2 per body)", path=source)
    bodies = {name: _body_from_rows(rows, source, name) for name, rows in per_body.items()}
    camera = bodies.pop(CAMERA_BODY, None)
    return TrajectorySet(camera, bodies, source)


def _from_tum(text: str, source: str) -> TrajectorySet:
    rows = []
    for i, line in enumerate(text.splitlines()):
        stripped = line.split("#", 1)[0].strip()
        if not stripped:
            continue
        cells = stripped.replace(",", " ").split()
        if len(cells) != 8:
            raise InputError(f"{len(cells)} values (expected 8: t tx ty tz qx qy qz qw)", path=source,
                             field=f"line {i + 1}")
        try:
            rows.append((i + 1, [float(c) for c in cells]))
        except ValueError:
            bad = next(c for c in cells if not _is_float(c))
            raise InputError(f"{bad!r} is not a number (expected t tx ty tz qx qy qz qw)", path=source,
                             field=f"line {i + 1}") from None
    if not rows:
        raise InputError("no poses (expected lines 't tx ty tz qx qy qz qw')", path=source)
    return TrajectorySet(_body_from_rows(rows, source, CAMERA_BODY), {}, source)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _body_from_rows(rows: list[tuple[int, list[float]]], source: str, body: str) -> Trajectory:
    if len(rows) < 2:
        raise InputError(f"{len(rows)} pose(s) for body {body!r} (expected at least 2)", path=source,
                         field=f"line {rows[0][0]}")
    data = np.array([v for _, v in rows], dtype=np.float64)
    labels = [f"line {n}" for n, _ in rows]
    _check_keyframes(data[:, 0], data[:, 1:4], data[:, 4:8], source, labels)
    return Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8], source=f"{source}:{body}")


# --------------------------------------------------------------------------------------------------------------
# Saving


def save_trajectory(ts: TrajectorySet, path) -> Path:
    """Write ``ts`` as TOML or JSON keyframes, CSV or TUM, chosen by the suffix of ``path``.

    The file is written atomically. TUM holds only a camera; its times are written with ``time_offset_s``
    added back. Numbers are written with full float64 precision (``repr``), so reading back is exact.
    """
    from simspad.io.atomic import atomic_path

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        text = _to_toml(ts)
    elif suffix == ".json":
        text = json.dumps(_to_document(ts), indent=1) + "\n"
    elif suffix == ".csv":
        text = _to_csv(ts)
    elif suffix in TUM_SUFFIXES:
        if ts.camera is None or ts.objects:
            raise InputError("the TUM format holds exactly one (camera) trajectory (use .toml, .json or .csv for "
                             "objects)", path=path)
        text = "# timestamp tx ty tz qx qy qz qw\n" + "".join(
            f"{_f(t + ts.time_offset_s)} {' '.join(_f(v) for v in p)} {' '.join(_f(v) for v in q)}\n"
            for t, p, q in zip(ts.camera.times_s, ts.camera.positions_m, ts.camera.quaternions_xyzw))
    else:
        raise InputError(f"unknown trajectory format {path.suffix!r} (expected .toml, .json, .csv, .txt or .tum)",
                         path=path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def _f(x: float) -> str:
    return repr(float(x))


def _keyframes(tr: Trajectory) -> list[dict]:
    return [{"t": float(t), "position": [float(v) for v in p], "quaternion_xyzw": [float(v) for v in q]}
            for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw)]


def _to_document(ts: TrajectorySet) -> dict:
    doc: dict = {"format": "simspad-trajectory"}
    if ts.time_offset_s:
        doc["time_offset_s"] = ts.time_offset_s
    if ts.camera is not None:
        doc["camera"] = {"keyframes": _keyframes(ts.camera)}
    if ts.objects:
        doc["objects"] = {k: {"keyframes": _keyframes(v)} for k, v in ts.objects.items()}
    return doc


def _to_toml(ts: TrajectorySet) -> str:
    out = ['format = "simspad-trajectory"']
    if ts.time_offset_s:
        out.append(f"time_offset_s = {_f(ts.time_offset_s)}")

    def table(header: str, tr: Trajectory) -> None:
        out.append(f"\n[{header}]\nkeyframes = [")
        for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            out.append(f"  {{ t = {_f(t)}, position = [{', '.join(map(_f, p))}], "
                       f"quaternion_xyzw = [{', '.join(map(_f, q))}] }},")
        out.append("]")

    if ts.camera is not None:
        table("camera", ts.camera)
    for name, tr in ts.objects.items():
        table(f"objects.{json.dumps(name)}", tr)
    return "\n".join(out) + "\n"


def _to_csv(ts: TrajectorySet) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")  # quotes body names that hold commas
    writer.writerow(_CSV_COLUMNS + ("body",))
    for name, tr in ts.bodies().items():
        for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            writer.writerow([_f(t), *map(_f, p), *map(_f, q), name])
    return buf.getvalue()


# --------------------------------------------------------------------------------------------------------------
# Summary


def motion_summary(tr: Trajectory, *, rate_hz: float = 2000.0) -> dict[str, float]:
    """Duration (s), path length (m), max speed (m/s) and max angular rate (rad/s) sampled at ``rate_hz``."""
    if len(tr.times_s) == 1:
        return {"duration_s": 0.0, "path_length_m": 0.0, "max_speed_m_s": 0.0, "max_angular_rate_rad_s": 0.0,
                "keyframes": 1}
    n = max(2, min(200_000, int(math.ceil((tr.t_end - tr.t_start) * rate_hz)) + 1))
    t = np.linspace(tr.t_start, tr.t_end, n)
    p = tr.position(t)
    v, w = tr.velocity(t)
    return {"duration_s": tr.t_end - tr.t_start,
            "path_length_m": float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()),
            "max_speed_m_s": float(np.linalg.norm(v, axis=1).max()),
            "max_angular_rate_rad_s": float(np.linalg.norm(w, axis=1).max()),
            "keyframes": len(tr.times_s)}


def describe_trajectory(path) -> str:
    """A readable summary of a trajectory file: per body duration, path length, max speed, max angular rate."""
    ts = load_trajectory(path)
    lines = [f"trajectory {ts.source}"]
    if ts.time_offset_s:
        lines.append(f"  time offset    {ts.time_offset_s:.6f} s subtracted (timestamps rebased to start at 0)")
    lines.append(f"  common span    {ts.t_start:.6g} – {ts.t_end:.6g} s")
    for name, tr in ts.bodies().items():
        s = motion_summary(tr)
        lines.append(f"  {name}:")
        lines.append(f"    keyframes        {s['keyframes']}  ({tr.t_start:.6g} – {tr.t_end:.6g} s)")
        lines.append(f"    duration         {s['duration_s']:.6g} s")
        lines.append(f"    path length      {s['path_length_m']:.6g} m (of the body origin)")
        lines.append(f"    max speed        {s['max_speed_m_s']:.6g} m/s")
        lines.append(f"    max angular rate {s['max_angular_rate_rad_s']:.6g} rad/s "
                     f"({np.rad2deg(s['max_angular_rate_rad_s']):.4g} deg/s)")
    return "\n".join(lines)

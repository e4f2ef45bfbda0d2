"""Timestamped rigid-body motion (SE(3)) of the camera and of named scene objects.

A :class:`Trajectory` interpolates keyframes: a C² cubic spline for positions and a C² rotation spline
(``scipy.spatial.transform.RotationSpline``) for orientations, so both the pose and its velocity (linear and
angular, world frame) are continuous. A :class:`TrajectorySet` is what a trajectory file holds: an optional
camera trajectory plus object trajectories by id. Generators of common motions live in
:mod:`simspad.motion.generators`; the file formats in :mod:`simspad.io.trajectory_files`.

Pose convention (docs/internals.md): 4×4 ``camera_to_world`` (or ``object_to_world``) float64 matrices in
Mitsuba's convention — the camera looks along its local +Z with +Y up and +X to the left, as
``mi.ScalarTransform4f.look_at``. Quaternions are scalar-last ``(x, y, z, w)`` and rotate body to world.

Outside its keyframe span a trajectory holds its first / last pose (velocity zero there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from simspad import defaults
from simspad.errors import InputError

QUATERNION_NORM_TOLERANCE = 1e-3
"""Quaternions whose norm differs from 1 by more than this are refused (larger errors mean a broken file)."""

#: Body name of the camera in a :class:`TrajectorySet` (and in CSV files' ``body`` column).
CAMERA_BODY = "camera"


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
        check_keyframes(times_s, positions_m, quaternions_xyzw, source)
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


def check_keyframes(times_s, positions_m, quats, source: str, rows: list[str] | None = None) -> None:
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
    for name, arr, limit, unit in (("t", times_s, defaults.MAX_TRAJECTORY_TIME_S, "s"),
                                   ("position", positions_m, defaults.MAX_TRAJECTORY_POSITION_M, "m")):
        big = (np.abs(np.asarray(arr, dtype=np.float64).reshape(len(arr), -1)) > limit).any(axis=1)
        if big.any():
            i = int(np.argmax(big))
            raise InputError(f"{name} beyond ±{limit:g} {unit} (expected times in seconds and positions in metres)",
                             path=source, field=where(i))
    steps = np.diff(times_s)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        raise InputError(f"time {float(times_s[i])!r} s does not increase (previous keyframe at "
                         f"{float(times_s[i - 1])!r} s; "
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

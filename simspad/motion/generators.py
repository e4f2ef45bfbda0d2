"""Generators of common motions: a static pose, a linear pan, an orbit, hand-held shake, a spinning object.

Each returns a :class:`~simspad.motion.trajectory.Trajectory` sampled densely enough (keyframes per period or
per revolution, see each function) that its spline follows the analytic motion closely. Trajectory files name
them with ``generator = "<name>"`` (:mod:`simspad.io.trajectory_tables`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from simspad import defaults
from simspad.motion.trajectory import Trajectory, look_at


def _frame_count(duration_s: float, rate_hz: float) -> int:
    n = duration_s * rate_hz
    if not n <= defaults.MAX_GENERATOR_SAMPLES:  # also NaN: refuse before allocating (rpm = 1e15 wanted PiB)
        raise ValueError(f"needs {n:.3g} samples ({duration_s:g} s at {rate_hz:.3g} Hz, set by the speed and "
                         f"rate_hz); the limit is {defaults.MAX_GENERATOR_SAMPLES:,}: check the units of the "
                         "speed, rate_hz and duration_s")
    return max(2, int(math.ceil(n - 1e-9)) + 1)


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


@dataclass(frozen=True)
class Tremor:
    """Band and size of hand tremor (:func:`handheld_shake`).

    Attributes
    ----------
    f_lo_hz, f_hi_hz : float
        Frequency band of the sinusoids, Hz (0 < f_lo_hz ≤ f_hi_hz).
    translation_amplitude_m : float
        Per-axis RMS of the translation, m.
    rotation_amplitude_deg : float
        Per-axis RMS of the rotation, degrees.
    n_components : int
        Sinusoids summed per axis.
    """

    f_lo_hz: float = 1.0
    f_hi_hz: float = 12.0
    translation_amplitude_m: float = 0.002
    rotation_amplitude_deg: float = 0.5
    n_components: int = 24


def handheld_shake(position_m=(0.0, 0.0, 0.0), quaternion_xyzw=(0.0, 0.0, 0.0, 1.0), *, seed: int = 0,
                   tremor: Tremor = Tremor(), duration_s: float = 1.0, rate_hz: float | None = None,
                   yaw_rate_deg_s: float = 0.0, start_yaw_deg: float = 0.0, axis=(0.0, 1.0, 0.0),
                   source: str = "handheld_shake") -> Trajectory:
    """Hand tremor around a base pose, optionally panning: seeded band-limited noise.

    Each translation axis (world) and each rotation axis (body frame, small-angle rotation vector) is a sum of
    ``tremor.n_components`` sinusoids with frequencies drawn uniformly in ``[tremor.f_lo_hz, tremor.f_hi_hz]``,
    random phases and Rayleigh-distributed weights, scaled so that the per-axis RMS (over an infinite time)
    equals ``tremor.translation_amplitude_m`` (m) and ``tremor.rotation_amplitude_deg`` (deg). Deterministic
    for a given ``seed``.

    A hand-held pan: with ``yaw_rate_deg_s`` (deg/s) or ``start_yaw_deg`` (deg) the base pose turns about the
    world ``axis`` through the camera, by ``start_yaw_deg + yaw_rate_deg_s·t`` (right-handed; a pan to the left
    about the up vector for positive rates), and the tremor rides on the turning pose. Without them the pose is
    the base pose plus tremor, as before.
    """
    f_lo_hz, f_hi_hz, n_components = tremor.f_lo_hz, tremor.f_hi_hz, tremor.n_components
    if not 0 < f_lo_hz <= f_hi_hz:
        raise ValueError(f"handheld_shake: expected 0 < f_lo_hz ≤ f_hi_hz, got {f_lo_hz}, {f_hi_hz}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5A4E]))
    # 20 keyframes per period of the highest frequency: spline error ~ (2π/20)^4/384 ≈ 3e-5 of the amplitude;
    # a pan keeps ≥ 8 keyframes per 45° as linear_pan does.
    rate = max(rate_hz or 0.0, 20.0 * f_hi_hz, 8 * abs(yaw_rate_deg_s) / 45.0)
    n = _frame_count(duration_s, rate)
    t = np.linspace(0.0, duration_s, n)

    def band_noise(rms: float) -> np.ndarray:
        freqs = rng.uniform(f_lo_hz, f_hi_hz, size=(3, n_components))
        phases = rng.uniform(0.0, 2 * np.pi, size=(3, n_components))
        weights = rng.rayleigh(1.0, size=(3, n_components))
        weights *= rms * np.sqrt(2.0) / np.sqrt((weights**2).sum(axis=1, keepdims=True))
        return np.einsum("ak,akn->na", weights,
                         np.sin(2 * np.pi * freqs[:, :, None] * t[None, None, :] + phases[:, :, None]))

    dp = band_noise(tremor.translation_amplitude_m)
    dr = band_noise(np.deg2rad(tremor.rotation_amplitude_deg))
    p = np.asarray(position_m, dtype=np.float64) + dp
    base = Rotation.from_quat(quaternion_xyzw)
    if yaw_rate_deg_s != 0.0 or start_yaw_deg != 0.0:
        # Only when asked: composing with an identity turn would still round the quaternion of a plain shake.
        yaw_deg = start_yaw_deg + yaw_rate_deg_s * t
        base = Rotation.from_rotvec(np.deg2rad(yaw_deg)[:, None] * _unit(axis)) * base
    q = (base * Rotation.from_rotvec(dr)).as_quat()
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

"""Retiming: the same motion played ``k`` times faster (``k`` < 1: slower).

A retimed trajectory's pose at time ``t`` is the base trajectory's pose at ``k·t``; velocities scale by ``k``.
It is built by dividing the keyframe times by ``k`` and keeping the keyframe poses: the interpolating splines of
:class:`~simspad.motion.trajectory.Trajectory` (a not-a-knot cubic for positions, ``RotationSpline`` for
orientations) are equivariant under a linear change of the time variable, so the retimed spline *is* the base
spline composed with ``t ↦ k·t`` (to floating-point round-off, ~1e-14 m on the built-in trajectories), with no
resampling error. A retimed trajectory covers ``[t_start / k, t_end / k]``.
"""

from __future__ import annotations

import math

from simspad.motion.trajectory import Trajectory, TrajectorySet


def check_speed_factor(k: float) -> float:
    """``k`` as a float; ValueError unless it is finite and > 0."""
    k = float(k)
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"speed factor must be a finite number > 0, got {k!r}")
    return k


def retimed_trajectory(trajectory: Trajectory, k: float) -> Trajectory:
    """``trajectory`` played ``k`` times faster: pose(t) = base pose(k·t)."""
    k = check_speed_factor(k)
    return Trajectory(trajectory.times_s / k, trajectory.positions_m, trajectory.quaternions_xyzw,
                      source=f"{trajectory.source} ×{k:g}")


def retimed(trajectories: TrajectorySet, k: float) -> TrajectorySet:
    """Every body of ``trajectories`` (camera and objects alike) played ``k`` times faster.

    ``k = 1`` returns the set unchanged (the same object).
    """
    k = check_speed_factor(k)
    if k == 1.0:
        return trajectories
    camera = None if trajectories.camera is None else retimed_trajectory(trajectories.camera, k)
    objects = {name: retimed_trajectory(tr, k) for name, tr in trajectories.objects.items()}
    return TrajectorySet(camera=camera, objects=objects, source=f"{trajectories.source} retimed ×{k:g}",
                         time_offset_s=trajectories.time_offset_s)


def base_span_s(start_s: float, duration_s: float, k: float) -> tuple[float, float]:
    """The span of base-trajectory time, s, that a sequence ``[start_s, start_s + duration_s]`` at speed ``k``
    plays: ``[k·start_s, k·(start_s + duration_s)]``."""
    k = check_speed_factor(k)
    return k * start_s, k * (start_s + duration_s)

"""The speed axis of a dataset: the spec's ``speed = [1.0, 8.0]`` list of speed factors, and the retiming that
plays a trajectory set ``k`` times faster (``k`` < 1: slower).

Every sequence is produced at every factor ``k`` by retiming its trajectory, camera and objects alike
(:func:`retimed`: the pose at time ``t`` is the base pose at ``k·t``). Renders are per (sequence, speed),
recordings per (sequence, speed, lux). The factor 1 keeps the names, seeds and hashes a spec without ``speed``
has always had, so such a spec gives the same files; any other factor adds ``x<k>`` to the names and
``("speed", k)`` to the keys.

A retimed trajectory's velocities scale by ``k``. It is built by dividing the keyframe times by ``k`` and keeping
the keyframe poses: the interpolating splines of :class:`~simspad.motion.trajectory.Trajectory` (a not-a-knot
cubic for positions, ``RotationSpline`` for orientations) are equivariant under a linear change of the time
variable, so the retimed spline *is* the base spline composed with ``t ↦ k·t`` (to floating-point round-off,
~1e-14 m on the built-in trajectories), with no resampling error. A retimed trajectory covers
``[t_start / k, t_end / k]``.
"""

from __future__ import annotations

import math
from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.trajectory_files import load_trajectory
from simspad.motion.trajectory import Trajectory, TrajectorySet
from simspad.scenes.library import resolve_scene

#: Speed factors of a spec without ``speed``.
DEFAULT_SPEEDS = (1.0,)


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


def speed_keys(k: float) -> tuple:
    """Extra seed-stream keys of factor ``k``: none for k = 1, else ``("speed", k)``."""
    return () if float(k) == 1.0 else ("speed", float(k))


def sequence_trajectory_path(scene: str, trajectory: str | None) -> str | None:
    """The sequence's trajectory file: its own, else the scene's default (None: the scene is still)."""
    if trajectory is not None:
        return trajectory
    default = resolve_scene(scene).default_trajectory
    return None if default is None else str(default)


def sequence_trajectories(scene: str, trajectory: str | None, k: float) -> TrajectorySet | str | None:
    """What the renderer gets for a sequence at speed ``k``: at k = 1 the trajectory as the spec gives it (a
    path or None, exactly as without a speed axis), else the loaded set retimed by ``k``."""
    if float(k) == 1.0:
        return trajectory
    path = sequence_trajectory_path(scene, trajectory)
    if path is None:
        return TrajectorySet(camera=None, objects={}, source="<static>")
    return retimed(load_trajectory(path), k)


def coverage_problem(scene: str, trajectory: str | None, start_s: float, duration_s: float,
                     k: float) -> str | None:
    """Why the sequence cannot be played at speed ``k`` (its retimed span runs past the trajectory's coverage),
    or None when it can."""
    path = sequence_trajectory_path(scene, trajectory)
    if path is None:
        return None
    try:
        ts = load_trajectory(path)
    except SimSpadError:
        return None  # reported by the sequence's own trajectory check
    if not ts.bodies() or ts.is_static:
        return None
    t0, t1 = ts.t_start, ts.t_end
    b0, b1 = base_span_s(start_s, duration_s, k)
    eps = 1e-9 * max(1.0, abs(t1))
    if b0 >= t0 - eps and b1 <= t1 + eps:
        return None
    longest = t1 / (start_s + duration_s) if start_s + duration_s > 0 else float("inf")
    return (f"at speed ×{k:g} the sequence plays {b0:g}–{b1:g} s of its trajectory {Path(path).name}, which "
            f"covers {t0:g}–{t1:g} s (expected a factor ≤ {longest:g}, or a shorter duration_s)")

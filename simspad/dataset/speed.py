"""The speed axis of a dataset: the spec's ``speed = [1.0, 8.0]`` list of speed factors.

Every sequence is produced at every factor ``k`` by retiming its trajectory, camera and objects alike
(:func:`simspad.motion.retiming.retimed`: the pose at time ``t`` is the base pose at ``k·t``). Renders are per
(sequence, speed), recordings per (sequence, speed, lux). The factor 1 keeps the names, seeds and hashes a spec
without ``speed`` has always had, so such a spec gives the same files; any other factor adds ``x<k>`` to the
names and ``("speed", k)`` to the keys.
"""

from __future__ import annotations

from pathlib import Path

from simspad.errors import SimSpadError
from simspad.io.trajectory_files import load_trajectory
from simspad.motion.retiming import base_span_s, retimed
from simspad.motion.trajectory import TrajectorySet
from simspad.scenes.library import resolve_scene

#: Speed factors of a spec without ``speed``.
DEFAULT_SPEEDS = (1.0,)


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

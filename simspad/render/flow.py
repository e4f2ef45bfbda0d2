"""Image motion of a loaded scene along a trajectory: poses per instant, and the predicted image speed that
:func:`simspad.render.schedule.keyframe_schedule` turns into keyframe instants.

The speed bound adds the camera-induced flow (:func:`~simspad.render.schedule.camera_flow_bound`, for scene
points at the near depth or farther) and each animated object's own flow
(:func:`~simspad.render.schedule.object_flow_bound`). The near depth is a low percentile of a few cheap depth
renders spread over the rendered span.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from simspad.motion.trajectory import TrajectorySet
from simspad.render.mitsuba_scene import MitsubaScene
from simspad.render.schedule import camera_flow_bound, object_flow_bound

#: Scene-depth percentile that bounds image motion from camera translation.
NEAR_DEPTH_PERCENTILE = 2.0
#: Depth probes (evenly spaced instants) used to predict image motion before rendering.
DEPTH_PROBES = 5


def camera_poses(ts: TrajectorySet, rest_camera: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Camera-to-world (N, 4, 4) at ``times`` (s): the trajectory's camera, or the scene's own (``rest_camera``)."""
    cam = ts.camera.pose(times) if ts.camera is not None else np.repeat(rest_camera[None], len(times), axis=0)
    return np.asarray(cam).reshape(len(times), 4, 4)


def object_poses(ts: TrajectorySet, t: float) -> dict[str, np.ndarray]:
    """``object_to_world`` (4, 4) of every animated object at instant ``t`` (s)."""
    return {name: np.asarray(tr.pose(t)).reshape(4, 4) for name, tr in ts.objects.items()}


def predicted_flow_fn(ts: TrajectorySet, ms: MitsubaScene, near_depth_m: float) -> Callable[[np.ndarray], np.ndarray]:
    """``max_flow(times) -> ndarray``: an upper bound of the image speed (px/s) anywhere in the image."""
    def max_flow(times):
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        cam = camera_poses(ts, ms.rest_camera_to_world, times)
        if ts.camera is not None:
            v, w = ts.camera.velocity(times)
            total = camera_flow_bound(cam, np.reshape(v, (-1, 3)), np.reshape(w, (-1, 3)), near_depth_m,
                                      ms.focal_px, ms.width, ms.height)
        else:
            total = np.zeros(len(times))
        for name, tr in ts.objects.items():
            v, w = tr.velocity(times)
            total = total + object_flow_bound(cam, np.asarray(tr.pose(times)).reshape(-1, 4, 4), np.reshape(v, (-1, 3)),
                                              np.reshape(w, (-1, 3)), ms.objects[name]["points"], ms.focal_px,
                                              ms.width, ms.height)
        return total

    return max_flow


def near_depth(ts: TrajectorySet, ms: MitsubaScene, t0: float, t1: float, seed: int) -> float:
    """A low percentile of scene depth (m) over a few probe instants in [t0, t1] (depth pass only: cheap)."""
    near = np.inf
    for t in np.linspace(t0, t1, DEPTH_PROBES):
        ms.set_pose(camera_poses(ts, ms.rest_camera_to_world, np.array([t]))[0], object_poses(ts, t))
        z = ms.render_depth(seed)
        finite = z[np.isfinite(z)]
        if finite.size:
            near = min(near, float(np.percentile(finite, NEAR_DEPTH_PERCENTILE)))
    return near if np.isfinite(near) else 1.0


def max_step_flow(flow_fn: Callable[[np.ndarray], np.ndarray], times: np.ndarray, samples: int = 8) -> float:
    """Largest predicted image motion (px) between consecutive keyframes (speed integrated per step)."""
    u = (np.arange(samples) + 0.5) / samples
    inner = times[:-1, None] + np.diff(times)[:, None] * u[None, :]
    speed = np.asarray(flow_fn(inner.ravel())).reshape(inner.shape)
    return float(np.max(speed.mean(axis=1) * np.diff(times))) if len(times) > 1 else 0.0

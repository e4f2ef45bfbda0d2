"""Adaptive keyframe schedule: render only the instants that matter (ESIM's rule, applied before rendering).

Between consecutive keyframes the largest image-space motion must stay below ``max_flow_px``, so that linear
interpolation in time is accurate; and keyframes are never further apart than ``1 / min_rate_hz``. The image
speed (px/s) is predicted from the camera's linear and angular velocity, the objects' rigid motion, a near scene
depth and the focal length in pixels (:func:`camera_flow_bound`, :func:`object_flow_bound`).
"""

from __future__ import annotations

import math
import os
from typing import Callable

import numpy as np

from simspad import defaults
from simspad.errors import SimSpadError

#: Grid cells per smallest keyframe interval when integrating the predicted image speed.
_CELLS_PER_STEP = 4
#: Image points per axis at which the camera-induced flow is evaluated (its maximum lies on the border).
_FLOW_GRID = 9


def keyframe_schedule(t0: float, t1: float, max_flow_fn: Callable[[np.ndarray], np.ndarray], max_flow_px: float,
                      min_rate_hz: float) -> np.ndarray:
    """Instants in [t0, t1] whose consecutive image motion stays ≤ ``max_flow_px``, at least ``min_rate_hz``.

    Parameters
    ----------
    t0, t1 : float
        Interval in seconds (t1 > t0). Both ends are keyframes.
    max_flow_fn : callable
        ``max_flow_fn(t: ndarray) -> ndarray``: an upper bound of the image speed (px/s) anywhere in the image
        at each instant.
    max_flow_px : float
        Largest image motion allowed between consecutive keyframes, pixels.
    min_rate_hz : float
        Keyframes are never further apart than ``1 / min_rate_hz``.

    Returns
    -------
    ndarray
        Strictly increasing instants (float64, s), first t0, last t1.

    Notes
    -----
    The motion between two instants is bounded by the integral of the image speed, evaluated on a grid fine
    enough (several cells per keyframe step) with each cell taking the larger speed at its two ends. Keyframes
    are placed greedily, each as far as the bound allows.
    """
    if not (t1 > t0):
        raise ValueError(f"t1 = {t1!r} must exceed t0 = {t0!r}")
    if not (max_flow_px > 0 and min_rate_hz > 0):
        raise ValueError("max_flow_px and min_rate_hz must be > 0")
    max_step_s = 1.0 / min_rate_hz
    coarse = np.linspace(t0, t1, max(2, min(4097, int(math.ceil((t1 - t0) / max_step_s)) * 2 + 1)))
    v_peak = float(np.max(np.abs(max_flow_fn(coarse))))
    step_s = max_step_s if v_peak <= 0 else min(max_step_s, max_flow_px / v_peak)
    n_keyframes = (t1 - t0) / step_s
    if not n_keyframes <= defaults.MAX_KEYFRAMES and os.environ.get("SIMSPAD_IGNORE_LIMITS", "") != "1":
        # Refuse before allocating the integration grid (a 0.5 m jump in 0.1 µs asked for gigabytes).
        raise SimSpadError(f"the motion needs up to {n_keyframes:.3g} keyframes (peak image speed {v_peak:.3g} px/s "
                           f"at max_flow_px = {max_flow_px:g} over {t1 - t0:g} s); the limit is "
                           f"{defaults.MAX_KEYFRAMES:,}: check the trajectory for a jump or a unit slip, or raise "
                           "max_flow_px (SIMSPAD_IGNORE_LIMITS=1 to try anyway)", field="trajectory")
    n_cells = max(1, int(math.ceil((t1 - t0) / step_s * _CELLS_PER_STEP)))
    grid = np.linspace(t0, t1, n_cells + 1)
    speed = np.abs(np.asarray(max_flow_fn(grid), dtype=np.float64))
    mid = np.abs(np.asarray(max_flow_fn(0.5 * (grid[:-1] + grid[1:])), dtype=np.float64))
    cell_speed = np.maximum(np.maximum(speed[:-1], speed[1:]), mid)
    flow = np.concatenate([[0.0], np.cumsum(cell_speed * np.diff(grid))])

    eps_s = 1e-12 * max(1.0, abs(t1))
    picked = [0]
    i = 0
    while i < n_cells:
        j_flow = int(np.searchsorted(flow, flow[i] + max_flow_px, side="right")) - 1
        j_time = int(np.searchsorted(grid, grid[i] + max_step_s + eps_s, side="right")) - 1
        i = max(i + 1, min(j_flow, j_time, n_cells))
        picked.append(i)
    return grid[picked]


def flow_grid(width: int, height: int, focal_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates (x/z, y/z) of a grid over the image, borders included."""
    half_w = 0.5 * width / focal_px
    half_h = 0.5 * height / focal_px
    x, y = np.meshgrid(np.linspace(-half_w, half_w, _FLOW_GRID), np.linspace(-half_h, half_h, _FLOW_GRID))
    return x.ravel(), y.ravel()


def camera_flow_bound(camera_to_world: np.ndarray, linear_m_s: np.ndarray, angular_rad_s: np.ndarray,
                      near_depth_m: float, focal_px: float, width: int, height: int) -> np.ndarray:
    """Largest image speed (px/s) caused by camera motion, for scene points at ``near_depth_m`` or farther.

    Uses the motion field of a pinhole camera. In camera coordinates a static point P = Z·q, q = (x, y, 1),
    moves as Ṗ = −v − ω × P for camera velocities v, ω, so its normalised image velocity is
    (−v_xy + q_xy·v_z)/Z − ((ω × q)_xy − q_xy·(ω × q)_z): a translational part in 1/Z plus a rotational part
    independent of depth. Its magnitude is convex in 1/Z, so over all depths Z ≥ ``near_depth_m`` it peaks at
    the near depth or at infinity: the bound takes the larger of the two at every point of an image grid.

    Parameters
    ----------
    camera_to_world : ndarray (N, 4, 4)
    linear_m_s, angular_rad_s : ndarray (N, 3)
        World-frame camera velocities.
    near_depth_m : float
        A near scene depth (a low percentile of the depth map).
    focal_px : float
        Focal length in pixels.
    width, height : int
        Image size in pixels.

    Returns
    -------
    ndarray (N,)
        px/s.
    """
    rot = np.asarray(camera_to_world)[:, :3, :3]
    v = np.einsum("nji,nj->ni", rot, np.asarray(linear_m_s))  # world → camera: Rᵀ·v
    w = np.einsum("nji,nj->ni", rot, np.asarray(angular_rad_s))
    x, y = flow_grid(width, height, focal_px)
    q = np.stack([x, y, np.ones_like(x)], axis=1)  # (G, 3)
    qxy = q[None, :, :2]
    trans = -v[:, None, :2] + qxy * v[:, None, 2:3]
    cross = np.cross(w[:, None, :], q[None, :, :])
    rotational = -(cross[..., :2] - qxy * cross[..., 2:3])
    near = np.linalg.norm(trans / max(near_depth_m, 1e-6) + rotational, axis=-1)
    far = np.linalg.norm(rotational, axis=-1)
    return focal_px * np.max(np.maximum(near, far), axis=1)


def object_flow_bound(camera_to_world: np.ndarray, object_to_world: np.ndarray, linear_m_s: np.ndarray,
                      angular_rad_s: np.ndarray, rest_points_m: np.ndarray, focal_px: float, width: int,
                      height: int) -> np.ndarray:
    """Largest image speed (px/s) of a rigidly moving object's own motion (camera motion bounded separately).

    A point p of the object moves at v + ω × (p − c) (c the object origin); its image speed is at most
    f·|v_p|·sqrt(1 + r²)/Z with r the largest normalised image radius and Z the object's nearest camera depth.

    Parameters
    ----------
    camera_to_world, object_to_world : ndarray (N, 4, 4)
    linear_m_s, angular_rad_s : ndarray (N, 3)
        World-frame velocity of the object's origin and its angular velocity.
    rest_points_m : ndarray (M, 3)
        Points spanning the object in its rest pose (vertices or bounding-box corners).
    """
    rest = np.asarray(rest_points_m, dtype=np.float64)
    obj = np.asarray(object_to_world)
    world = np.einsum("nij,mj->nmi", obj[:, :3, :3], rest) + obj[:, None, :3, 3]
    arm = world - obj[:, None, :3, 3]
    speed = np.linalg.norm(np.asarray(linear_m_s)[:, None, :] + np.cross(np.asarray(angular_rad_s)[:, None, :], arm),
                           axis=-1)
    cam = np.asarray(camera_to_world)
    depth = np.einsum("nj,nmj->nm", cam[:, :3, 2], world - cam[:, None, :3, 3])  # along the optical axis (+Z)
    near = np.maximum(np.min(depth, axis=1), 1e-3)  # an object at or behind the camera plane: cap, do not explode
    r2 = (0.5 * width / focal_px) ** 2 + (0.5 * height / focal_px) ** 2
    return focal_px * np.max(speed, axis=1) * math.sqrt(1 + r2) / near


def focal_length_px(x_fov_deg: float, width: int) -> float:
    """Focal length in pixels of a pinhole camera with horizontal field of view ``x_fov_deg``."""
    return 0.5 * width / math.tan(math.radians(x_fov_deg) / 2)


def brute_force_keyframes(duration_s: float, bin_s: float) -> int:
    """Keyframes a renderer without adaptive sampling would need: one per SPAD bin of ``bin_s`` seconds (plus the
    end). The bin is the sensor preset's (:class:`simspad.sensors.presets.SpadParams`), passed in by the caller:
    the renderer imports no sensor."""
    return int(math.ceil(duration_s / bin_s - 1e-9)) + 1

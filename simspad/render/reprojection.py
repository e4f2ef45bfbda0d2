"""Pinhole reprojection between keyframes: pixel + depth → world point → pixel of another pose.

The camera model is the one the renderer uses (:mod:`simspad.render.mitsuba_scene`): a Mitsuba ``perspective``
sensor with horizontal field of view ``x_fov_deg`` (``fov_axis = "x"``), square pixels and the principal point at
the image centre. In camera coordinates the camera looks along +Z with +Y up and +X to the *left* (Mitsuba's
convention), and image rows run downwards, so the pixel whose centre is at column ``c``, row ``r`` (0-based) sees
the direction

    d = (−(c + ½ − W/2) / f, −(r + ½ − H/2) / f, 1),  f = (W/2) / tan(x_fov / 2)  (pixels).

Depth is ``Z``: the distance along the optical axis in metres (what a keyframe's ``Z`` channel holds, ``inf``
where the ray hits nothing), so the camera-space point of a pixel is ``Z · d`` and the world point is
``camera_to_world · (Z · d, 1)`` with ``camera_to_world`` as stored per keyframe in ``timeline.json``.

Continuous pixel coordinates returned by :func:`project` are *index* coordinates: ``(col_px, row_px) = (c, r)``
at the centre of pixel ``[r, c]``, the convention of :func:`scipy.ndimage.map_coordinates`.

Object ids
----------
A scene with animated objects needs to know which object each pixel shows, to move its point with that object's
transform rather than with the static world. Keyframes of such scenes carry one extra EXR channel,
:data:`OBJECT_ID_CHANNEL` (float32 holding small integers): 0 for the static scene (and for rays that hit
nothing), ``k ≥ 1`` for the k-th name of ``timeline.json``'s ``renderer.animated_objects`` (sorted object ids).
Each keyframe of ``timeline.json`` then also lists ``object_to_world`` (``{name: 4x4}``) at its instant. Readers
that do not know the channel ignore it (:func:`simspad.io.exr.read_exr` returns it as ``"object_id"``).
A point of object k seen in keyframe a at world position p moves to ``M_k(t) · M_k(t_a)⁻¹ · p`` at instant t
(:func:`move_points`).
"""

from __future__ import annotations

import numpy as np

from simspad.io.exr import OBJECT_ID_CHANNEL
from simspad.motion.pinhole import PinholeCamera, move_points, project, unproject

__all__ = ["OBJECT_ID_CHANNEL", "STATIC_ID", "PinholeCamera", "image_motion_px", "move_points", "project",
           "reproject", "unproject"]

#: Object id of the static scene and of rays that hit nothing.
STATIC_ID = 0


def reproject(camera: PinholeCamera, depth_z: np.ndarray, from_camera: np.ndarray, to_camera: np.ndarray,
              object_id: np.ndarray | None = None, from_objects: list | None = None,
              to_objects: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where every pixel of a keyframe (depth ``depth_z`` at pose ``from_camera``) lands at pose ``to_camera``.

    Animated objects (``object_id`` with ``from_objects`` / ``to_objects`` as in :func:`move_points`) move with
    their own transforms. Returns ``(col_px, row_px, depth_z)`` at the target, each [H, W] (NaN where the pixel
    hit nothing or lands behind the camera).
    """
    points = unproject(camera, depth_z, from_camera)
    points = move_points(points, object_id, from_objects or [], to_objects or [])
    return project(camera, points, to_camera)


def image_motion_px(camera: PinholeCamera, depth_z: np.ndarray, from_camera: np.ndarray, to_camera: np.ndarray,
                    object_id: np.ndarray | None = None, from_objects: list | None = None,
                    to_objects: list | None = None) -> np.ndarray:
    """Per-pixel image displacement (pixels) between two poses: [H, W, 2] as (Δcol, Δrow), NaN where unknown."""
    col, row, _ = reproject(camera, depth_z, from_camera, to_camera, object_id, from_objects, to_objects)
    c0 = np.arange(camera.width, dtype=np.float64)[None, :]
    r0 = np.arange(camera.height, dtype=np.float64)[:, None]
    return np.stack([col - c0, row - r0], axis=-1)

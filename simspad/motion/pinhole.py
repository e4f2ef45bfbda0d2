"""The renderer's pinhole camera: intrinsics from the horizontal field of view, unprojection of a depth map to world
points, projection of world points to pixels, and the rigid motion of animated objects' points.

The camera model is a Mitsuba ``perspective`` sensor with horizontal field of view ``x_fov_deg`` (``fov_axis =
"x"``), square pixels and the principal point at the image centre. In camera coordinates the camera looks along +Z
with +Y up and +X to the *left* (Mitsuba's convention), and image rows run downwards, so the pixel whose centre is
at column ``c``, row ``r`` (0-based) sees the direction

    d = (−(c + ½ − W/2) / f, −(r + ½ − H/2) / f, 1),  f = (W/2) / tan(x_fov / 2)  (pixels).

Depth is ``Z``: the distance along the optical axis in metres (``inf`` where the ray hits nothing), so the
camera-space point of a pixel is ``Z · d`` and the world point is ``camera_to_world · (Z · d, 1)``.

Continuous pixel coordinates are *index* coordinates: ``(col_px, row_px) = (c, r)`` at the centre of pixel
``[r, c]``, the convention of :func:`scipy.ndimage.map_coordinates`. In these coordinates the intrinsic matrix
of the equivalent OpenCV camera (x right, y down, z forward) is :meth:`PinholeCamera.K`.

This module sits in the motion layer so that both the renderer (keyframe synthesis) and the sensors' ground truth
(motion field) use one camera model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MITSUBA_TO_OPENCV", "PinholeCamera", "move_points", "project", "unproject"]

#: Mitsuba camera axes (+X left, +Y up, +Z forward) to OpenCV's (x right, y down, z forward): a camera-space point
#: p_cv = MITSUBA_TO_OPENCV · p_mitsuba.
MITSUBA_TO_OPENCV = np.diag([-1.0, -1.0, 1.0])


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics of the renderer's pinhole camera.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    focal_px : float
        Focal length in pixels (square pixels, principal point at the image centre).
    """

    width: int
    height: int
    focal_px: float

    @classmethod
    def from_fov(cls, x_fov_deg: float, width: int, height: int) -> PinholeCamera:
        """The camera of a Mitsuba perspective sensor with horizontal field of view ``x_fov_deg`` (degrees)."""
        if not 0 < x_fov_deg < 180:
            raise ValueError(f"x_fov_deg must be in (0, 180), got {x_fov_deg!r}")
        return cls(int(width), int(height), 0.5 * int(width) / math.tan(math.radians(x_fov_deg) / 2))

    @classmethod
    def from_timeline_meta(cls, meta: dict) -> PinholeCamera:
        """The camera of a render directory written by :func:`simspad.render.renderer.render_sequence`
        (``width``, ``height`` and ``renderer.x_fov_deg`` of its ``timeline.json``)."""
        return cls.from_fov(float(meta["renderer"]["x_fov_deg"]), int(meta["width"]), int(meta["height"]))

    @property
    def principal_point_px(self) -> tuple[float, float]:
        """Principal point ``(cx, cy)`` in index coordinates (the image centre: ``(W/2 − ½, H/2 − ½)``), px."""
        return 0.5 * self.width - 0.5, 0.5 * self.height - 0.5

    @property
    def y_fov_deg(self) -> float:
        """Vertical field of view, degrees."""
        return math.degrees(2.0 * math.atan(0.5 * self.height / self.focal_px))

    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix (float64, px) of the equivalent OpenCV camera (x right, y down, z forward, index
        coordinates): ``(c, r, 1)ᵀ ∝ K · p_cv`` with ``p_cv = MITSUBA_TO_OPENCV · p_camera``."""
        cx, cy = self.principal_point_px
        return np.array([[self.focal_px, 0.0, cx], [0.0, self.focal_px, cy], [0.0, 0.0, 1.0]])

    def rays(self) -> np.ndarray:
        """Camera-space direction of every pixel centre, scaled to unit Z: [H, W, 3] float64."""
        x = -(np.arange(self.width) + 0.5 - 0.5 * self.width) / self.focal_px
        y = -(np.arange(self.height) + 0.5 - 0.5 * self.height) / self.focal_px
        d = np.empty((self.height, self.width, 3))
        d[..., 0] = x[None, :]
        d[..., 1] = y[:, None]
        d[..., 2] = 1.0
        return d


def unproject(camera: PinholeCamera, depth_z: np.ndarray, camera_to_world: np.ndarray) -> np.ndarray:
    """World points (m) of every pixel of a depth map.

    Parameters
    ----------
    camera : PinholeCamera
    depth_z : ndarray [H, W]
        Depth along the optical axis, metres; ``inf`` (no hit) gives non-finite points.
    camera_to_world : ndarray (4, 4)
        Pose of the camera (Mitsuba convention, as in ``timeline.json``).

    Returns
    -------
    ndarray [H, W, 3] float64
    """
    z = np.asarray(depth_z, dtype=np.float64)
    if z.shape != (camera.height, camera.width):
        raise ValueError(f"depth must be {(camera.height, camera.width)}, got {z.shape}")
    m = np.asarray(camera_to_world, dtype=np.float64)
    with np.errstate(invalid="ignore"):  # inf depth: inf·0 on the axis gives NaN, a point that does not exist
        p_cam = camera.rays() * z[..., None]
        return p_cam @ m[:3, :3].T + m[:3, 3]


def project(camera: PinholeCamera, points_world: np.ndarray, camera_to_world: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel coordinates and depth of world points seen from ``camera_to_world``.

    Parameters
    ----------
    camera : PinholeCamera
    points_world : ndarray [..., 3]
        World points, metres.
    camera_to_world : ndarray (4, 4)

    Returns
    -------
    col_px, row_px : ndarray [...]
        Continuous index coordinates (``(c, r)`` at the centre of pixel ``[r, c]``); NaN for points at or
        behind the camera plane.
    depth_z : ndarray [...]
        Depth along the optical axis, metres (≤ 0: behind the camera).
    """
    m = np.asarray(camera_to_world, dtype=np.float64)
    p = np.asarray(points_world, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Background pixels (no hit) carry infinite points: inf·0 in the product gives the NaN they should get.
        p_cam = (p - m[:3, 3]) @ m[:3, :3]  # world → camera: Rᵀ·(p − o) for a rigid pose
        z = p_cam[..., 2]
        inv = np.where(z > 0, 1.0 / z, np.nan)
        col = -p_cam[..., 0] * inv * camera.focal_px + 0.5 * camera.width - 0.5
        row = -p_cam[..., 1] * inv * camera.focal_px + 0.5 * camera.height - 0.5
    return col, row, z


def move_points(points_world: np.ndarray, object_id: np.ndarray | None, from_poses: list[np.ndarray],
                to_poses: list[np.ndarray]) -> np.ndarray:
    """Carry world points of animated objects from one instant to another (static points stay).

    Parameters
    ----------
    points_world : ndarray [..., 3]
    object_id : ndarray [...] or None
        :data:`OBJECT_ID_CHANNEL` values; None: every point is static.
    from_poses, to_poses : list of ndarray (4, 4)
        ``object_to_world`` of object k (k = 1, 2, ...) at the source and the target instant: entry ``k − 1``.

    Returns
    -------
    ndarray [..., 3]
        ``M_k(to) · M_k(from)⁻¹ · p`` where the id is k, ``p`` where it is 0.
    """
    out = np.array(points_world, dtype=np.float64, copy=True)
    if object_id is None or not from_poses:
        return out
    ids = np.rint(np.asarray(object_id)).astype(np.int64)
    for k, (a, b) in enumerate(zip(from_poses, to_poses), start=1):
        sel = ids == k
        if not sel.any():
            continue
        rel = np.asarray(b, dtype=np.float64) @ np.linalg.inv(np.asarray(a, dtype=np.float64))
        out[sel] = out[sel] @ rel[:3, :3].T + rel[:3, 3]
    return out

"""The exact motion field of a rendered scene: where each pixel's surface point goes over an interval, its
instantaneous image velocity, and whether the point is still visible at the end.

This is the *motion field of surfaces* (the projection of the 3-D motion of the surface point a pixel centre sees),
computed from geometry: depth, the camera's poses and intrinsics, and each animated object's rigid motion. It is
not brightness-constancy optical flow: shading, shadows, reflections and emission changes do not move it, and it
is defined on untextured surfaces too.

Conventions (docs/format.md, section 3): forward (from instant t to t + Δt), in pixels, ``[..., 0]`` along x
(columns, to the right) and ``[..., 1]`` along y (rows, downwards), pixel centres at integer index coordinates.
A pixel that sees nothing (infinite depth) is a direction, not a point: it moves with the camera's rotation only.
"""

from __future__ import annotations

import numpy as np

from simspad.motion.pinhole import PinholeCamera, project, unproject

__all__ = ["DEPTH_REL_TOLERANCE", "flow_validity", "image_velocity", "motion_field", "relative_motion"]

#: Depth agreement for visibility: a moved point is seen at t + Δt when the depth there is within this fraction
#: of its own depth (plus the local depth slope over one pixel, for surfaces seen at grazing angles).
DEPTH_REL_TOLERANCE = 0.02


def relative_motion(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """The rigid motion ``M(t_b) · M(t_a)⁻¹`` (4×4) that carries a world point attached to a body from ``t_a`` to
    ``t_b``, given the body's ``object_to_world`` at both instants."""
    return np.asarray(pose_b, np.float64) @ np.linalg.inv(np.asarray(pose_a, np.float64))


def _pixel_grid(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    return (np.arange(camera.width, dtype=np.float64)[None, :], np.arange(camera.height, dtype=np.float64)[:, None])


def motion_field(camera: PinholeCamera, depth_z: np.ndarray, instance: np.ndarray, camera_a: np.ndarray,
                 camera_b: np.ndarray, moves: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Forward motion field from instant a to instant b.

    Parameters
    ----------
    camera : PinholeCamera
    depth_z : ndarray [H, W]
        Depth along the optical axis at a, m, at the pixel centres (``inf``: nothing hit).
    instance : ndarray [H, W] int
        Instance id of each pixel at a (0: nothing hit).
    camera_a, camera_b : ndarray (4, 4)
        ``camera_to_world`` at a and b (Mitsuba convention).
    moves : dict of int to ndarray (4, 4)
        Instance id → :func:`relative_motion` of that animated object from a to b; other instances are static.

    Returns
    -------
    flow : ndarray [H, W, 2] float64
        Displacement (Δx right, Δy down), px; NaN where the point lies at or behind the camera plane at b.
    depth_b : ndarray [H, W] float64
        The moved point's depth at b, m (``inf`` for directions).
    """
    depth = np.asarray(depth_z, dtype=np.float64)
    finite = np.isfinite(depth)
    points = unproject(camera, np.where(finite, depth, 1.0), camera_a)
    ids = np.asarray(instance)
    for k, rel in moves.items():
        sel = finite & (ids == k)
        if sel.any():
            points[sel] = points[sel] @ rel[:3, :3].T + rel[:3, 3]
    col, row, z = project(camera, points, camera_b)
    if not finite.all():
        # Directions: rotate the ray into camera b and project it (translation does not move a point at infinity).
        ra, rb = np.asarray(camera_a, np.float64)[:3, :3], np.asarray(camera_b, np.float64)[:3, :3]
        d = camera.rays()[~finite] @ (rb.T @ ra).T
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(d[:, 2] > 0, 1.0 / d[:, 2], np.nan)
        cx, cy = camera.principal_point_px
        col[~finite] = -d[:, 0] * inv * camera.focal_px + cx
        row[~finite] = -d[:, 1] * inv * camera.focal_px + cy
        z[~finite] = np.where(d[:, 2] > 0, np.inf, np.nan)
    c0, r0 = _pixel_grid(camera)
    return np.stack([col - c0, row - r0], axis=-1), z


def _one_sided_slope(depth: np.ndarray) -> np.ndarray:
    """Per pixel, the smaller absolute depth step to a neighbour along columns plus that along rows (m): the
    slope of a surface over one pixel, which stays small at an occlusion edge (one side is the same surface)."""
    with np.errstate(invalid="ignore"):
        out = np.zeros_like(depth)
        for axis in (0, 1):
            d = np.abs(np.diff(depth, axis=axis))
            pad_lo = [(0, 0), (0, 0)]
            pad_hi = [(0, 0), (0, 0)]
            pad_lo[axis] = (1, 0)
            pad_hi[axis] = (0, 1)
            back = np.pad(d, pad_lo, constant_values=np.inf)
            fwd = np.pad(d, pad_hi, constant_values=np.inf)
            step = np.fmin(back, fwd)
            out += np.where(np.isfinite(step), step, 0.0)
    return out


def flow_validity(camera: PinholeCamera, flow: np.ndarray, depth_moved: np.ndarray, instance_a: np.ndarray,
                  depth_b: np.ndarray, instance_b: np.ndarray) -> np.ndarray:
    """Where the motion field can be checked against the image at b: the moved point lands inside the image and
    is the surface seen there (same instance, depth within :data:`DEPTH_REL_TOLERANCE` plus the local slope); a
    direction (nothing hit) lands where nothing is hit either.

    Returns
    -------
    ndarray [H, W] bool
    """
    c0, r0 = _pixel_grid(camera)
    col, row = c0 + flow[..., 0], r0 + flow[..., 1]
    with np.errstate(invalid="ignore"):
        inside = (col >= -0.5) & (col < camera.width - 0.5) & (row >= -0.5) & (row < camera.height - 0.5)
    ci = np.clip(np.rint(np.nan_to_num(col)), 0, camera.width - 1).astype(np.intp)
    ri = np.clip(np.rint(np.nan_to_num(row)), 0, camera.height - 1).astype(np.intp)
    db = np.asarray(depth_b, np.float64)
    seen_depth = db[ri, ci]
    same = np.asarray(instance_b)[ri, ci] == np.asarray(instance_a)
    direction = ~np.isfinite(depth_moved)
    with np.errstate(invalid="ignore"):
        tol = DEPTH_REL_TOLERANCE * depth_moved + _one_sided_slope(db)[ri, ci]
        agrees = np.where(direction, ~np.isfinite(seen_depth), np.abs(seen_depth - depth_moved) <= tol)
    return inside & same & agrees & ~np.isnan(depth_moved)


def image_velocity(camera: PinholeCamera, depth_z: np.ndarray, instance: np.ndarray, camera_to_world: np.ndarray,
                   camera_velocity: tuple, objects: dict[int, tuple]) -> np.ndarray:
    """Instantaneous image velocity of every pixel's surface point, px s⁻¹ ([H, W, 2], x right, y down).

    Parameters
    ----------
    camera, depth_z, instance
        As :func:`motion_field`.
    camera_to_world : ndarray (4, 4)
    camera_velocity : (v, w)
        The camera's linear (m s⁻¹) and angular (rad s⁻¹) velocity, world frame.
    objects : dict of int to (pose, v, w)
        Instance id → that animated object's ``object_to_world``, linear and angular velocity (world frame).

    Notes
    -----
    A point X of a body with origin o, velocity v and angular velocity ω moves at ``v + ω × (X − o)``. In the
    camera frame ``P = Rᵀ(X − o_c)`` moves at ``Ṗ = Rᵀ(Ẋ − v_c − ω_c × (X − o_c))``, and the pixel
    ``c = −f·P_x/P_z + c_x`` at ``ċ = −f·(Ṗ_x·P_z − P_x·Ṗ_z)/P_z²`` (likewise the row with P_y).
    """
    depth = np.asarray(depth_z, dtype=np.float64)
    finite = np.isfinite(depth)
    m = np.asarray(camera_to_world, np.float64)
    origin, rot = m[:3, 3], m[:3, :3]
    v_c, w_c = (np.asarray(a, np.float64) for a in camera_velocity)
    # Directions (no hit) are unit-depth rays that only the camera's rotation moves.
    x = unproject(camera, np.where(finite, depth, 1.0), m)
    rel = x - origin
    x_dot = np.zeros_like(x)
    ids = np.asarray(instance)
    for k, (pose, v, w) in objects.items():
        sel = finite & (ids == k)
        if sel.any():
            o = np.asarray(pose, np.float64)[:3, 3]
            x_dot[sel] = np.asarray(v, np.float64) + np.cross(np.asarray(w, np.float64), x[sel] - o)
    rel_dot = x_dot - np.cross(w_c, rel)
    rel_dot[finite] -= v_c
    p = rel @ rot
    p_dot = rel_dot @ rot
    f = camera.focal_px
    with np.errstate(divide="ignore", invalid="ignore"):
        inv2 = np.where(p[..., 2] > 0, 1.0 / p[..., 2] ** 2, np.nan)
        vc = -f * (p_dot[..., 0] * p[..., 2] - p[..., 0] * p_dot[..., 2]) * inv2
        vr = -f * (p_dot[..., 1] * p[..., 2] - p[..., 1] * p_dot[..., 2]) * inv2
    return np.stack([vc, vr], axis=-1)

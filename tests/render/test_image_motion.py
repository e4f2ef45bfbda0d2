"""Measured image motion against an analytic camera pan (known image speed from focal length and angular rate)."""

import math

import numpy as np
import pytest

from simspad.io.render_dir import write_render_dir
from simspad.render.image_motion import measure_image_motion, motion_attrs
from simspad.render.reprojection import PinholeCamera

W, H, FOV_DEG = 48, 36, 60.0
RATE_RAD_S = 2.0  # pan about the camera's vertical axis


def _pan_pose(theta: float) -> np.ndarray:
    """Camera at the origin, rotated by theta about world +Y (looking along +Z at theta = 0)."""
    c, s = math.cos(theta), math.sin(theta)
    m = np.eye(4)
    m[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    return m


def _pan_render(tmp_path, depth_m: float, n: int = 41, duration_s: float = 0.02):
    times = np.linspace(0.0, duration_s, n)
    poses = np.stack([_pan_pose(RATE_RAD_S * t) for t in times])
    frames = np.ones((n, H, W), np.float32)
    depth = np.full((n, H, W), depth_m, np.float32)
    return write_render_dir(tmp_path / f"pan{depth_m:g}", times, frames, depth, poses,
                            renderer={"x_fov_deg": FOV_DEG}).parent, times


def _expected_displacement_px(theta: float) -> np.ndarray:
    """Image displacement of every pixel when the camera pans by theta, by rotating each pixel's ray (a static
    point's direction) into the rotated camera: independent of depth for a pure rotation."""
    f = PinholeCamera.from_fov(FOV_DEG, W, H).focal_px
    u = (np.arange(W) + 0.5 - W / 2)[None, :] * np.ones((H, 1))  # image x (right), px from the centre
    v = (np.arange(H) + 0.5 - H / 2)[:, None] * np.ones((1, W))  # image y (down)
    x, y = -u / f, -v / f  # camera-frame ray (x left, y up, z = 1)
    c, s = math.cos(theta), math.sin(theta)
    x2, z2 = c * x - s * 1.0, s * x + c * 1.0  # the ray in the camera rotated by theta about +Y
    u2, v2 = -f * x2 / z2, -f * y / z2
    return np.hypot(u2 - u, v2 - v)


def test_pan_speed_and_blur_match_analytic(tmp_path):
    render_dir, times = _pan_render(tmp_path, 2.0)
    exposure_s = 0.01
    m = measure_image_motion(render_dir, exposure_s=exposure_s)
    dt = times[1] - times[0]
    speed = _expected_displacement_px(RATE_RAD_S * dt) / dt  # the same at every instant of a uniform pan
    f = PinholeCamera.from_fov(FOV_DEG, W, H).focal_px
    assert np.percentile(speed, 50) == pytest.approx(m.speed_px_s_p50, rel=5e-3)
    assert np.percentile(speed, 95) == pytest.approx(m.speed_px_s_p95, rel=5e-3)
    # the centre of the image moves at f·ω: the median is a little above it
    assert f * RATE_RAD_S < m.speed_px_s_p50 < 1.2 * f * RATE_RAD_S
    blur = _expected_displacement_px(RATE_RAD_S * exposure_s)
    assert np.percentile(blur, 95) == pytest.approx(m.frame_blur_px_p95, rel=5e-3)
    assert m.frame_blur_px_p95 > 0.5 * exposure_s * m.speed_px_s_p95


def test_static_camera_measures_zero_and_attrs_are_named(tmp_path):
    times = np.linspace(0.0, 0.01, 5)
    poses = np.stack([_pan_pose(0.0)] * 5)
    render_dir = write_render_dir(tmp_path / "still", times, np.ones((5, H, W), np.float32),
                                  np.full((5, H, W), 3.0, np.float32), poses, renderer={"x_fov_deg": FOV_DEG}).parent
    m = measure_image_motion(render_dir, exposure_s=0.005)
    attrs = motion_attrs(m, 4.0)
    assert attrs["speed_factor"] == 4.0
    assert attrs["image_speed_px_s_p50"] == attrs["image_speed_px_s_p95"] == attrs["frame_blur_px_p95"] == 0.0

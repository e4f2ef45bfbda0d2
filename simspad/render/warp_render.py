"""``--interpolation warp``: render the anchor keyframes with Mitsuba and synthesize the rest by reprojection.

:func:`render_with_warps` is what :func:`simspad.render.renderer.render_sequence` calls instead of rendering every
keyframe: it renders (or re-uses from the cache) the keyframes :mod:`simspad.render.warp_schedule` asks for,
and writes the synthesized ones (:mod:`simspad.render.warp`) as ordinary keyframes of the render directory
(same EXR layout: R, G, B, Z, and ``object_id`` when the scene animates objects). Rendered keyframes keep the
names (cache keys) of a linear render, so both schedules share them; synthesized ones are keyed by the same
fields plus the synthesis version and parameters.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from simspad.io.exr import read_exr
from simspad.motion.trajectory import TrajectorySet
from simspad.physics.radiometry import luminance_from_rgb
from simspad.render.flow import object_poses
from simspad.render.keyframe_files import frame_names, write_frame
from simspad.render.mitsuba_scene import CompileCounter, MitsubaScene
from simspad.render.reprojection import PinholeCamera
from simspad.render.warp import WarpSource
from simspad.render.warp_schedule import (
    WARP_STRIDE,
    WARP_THRESHOLD,
    WarpPlanResult,
    synthesize_keyframes,
)

#: Bumped when synthesized pixels from the same anchors would change: part of their cache key.
WARP_VERSION = 1
#: Floor of the measured render noise (relative RMS) that scales the disagreement threshold: a noiseless render
#: (a flat scene) must not make every synthesized keyframe fail on round-off.
MIN_NOISE = 2e-3


class WarpedFrames(NamedTuple):
    names: list  # relative file of each keyframe
    plan: WarpPlanResult  # source of each keyframe, disagreement of the synthesized ones
    frame_times_s: list  # wall time of each keyframe rendered now, s
    compiled: list  # kernels new to the process while rendering each of them
    n_reused: int  # rendered keyframes taken from the cache
    render_s: float  # wall time of the whole loop (renders and synthesis), s
    stride: int  # anchor spacing used, keyframes
    threshold: float  # disagreement threshold used, in units of the render noise
    noise: float  # Monte Carlo noise of one render (relative RMS), measured at the first keyframe


def warp_key(base_key: dict, stride: int, threshold: float) -> dict:
    """Cache-key fields of synthesized keyframes."""
    return dict(base_key, warp=WARP_VERSION, warp_stride=int(stride), warp_threshold=float(threshold))


def render_with_warps(ms: MitsubaScene, ts: TrajectorySet, times: np.ndarray, cam_poses: np.ndarray,
                      base_key: dict, out_dir: Path, seed: int, counter: CompileCounter, bar, *,
                      stride: int = WARP_STRIDE, threshold: float = WARP_THRESHOLD) -> WarpedFrames:
    """Render and synthesize every keyframe at ``times`` into ``out_dir``; ``bar.update(1)`` per keyframe."""
    render_names = frame_names(base_key, times)
    warp_names = frame_names(warp_key(base_key, stride, threshold), times)
    names = list(warp_names)
    camera = PinholeCamera.from_fov(ms.x_fov_deg, ms.width, ms.height)
    object_names = ms.object_names
    frame_times, compiled, reused = [], [], [0]

    def poses_of(i: int) -> tuple:
        objects = object_poses(ts, float(times[i]))
        return tuple(objects[k] for k in object_names)

    def render(i: int) -> WarpSource:
        names[i] = render_names[i]
        path = out_dir / render_names[i]
        if path.is_file():
            reused[0] += 1
            data = read_exr(path)
            return WarpSource(data["rgb"], data["z"], cam_poses[i], data.get("object_id"), poses_of(i))
        tic = time.perf_counter()
        ms.set_pose(cam_poses[i], object_poses(ts, float(times[i])))
        rgb = ms.render_radiance(seed)
        depth, object_id = ms.render_depth_ids(seed)
        write_frame(path, rgb, depth, object_id)
        frame_times.append(time.perf_counter() - tic)
        compiled.append(counter.take())
        return WarpSource(rgb, depth, cam_poses[i], object_id, poses_of(i))

    def write(i: int, rgb, depth, object_id) -> None:
        path = out_dir / warp_names[i]
        if not path.is_file():  # synthesis is deterministic: an existing file holds these very pixels
            write_frame(path, rgb, depth, object_id)

    tic = time.perf_counter()
    noise = render_noise(ms, ts, float(times[0]), cam_poses[0], seed) if len(times) > 2 else 0.0
    plan = synthesize_keyframes(camera, times, render, lambda i: (cam_poses[i], poses_of(i)), write,
                                stride=stride, threshold=threshold * max(noise, MIN_NOISE),
                                on_keyframe=lambda i: bar.update(1))
    return WarpedFrames(names, plan, frame_times, compiled, reused[0], time.perf_counter() - tic, stride, threshold,
                        noise)


def render_noise(ms: MitsubaScene, ts: TrajectorySet, t: float, camera_to_world: np.ndarray, seed: int) -> float:
    """Monte Carlo noise of one render (relative RMS of luminance): two renders of the same pose with seeds
    ``seed`` and ``seed + 1`` differ by √2 times it. Two more renders per sequence; they are not keyframes."""
    ms.set_pose(camera_to_world, object_poses(ts, t))
    y0 = luminance_from_rgb(ms.render_radiance(seed)).astype(np.float64)
    y1 = luminance_from_rgb(ms.render_radiance(seed + 1)).astype(np.float64)
    mean = float(np.mean(y0))
    return float(np.sqrt(np.mean((y1 - y0) ** 2) / 2) / mean) if mean > 0 else 0.0

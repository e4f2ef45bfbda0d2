"""Render linear radiance keyframes of a scene along a trajectory with Mitsuba 3 (DESIGN §1, §5, §6).

For each instant of the adaptive schedule (:mod:`simspad.render.schedule`, fed by the predicted image motion of
:mod:`simspad.render.flow`) the camera is posed through ``mi.traverse`` (no recompilation: one
``params.update()`` before the first frame, then only values change), animated objects get their vertices moved
rigidly from the rest pose, and two passes are rendered with a fixed seed so Monte Carlo noise stays frozen in
screen space: radiance (the scene's integrator, ``spp`` samples) and depth (an ``aov`` integrator at 1 spp)
(:mod:`simspad.render.mitsuba_scene`). Each keyframe is one EXR (R, G, B, Z) written atomically, named by a hash
of everything that determines its pixels, so re-runs re-use frames and an interrupted render resumes
(:mod:`simspad.render.keyframe_files`); ``timeline.json`` is written last.
"""

from __future__ import annotations

import hashlib
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from simspad.errors import SimSpadError
from simspad.io.render_dir import write_timeline_json
from simspad.io.trajectory_files import load_trajectory
from simspad.motion.trajectory import TrajectorySet
from simspad.render.flow import camera_poses, max_step_flow, near_depth, object_poses, predicted_flow_fn
from simspad.render.keyframe_files import frame_names, make_out_dir, remove_created, remove_stale_frames, write_frame
from simspad.render.mitsuba_env import select_variant
from simspad.render.mitsuba_scene import (
    DEPTH_SPP,
    PSF_SIGMA_PX,
    RECONSTRUCTION_FILTER,
    CompileCounter,
    MitsubaScene,
    sampler_for,
)
from simspad.render.schedule import brute_force_keyframes, keyframe_schedule
from simspad.render.settings import RenderSettings
from simspad.render.summary import RenderSummary
from simspad.scenes.library import content_hash, resolve_scene

__all__ = ["RenderSettings", "RenderSummary", "render_sequence", "select_variant"]

#: Bumped when the pixels a given (scene, pose, settings) produce would change: part of every frame's cache key.
RENDERER_VERSION = 6  # 6: Z measured from the camera centre (was: near-clip plane); object_id channel
#: Slack (s) allowed between the requested span and the trajectory's span.
SPAN_TOLERANCE_S = 1e-9


# ---------------------------------------------------------------------------------------------------- inputs
def _load_trajectory(trajectory, scene_info):
    if isinstance(trajectory, TrajectorySet):
        return trajectory, trajectory.source, _trajectory_set_hash(trajectory)
    path = trajectory if trajectory is not None else scene_info.default_trajectory
    if path is None:
        return TrajectorySet(camera=None, objects={}, source="<static>"), "<static>", "static"
    path = Path(path)
    ts = load_trajectory(path)
    return ts, str(path), hashlib.sha256(path.read_bytes()).hexdigest()


def _trajectory_set_hash(ts) -> str:
    digest = hashlib.sha256()
    for name, tr in sorted(ts.bodies().items()):
        digest.update(name.encode())
        for a in (tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            digest.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _check_span(ts, source: str, start_s: float, end_s: float) -> None:
    for name, tr in ts.bodies().items():
        if tr.is_static:
            continue
        if tr.t_start > start_s + SPAN_TOLERANCE_S or tr.t_end < end_s - SPAN_TOLERANCE_S:
            raise SimSpadError(f"trajectory covers [{tr.t_start:g}, {tr.t_end:g}] s but the render needs "
                               f"[{start_s:g}, {end_s:g}] s", path=source, field=name)



# ---------------------------------------------------------------------------------------------------- render
def render_sequence(scene, trajectory, settings: RenderSettings, *, out_dir,
                    progress: bool = True, variant: str | None = None,
                    spad_bin_s: float | None = None) -> RenderSummary:
    """Render radiance keyframes of ``scene`` along ``trajectory`` into a render directory (DESIGN §5).

    Parameters
    ----------
    scene : str, Path or SceneInfo
        Built-in scene name, a user's Mitsuba scene folder or ``.xml``.
    trajectory : str, Path, TrajectorySet or None
        Trajectory file (or loaded set); None: the scene's default trajectory (static if it has none).
    settings : RenderSettings
        Span, resolution, samples per pixel, keyframe-schedule limits and seed.
    out_dir : str or Path
        Render directory; frames already there with the same cache key are re-used.
    progress : bool
        Show a progress bar on stderr.
    variant : str, optional
        Force a Mitsuba variant (default: :func:`select_variant`).
    spad_bin_s : float, optional
        A SPAD bin (s) to compare the keyframe count with: one render per bin is what a renderer without
        adaptive sampling would need (``schedule.n_spad_bins`` in ``timeline.json``). The caller passes the
        sensor preset's bin (the renderer knows no sensor); None leaves the comparison out.

    Returns
    -------
    RenderSummary

    Raises
    ------
    SimSpadError
        Bad settings, unknown scene, missing camera id, trajectory not covering the span, unwritable output;
        raised before anything is written.
    """
    width, height = settings.checked_size()
    duration_s, start_s, spp, seed = settings.duration_s, settings.start_s, settings.spp, settings.seed
    max_flow_px, min_rate_hz = settings.max_flow_px, settings.min_rate_hz
    spp, seed, max_flow_px, min_rate_hz = int(spp), int(seed), float(max_flow_px), float(min_rate_hz)
    out_dir = Path(out_dir)
    created = make_out_dir(out_dir)
    t0, t1 = float(start_s), float(start_s) + float(duration_s)
    try:
        info = resolve_scene(scene)
        ts, traj_source, traj_hash = _load_trajectory(trajectory, info)
        _check_span(ts, traj_source, t0, t1)
        variant = select_variant(variant)
        counter = CompileCounter(variant)
        ms = MitsubaScene(info, ts, width, height, spp)
        near_depth_m = near_depth(ts, ms, t0, t1, seed)
        flow_fn = predicted_flow_fn(ts, ms, near_depth_m)
        times = keyframe_schedule(t0, t1, flow_fn, max_flow_px, min_rate_hz)
    except BaseException:
        remove_created(created)
        raise
    step_flow = max_step_flow(flow_fn, times)
    cam_poses = camera_poses(ts, ms.rest_camera_to_world, times)
    mitsuba_version = ms.mi.__version__

    base_key = {"renderer": RENDERER_VERSION, "mitsuba": mitsuba_version, "variant": variant,
                "scene": content_hash(info), "trajectory": traj_hash, "width": width, "height": height, "spp": spp,
                "seed": seed, "depth_spp": DEPTH_SPP, "sampler": sampler_for(spp),
                "psf_sigma_px": PSF_SIGMA_PX}
    names = frame_names(base_key, times)

    counter.take()  # kernels of loading and depth probes belong to no frame
    done = _render_frames(ms, ts, [(t, cam_poses[i], out_dir / name) for i, (t, name) in enumerate(zip(times, names))],
                          seed, counter, progress)

    keyframes = [{"t": float(t), "file": name, "camera_to_world": cam_poses[i].tolist()}
                 for i, (t, name) in enumerate(zip(times, names))]
    for kf in keyframes if ms.object_names else []:  # what reprojection needs to move animated objects
        kf["object_to_world"] = {k: m.tolist() for k, m in sorted(object_poses(ts, kf["t"]).items())}
    n_spad_bins = None if spad_bin_s is None else brute_force_keyframes(duration_s, spad_bin_s)
    schedule = {"n_keyframes": len(times)}
    if n_spad_bins is not None:
        schedule["n_spad_bins"] = n_spad_bins
    schedule["max_predicted_flow_px"] = step_flow
    write_timeline_json(
        out_dir, width=width, height=height, keyframes=keyframes,
        scene=info.name, scene_hash=base_key["scene"], trajectory=traj_source, trajectory_hash=traj_hash,
        start_s=t0, duration_s=float(duration_s),
        renderer={"name": "mitsuba", "mitsuba_version": mitsuba_version, "variant": variant, "spp": spp,
                  "seed": seed, "sampler": sampler_for(spp), "rfilter": RECONSTRUCTION_FILTER,
                  "psf_sigma_px": PSF_SIGMA_PX, "depth_spp": DEPTH_SPP,
                  "depth": "Z: distance along the optical axis, m (inf: no hit)",
                  "max_flow_px": max_flow_px, "min_rate_hz": min_rate_hz, "near_depth_m": near_depth_m,
                  "focal_px": ms.focal_px, "x_fov_deg": ms.x_fov_deg, "camera_id": info.camera_id,
                  "animated_objects": ms.object_names,
                  "simspad_renderer_version": RENDERER_VERSION},
        schedule=schedule,
    )
    remove_stale_frames(out_dir, set(names))
    return RenderSummary(out_dir=out_dir, n_keyframes=len(times), n_rendered=len(done.frame_times_s),
                         n_reused=done.n_reused, duration_s=float(duration_s), start_s=t0, n_spad_bins=n_spad_bins,
                         render_s=done.render_s, variant=variant,
                         compiled_first_frame=done.compiled[0] if done.compiled else -1,
                         compiled_after_first=sum(done.compiled[1:]) if counter.enabled else -1,
                         max_predicted_flow_px=step_flow, spad_bin_s=spad_bin_s, frame_times_s=done.frame_times_s)


class _RenderedFrames(NamedTuple):
    frame_times_s: list  # wall time of each rendered frame, s
    compiled: list  # kernels new to the process while rendering each frame
    n_reused: int  # frames already in the cache
    render_s: float  # wall time of the whole loop, s


def _render_frames(ms: MitsubaScene, ts: TrajectorySet, frames: list, seed: int, counter: CompileCounter,
                   progress: bool) -> _RenderedFrames:
    """Render and write every ``(t, camera_to_world, path)`` of ``frames`` whose file is not there yet."""
    frame_times, compiled, n_reused = [], [], 0
    bar = _progress(len(frames), progress)
    t_render = time.perf_counter()
    try:
        for t, camera_to_world, path in frames:
            if path.is_file():
                n_reused += 1
                bar.update(1)
                continue
            tic = time.perf_counter()
            ms.set_pose(camera_to_world, object_poses(ts, t))
            rgb = ms.render_radiance(seed)
            depth, object_id = ms.render_depth_ids(seed)
            write_frame(path, rgb, depth, object_id)
            frame_times.append(time.perf_counter() - tic)
            compiled.append(counter.take())
            bar.update(1)
    finally:
        bar.close()
    return _RenderedFrames(frame_times, compiled, n_reused, time.perf_counter() - t_render)


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    return tqdm(total=total, desc="render", unit="frame", file=sys.stderr, dynamic_ncols=True)

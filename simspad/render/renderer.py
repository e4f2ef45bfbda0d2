"""Render linear radiance keyframes of a scene along a trajectory with Mitsuba 3 (docs/internals.md, docs/format.md, README.md).

For each instant of the adaptive schedule (:mod:`simspad.render.schedule`, fed by the predicted image motion of
:mod:`simspad.render.flow`) the camera is posed through ``mi.traverse`` (no recompilation: one
``params.update()`` before the first frame, then only values change), animated objects get their vertices moved
rigidly from the rest pose, and two passes are rendered with a fixed seed so Monte Carlo noise stays frozen in
screen space: radiance (the scene's integrator, ``spp`` samples) and depth (an ``aov`` integrator at 1 spp)
(:mod:`simspad.render.mitsuba_scene`). Each keyframe is one EXR (R, G, B, Z) written atomically, named by a hash
of everything that determines its pixels, so re-runs re-use frames and an interrupted render resumes
(:mod:`simspad.render.keyframe_files`); ``timeline.json`` is written last.

A render is three stages (:mod:`simspad.render.render_layout`): :func:`layout_render` (keyframe instants, poses and
names), :func:`render_keyframes` (any list of keyframe indices, in any process: ``simspad generate`` spreads
chunks of them over its workers) with :func:`render_probe` (keyframe 0 again with the next seed: the render-noise
budget's probe), and :func:`finalize_render` (``timeline.json`` with the budget, once every keyframe exists).
:func:`render_sequence` runs the three in one process.

With ``interpolation = "warp"`` (opt-in, :mod:`simspad.render.settings` says why it is not the default) only
sparse keyframes are rendered; those between are synthesized by reprojection and rendered for real (in blocks or
whole) only where the warps disagree (:mod:`simspad.render.warp.rendering`, which also spreads it over processes);
``timeline.json`` marks each keyframe's ``source``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np
from tqdm import tqdm

from simspad.errors import SimSpadError
from simspad.io.exr import read_exr
from simspad.io.render_dir import TIMELINE_FILE, write_timeline_json
from simspad.io.trajectory_files import load_trajectory
from simspad.motion.trajectory import TrajectorySet
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.noise_budget import PROBE_SEED_OFFSET, relative_noise, render_noise_budget
from simspad.render.converged import (
    CACHE_FILE_PREFIX,
    CHAIN_VERTICES,
    LEVELS,
    converged_renderer,
    layout_convergence,
)
from simspad.render.flow import (
    camera_poses,
    max_step_flow,
    near_depth,
    object_poses,
    predicted_flow_fn,
)
from simspad.render.geometry import (
    missing_geometry,
    owned_instants,
    plan_geometry,
    remove_stale_geometry,
    render_geometry,
)
from simspad.render.keyframe_files import (
    frame_is_intact,
    frame_key,
    frame_names,
    make_out_dir,
    remove_created,
    remove_stale_frames,
    write_frame,
)
from simspad.render.mitsuba_env import select_variant
from simspad.render.mitsuba_scene import (
    DEPTH_SPP,
    PSF_SIGMA_PX,
    RECONSTRUCTION_FILTER,
    CompileCounter,
    MitsubaScene,
    sampler_for,
)
from simspad.render.render_layout import RenderLayout
from simspad.render.schedule import brute_force_keyframes, keyframe_schedule
from simspad.render.settings import RenderSettings
from simspad.render.render_summary import RenderSummary
from simspad.render.warp.rendering import (
    SegmentReport,
    cache_probe_names,
    chunk_result,
    merge_chunk_results,
    noise_probe_name,
    render_noise_probe,
    render_with_warps,
)
from simspad.scenes.library import content_hash, resolve_scene

__all__ = ["LoadedScene", "RenderLayout", "RenderSettings", "RenderSummary", "RenderedFrames", "finalize_render",
           "load_scene", "layout_render", "render_keyframes", "render_missing_geometry", "render_probe",
           "render_sequence", "select_variant", "with_warp_results"]

#: Bumped when the pixels a given (scene, pose, settings) produce would change: part of every frame's cache key.
RENDERER_VERSION = 7  # 7: multi-jittered samples (not the biased low-discrepancy ones); converged lookup in Dr.Jit
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



# ---------------------------------------------------------------------------------------------------- stages
class LoadedScene(NamedTuple):
    """A scene and trajectory loaded in this process (one Mitsuba load, re-used by the stages run here)."""

    info: Any  # simspad.scenes.library.SceneInfo
    ts: TrajectorySet
    traj_source: str
    traj_hash: str
    ms: MitsubaScene
    variant: str
    counter: CompileCounter


def load_scene(scene, trajectory, width: int, height: int, spp: int, variant: str | None = None) -> LoadedScene:
    """Resolve ``scene``, load ``trajectory`` and the Mitsuba scene at ``width`` × ``height`` px, ``spp``."""
    info = resolve_scene(scene)
    ts, traj_source, traj_hash = _load_trajectory(trajectory, info)
    variant = select_variant(variant)
    counter = CompileCounter(variant)
    ms = MitsubaScene(info, ts, width, height, spp)
    return LoadedScene(info, ts, traj_source, traj_hash, ms, variant, counter)


def layout_render(scene, trajectory, settings: RenderSettings, *, variant: str | None = None,
                spad_bin_s: float | None = None, loaded: LoadedScene | None = None,
                prefix: RenderLayout | None = None, prefix_time_scale: float = 1.0) -> RenderLayout:
    """Stage 1: the keyframe instants, poses and file names of a render, and its ``timeline.json`` fields.

    Loads the scene (unless ``loaded`` is given), checks the trajectory covers the span, and runs the adaptive
    schedule. Writes nothing. Arguments as :func:`render_sequence`.

    ``prefix`` (a linearly interpolated layout with the same scene, size, samples and seed) makes this render's first
    keyframes those of ``prefix``, at its instants times ``prefix_time_scale``, with its poses and file names: the
    same sequence played faster (:mod:`simspad.dataset.speed`) passes through the same poses, so the files of
    the slower render serve this one too and need not be rendered again (:func:`link_shared_keyframes`). The
    schedule goes on from the prefix's last instant to the end of the span.
    """
    width, height = settings.checked_size()
    spp, seed = int(settings.spp), int(settings.seed)
    max_flow_px, min_rate_hz = float(settings.max_flow_px), float(settings.min_rate_hz)
    duration_s = settings.duration_s
    t0, t1 = float(settings.start_s), float(settings.start_s) + float(duration_s)
    if loaded is None:
        loaded = load_scene(scene, trajectory, width, height, spp, variant)
    info, ts, ms = loaded.info, loaded.ts, loaded.ms
    _check_span(ts, loaded.traj_source, t0, t1)
    near_depth_m = near_depth(ts, ms, t0, t1, seed)
    flow_fn = predicted_flow_fn(ts, ms, near_depth_m)
    shared = ()  # instants of the prefix's keyframes, in this render's time
    if prefix is not None:
        _check_prefix(prefix, width, height, spp, seed, t0, t1, prefix_time_scale, settings.convergence)
        shared = np.asarray(prefix.times_s, dtype=np.float64) * prefix_time_scale
    n_shared = len(shared)
    own = keyframe_schedule(shared[-1] if n_shared else t0, t1, flow_fn, max_flow_px, min_rate_hz)[
        1 if n_shared else 0:]
    times = np.concatenate([shared, own])
    step_flow = max_step_flow(flow_fn, times)
    mitsuba_version = ms.mi.__version__
    base_key = {"renderer": RENDERER_VERSION, "mitsuba": mitsuba_version, "variant": loaded.variant,
                "scene": content_hash(info), "trajectory": loaded.traj_hash, "width": width, "height": height,
                "spp": spp, "seed": seed, "depth_spp": DEPTH_SPP, "sampler": sampler_for(spp),
                "psf_sigma_px": PSF_SIGMA_PX}
    convergence = convergence_fields(settings)
    if convergence is not None:  # (absent when off: a path-traced render's names and timeline stay as they were)
        base_key["convergence"] = convergence
    # Poses and files of this render's own keyframes; the shared ones are the prefix's, as it rendered them.
    cam_poses = [tuple(tuple(row) for row in p.tolist()) for p in camera_poses(ts, ms.rest_camera_to_world, own)]
    names = frame_names(base_key, own, first_index=n_shared)
    # What reprojection (keyframe synthesis, measured image motion) needs to move animated objects.
    objects_to_world = [{k: m.tolist() for k, m in sorted(object_poses(ts, float(t)).items())}
                        for t in own] if ms.object_names else []
    if prefix is not None:
        cam_poses = list(prefix.camera_to_world) + cam_poses
        names = list(prefix.names) + names
        objects_to_world = list(prefix.objects_to_world) + objects_to_world if objects_to_world else []
    n_spad_bins = None if spad_bin_s is None else brute_force_keyframes(duration_s, spad_bin_s)
    schedule = {"n_keyframes": len(times)}
    if n_spad_bins is not None:
        schedule["n_spad_bins"] = n_spad_bins
    schedule["max_predicted_flow_px"] = step_flow
    # Warp needs object ids to move animated objects, and pays a noise-probe render: below two strides of
    # keyframes it saves nothing, so such short sequences render every keyframe.
    warp = (prefix is None and settings.interpolation == "warp" and not ms.moves_objects_without_ids
            and len(times) >= 2 * settings.warp_stride)
    schedule["interpolation"] = "warp" if warp else "linear"
    schedule["n_rendered_keyframes"] = len(own)
    if n_shared:
        schedule["shared_keyframes"] = {"n_keyframes": n_shared, "time_scale": float(prefix_time_scale)}
    if warp:
        schedule["warp"] = {"stride": int(settings.warp_stride), "threshold": float(settings.warp_threshold),
                            "emission_layer": bool(settings.warp_emission and ms.splits_emission
                                                   and convergence is None)}
    timeline = dict(
        scene=info.name, scene_hash=base_key["scene"], trajectory=loaded.traj_source,
        trajectory_hash=loaded.traj_hash, start_s=t0, duration_s=float(duration_s),
        renderer={"name": "mitsuba", "mitsuba_version": mitsuba_version, "variant": loaded.variant, "spp": spp,
                  "seed": seed, "sampler": sampler_for(spp), "rfilter": RECONSTRUCTION_FILTER,
                  "psf_sigma_px": PSF_SIGMA_PX, "depth_spp": DEPTH_SPP,
                  "depth": "Z: distance along the optical axis, m (inf: no hit)",
                  "max_flow_px": max_flow_px, "min_rate_hz": min_rate_hz, "near_depth_m": near_depth_m,
                  "focal_px": ms.focal_px, "x_fov_deg": ms.x_fov_deg, "camera_id": info.camera_id,
                  "animated_objects": ms.object_names, "simspad_renderer_version": RENDERER_VERSION,
                  **({"convergence": dict(convergence, cache_file=cache_file_name(base_key))}
                     if convergence is not None else {})},
        schedule=schedule,
    )
    geometry = plan_geometry(ts, ms, t0, t1, settings.gt_rate_hz, base_key)
    if geometry is not None:
        timeline["geometry"] = geometry
    return RenderLayout(times_s=tuple(float(t) for t in times), names=tuple(names), camera_to_world=tuple(cam_poses),
                      width=width, height=height, spp=spp, seed=seed, variant=loaded.variant,
                      scene_hash=base_key["scene"], trajectory_hash=loaded.traj_hash, timeline=timeline,
                      objects_to_world=tuple(objects_to_world), base_key=base_key)


def _check_prefix(prefix: RenderLayout, width: int, height: int, spp: int, seed: int, t0: float, t1: float,
                  scale: float, convergence: str = "off") -> None:
    """A prefix must be a linear, path-traced render with this one's pixels-determining settings, starting where
    it starts. Converged renders share nothing: each lights its keyframes from its own irradiance cache (built
    from probe views over its own span), so a prefix's keyframes would be lit by another cache than the rest."""
    why = None
    if (prefix.width, prefix.height, prefix.spp, prefix.seed) != (width, height, spp, seed):
        why = "its size, samples per pixel or seed differ"
    elif convergence != "off" or prefix.timeline.get("renderer", {}).get("convergence"):
        why = "a converged render (convergence \"cache\") lights its keyframes from its own irradiance cache"
    elif prefix.warp is not None:  # (a prefix sharing its own first keyframes is fine: its files are all there)
        why = "only a linear render can be a prefix"
    elif not (scale > 0 and prefix.times_s[0] * scale == t0 and prefix.times_s[-1] * scale < t1):
        why = f"its span scaled by {scale:g} is not a prefix of {t0:g}–{t1:g} s"
    if why is not None:
        raise SimSpadError(f"cannot share keyframes with that render: {why}", field="prefix")


def link_shared_keyframes(layout: RenderLayout, indices, prefix_dir, out_dir) -> int:
    """Hard-link the shared keyframes (:func:`layout_render`'s ``prefix``) among ``indices`` from the prefix's
    render directory ``prefix_dir`` into ``out_dir``; a copy where the file system cannot link. Keyframes whose
    source is missing or damaged are left to :func:`render_keyframes`, which renders the same pixels (same pose,
    seed and settings). Returns how many were linked or copied."""
    out_dir, prefix_dir = Path(out_dir), Path(prefix_dir)
    shared = [i for i in indices if i < layout.n_shared]
    if shared:
        make_out_dir(out_dir)  # the render directory and its frames/ (a keyframe's name includes frames/)
    n = 0
    for i in shared:
        src, dst = prefix_dir / layout.names[i], out_dir / layout.names[i]
        if dst.is_file() or not src.is_file() or not frame_is_intact(src):
            continue
        try:
            os.link(src, dst)
        except FileExistsError:
            continue
        except OSError:  # no hard links here (another file system, or not supported): an atomic copy
            tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
            shutil.copyfile(src, tmp)
            os.replace(tmp, dst)
        n += 1
    return n


def build_convergence_cache(layout: RenderLayout, loaded: LoadedScene, out_dir) -> bool:
    """Build a converged ``layout``'s irradiance cache into the render directory ``out_dir`` unless it is there.

    ``simspad generate`` runs this in a render's layout job, before any keyframe chunk starts: the chunks, in
    other workers, then read the one cache instead of each building it (the values are the same in any process,
    so this changes no byte; it changes how often the build is paid). Returns True when it built the cache now;
    False for a path-traced layout or a cache already there.
    """
    fields = layout_convergence(layout)
    if fields is None or (Path(out_dir) / fields["cache_file"]).is_file():
        return False
    _check_same_inputs(layout, loaded)
    make_out_dir(out_dir)
    converged_renderer(layout, loaded.ms, loaded.ts, out_dir)
    return True


def render_keyframes(scene, trajectory, layout: RenderLayout, indices, *, out_dir, progress: bool = False,
                     loaded: LoadedScene | None = None, on_frame: Callable[[int], None] | None = None
                     ) -> "RenderedFrames":
    """Stage 2: render the keyframes ``indices`` of ``layout`` whose files are not in ``out_dir`` yet.

    Any subset, in any order, in any process: every keyframe uses the layout's fixed seed, so its bytes do not
    depend on what else this call renders. A later stage may call this with an explicit list (e.g. only the
    keyframes a synthesis step could not produce).

    Parameters
    ----------
    scene, trajectory
        As given to :func:`layout_render` (reloaded here unless ``loaded`` is given; their content hashes must
        match the layout's).
    layout : RenderLayout
    indices : iterable of int
        Keyframe indices into ``layout``.
    out_dir : str or Path
        Render directory (created if missing).
    progress : bool
        Show a keyframe progress bar on stderr.
    on_frame : callable, optional
        Called with each keyframe index once its file exists (rendered or re-used).

    Raises
    ------
    SimSpadError
        An index out of range, or a scene, trajectory or Mitsuba variant other than the layout's.
    """
    out_dir = Path(out_dir)
    indices = [int(i) for i in indices]
    bad = [i for i in indices if not 0 <= i < layout.n_keyframes]
    if bad:
        raise SimSpadError(f"keyframe index {bad[0]} outside the layout's 0..{layout.n_keyframes - 1}", field="indices")
    make_out_dir(out_dir)
    # A cached keyframe is decoded once here: a damaged one is rendered again, not re-used.
    paths = {i: out_dir / layout.names[i] for i in indices}
    todo = {i for i, path in paths.items() if not path.is_file() or not frame_is_intact(path)}
    geometry = layout.timeline.get("geometry")
    geometry_todo = missing_geometry(geometry, owned_instants(layout.times_s, geometry, indices), out_dir,
                                     layout.width, layout.height)
    if (todo or geometry_todo) and loaded is None:
        loaded = load_scene(scene, trajectory, layout.width, layout.height, layout.spp, layout.variant)
    if loaded is not None:
        _check_same_inputs(layout, loaded)
    counter = loaded.counter if loaded is not None else None
    if counter is not None:
        counter.take()  # kernels of loading and depth probes belong to no frame
    # Objects are posed as the layout says (shared keyframes were planned on the slower trajectory).
    frames = [(i, layout.times_s[i], np.asarray(layout.camera_to_world[i]), paths[i], i in todo,
               {k: np.asarray(m) for k, m in layout.objects_to_world[i].items()} if layout.objects_to_world else None)
              for i in indices]
    converged = None
    if todo and layout.timeline.get("renderer", {}).get("convergence"):
        converged = converged_renderer(layout, loaded.ms, loaded.ts, out_dir)
    done = _render_frames(loaded, frames, layout.seed, counter, progress, on_frame, converged)
    if geometry_todo:  # the geometry passes at the ground-truth instants these keyframes own
        render_geometry(loaded.ms, geometry, geometry_todo, out_dir)
    return done


def render_missing_geometry(layout: RenderLayout, keyframe_indices, out_dir, loaded: LoadedScene) -> int:
    """Render the geometry passes that the keyframes ``keyframe_indices`` own and that ``out_dir`` lacks (warp
    renders, whose keyframes are synthesized rather than rendered by :func:`render_keyframes`)."""
    geometry = layout.timeline.get("geometry")
    todo = missing_geometry(geometry, owned_instants(layout.times_s, geometry, keyframe_indices), Path(out_dir),
                            layout.width, layout.height)
    return render_geometry(loaded.ms, geometry, todo, Path(out_dir)) if todo else 0


def render_probe(scene, trajectory, layout: RenderLayout, *, out_dir, loaded: LoadedScene | None = None) -> bool:
    """Stage 2b: the render-noise budget's noise probe (keyframe 0 again with the next seed,
    :func:`~simspad.render.warp.rendering.render_noise_probe`) into ``out_dir`` unless it is there; in any process, like
    :func:`render_keyframes` (whose arguments these are). True if it was rendered now."""
    out_dir = Path(out_dir)
    if (out_dir / noise_probe_name(layout)).is_file():
        return False
    make_out_dir(out_dir)
    if loaded is None:
        loaded = load_scene(scene, trajectory, layout.width, layout.height, layout.spp, layout.variant)
    _check_same_inputs(layout, loaded)
    return render_noise_probe(loaded.ms, loaded.ts, layout, out_dir)


def convergence_fields(settings: RenderSettings) -> dict | None:
    """What a converged render records (``timeline.json`` ``renderer.convergence``, and the keyframes' cache key);
    None for a path-traced one."""
    if settings.convergence == "off":
        return None
    return {"mode": settings.convergence, "cache_samples": int(settings.cache_samples),
            "cache_cell_px": float(settings.cache_cell_px), "cache_probes": int(settings.cache_probes),
            "cache_width_px": int(settings.cache_width_px), "chain_vertices": CHAIN_VERTICES, "levels": list(LEVELS)}


def cache_file_name(base_key: dict) -> str:
    """The irradiance cache's file name in the render directory, keyed like the keyframes."""
    return f"{CACHE_FILE_PREFIX}{frame_key(base_key, -1.0)}.npz"


def finalize_render(layout: RenderLayout, out_dir) -> Path:
    """Stage 3: write ``timeline.json`` (which marks the render directory complete) once every keyframe file of
    ``layout`` exists, and delete frames of earlier renders into the same directory that it does not reference.

    Raises
    ------
    SimSpadError
        Keyframe files missing (their count and the first one).
    """
    out_dir = Path(out_dir)
    missing = [name for name in layout.names if not (out_dir / name).is_file()]
    if missing:
        raise SimSpadError(f"{len(missing)} of {layout.n_keyframes} keyframes not rendered yet (first: {missing[0]})",
                           path=out_dir)
    geometry = [g["file"] for g in layout.timeline.get("geometry", {}).get("instants", [])]
    missing = [name for name in geometry if not (out_dir / name).is_file()]
    if missing:
        raise SimSpadError(f"{len(missing)} of {len(geometry)} geometry passes not rendered yet (first: "
                           f"{missing[0]})", path=out_dir)
    path = write_timeline_json(out_dir, width=layout.width, height=layout.height, keyframes=layout.keyframes(),
                               **layout.timeline, render_noise=measure_render_noise(layout, out_dir))
    probes = {noise_probe_name(layout), *(cache_probe_names(layout) if layout_convergence(layout) else ())}
    remove_stale_frames(out_dir, set(layout.names) | probes)
    remove_stale_geometry(out_dir, set(geometry))
    keep = layout.timeline.get("renderer", {}).get("convergence", {}).get("cache_file")
    for stale in out_dir.glob(f"{CACHE_FILE_PREFIX}*.npz"):  # caches of earlier converged renders into out_dir
        if stale.name != keep:
            stale.unlink(missing_ok=True)
    return path


def measure_render_noise(layout: RenderLayout, out_dir) -> dict | None:
    """The render-noise budget of a render (``timeline.json``'s ``render_noise``) from keyframe 0's file and its
    noise probe (:func:`~simspad.render.warp.rendering.render_noise_probe`: keyframe 0 again with the next seed), or
    None where the probe was not rendered (a render made before SimSPAD rendered one for every render).

    :func:`simspad.radiance.noise_budget.render_noise_budget` defines the figures; the probe's file and seed are
    stored with them, so a recording can state its own figure at its lux level."""
    out_dir = Path(out_dir)
    probe = noise_probe_name(layout)
    if not (out_dir / probe).is_file():
        return None
    lum = lambda name: luminance_from_rgb(read_exr(out_dir / name)["rgb"])  # noqa: E731
    budget = {**render_noise_budget(lum(layout.names[0]), lum(probe)), "probe_file": probe, "probe_keyframe": 0,
              "probe_seed": layout.seed + PROBE_SEED_OFFSET, "probe_renders": 1}
    halves = cache_probe_names(layout) if layout_convergence(layout) is not None else ()
    if halves and all((out_dir / name).is_file() for name in halves):
        # A converged render: the probe measured the noise that changes between keyframes; the cache's own noise
        # stays on the surfaces. Half the difference of the two half caches' renders has the whole cache's noise
        # (each half has twice its variance); the two are independent, so the total adds in quadrature.
        cache_median, cache_rms = (v / math.sqrt(2.0) for v in relative_noise(lum(halves[0]), lum(halves[1])))
        budget.update({
            "keyframe_relative_noise_median": budget["relative_noise_median"],
            "keyframe_relative_noise_rms": budget["relative_noise_rms"],
            "cache_relative_noise_median": cache_median, "cache_relative_noise_rms": cache_rms,
            "relative_noise_median": math.hypot(budget["relative_noise_median"], cache_median),
            "relative_noise_rms": math.hypot(budget["relative_noise_rms"], cache_rms),
            "cache_probe_files": list(halves)})
    return budget


def _check_same_inputs(layout: RenderLayout, loaded: LoadedScene) -> None:
    if loaded.variant != layout.variant:
        raise SimSpadError(f"this worker renders with Mitsuba variant {loaded.variant} but the layout was made with "
                           f"{layout.variant}: give every worker the same DRJIT_LIBLLVM_PATH", field="variant")
    if content_hash(loaded.info) != layout.scene_hash:
        raise SimSpadError("the scene changed since the render was laid out", path=loaded.info.source or
                           loaded.info.folder, field="scene")
    if loaded.traj_hash != layout.trajectory_hash:
        raise SimSpadError("the trajectory changed since the render was laid out", path=loaded.traj_source,
                           field="trajectory")


# ---------------------------------------------------------------------------------------------------- render
def render_sequence(scene, trajectory, settings: RenderSettings, *, out_dir,
                    progress: bool = True, variant: str | None = None,
                    spad_bin_s: float | None = None) -> RenderSummary:
    """Render radiance keyframes of ``scene`` along ``trajectory`` into a render directory: the three stages
    (:func:`layout_render`, :func:`render_keyframes` of every keyframe, :func:`finalize_render`) in this process.

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
    out_dir = Path(out_dir)
    created = make_out_dir(out_dir)
    try:
        loaded = load_scene(scene, trajectory, width, height, int(settings.spp), variant)
        layout = layout_render(scene, trajectory, settings, spad_bin_s=spad_bin_s, loaded=loaded)
    except BaseException:
        remove_created(created)
        raise
    probe_s = None
    if layout.warp is not None:
        done, layout = _render_warped(layout, loaded, out_dir, progress)
        render_missing_geometry(layout, range(layout.n_keyframes), out_dir, loaded)
    else:
        done = render_keyframes(scene, trajectory, layout, range(layout.n_keyframes), out_dir=out_dir,
                                progress=progress, loaded=loaded)
        # The render-noise budget's probe (the warp schedule renders it for its own use): one keyframe more.
        tic = time.perf_counter()
        probe_s = time.perf_counter() - tic if render_probe(scene, trajectory, layout, out_dir=out_dir,
                                                            loaded=loaded) else 0.0
    finalize_render(layout, out_dir)
    render_noise = json.loads((out_dir / TIMELINE_FILE).read_text()).get("render_noise")
    schedule = layout.timeline["schedule"]
    return RenderSummary(out_dir=out_dir, n_keyframes=layout.n_keyframes, n_rendered=len(done.frame_times_s),
                         n_reused=done.n_reused, duration_s=float(settings.duration_s),
                         start_s=layout.timeline["start_s"],
                         n_spad_bins=schedule.get("n_spad_bins"), render_s=done.render_s, variant=layout.variant,
                         compiled_first_frame=done.compiled[0] if done.compiled else -1,
                         compiled_after_first=sum(done.compiled[1:]) if loaded.counter.enabled else -1,
                         max_predicted_flow_px=schedule["max_predicted_flow_px"], spad_bin_s=spad_bin_s,
                         frame_times_s=done.frame_times_s, n_warped=list(layout.sources).count("warp"),
                         render_noise=render_noise, probe_s=probe_s if layout.warp is None else None)


def _render_warped(layout: RenderLayout, loaded: LoadedScene, out_dir: Path, progress: bool):
    """Render sparse keyframes of ``layout`` and synthesize the rest (:mod:`simspad.render.warp.rendering`); the
    layout comes back with the keyframes' files and sources and the warp schedule in its timeline fields."""
    loaded.counter.take()  # kernels of loading and depth probes belong to no frame
    bar = _progress(layout.n_keyframes, progress)
    try:
        done = render_with_warps(loaded.ms, loaded.ts, layout, out_dir, loaded.counter, bar)
    finally:
        bar.close()
    return done, with_warp_results(layout, [chunk_result(done, 0, layout.n_keyframes - 1)])


def with_warp_results(layout: RenderLayout, chunks: list[SegmentReport]) -> RenderLayout:
    """``layout`` with the keyframe files, sources and ``schedule.warp`` fields that the warp chunks reported
    (:func:`simspad.render.warp.rendering.chunk_result`, any order): what :func:`finalize_render` then writes."""
    names, sources, warp = merge_chunk_results(layout.n_keyframes, chunks, layout.warp)
    schedule = dict(layout.timeline["schedule"], n_rendered_keyframes=sources.count("render"), warp=warp)
    return dataclasses.replace(layout, names=tuple(names), sources=tuple(sources),
                               timeline=dict(layout.timeline, schedule=schedule))


class RenderedFrames(NamedTuple):
    """What :func:`render_keyframes` did."""

    frame_times_s: list  # wall time of each rendered frame, s
    compiled: list  # kernels new to the process while rendering each frame
    n_reused: int  # frames already in the cache
    render_s: float  # wall time of the whole loop, s


def _render_frames(loaded: LoadedScene | None, frames: list, seed: int, counter: CompileCounter | None,
                   progress: bool, on_frame=None, converged=None) -> RenderedFrames:
    """Render and write every ``(index, t, camera_to_world, path, needed)`` of ``frames`` that is ``needed`` (its
    file is missing or damaged); count the others as re-used. ``converged`` ((ConvergedRenderer, cache)) renders
    the radiance from the irradiance cache instead of path tracing every pixel."""
    frame_times, compiled, n_reused = [], [], 0
    bar = _progress(len(frames), progress)
    t_render = time.perf_counter()
    try:
        for i, t, camera_to_world, path, needed, objects in frames:
            if not needed:
                n_reused += 1
            else:
                tic = time.perf_counter()
                poses = object_poses(loaded.ts, t) if objects is None else objects
                loaded.ms.set_pose(camera_to_world, poses)
                rgb = (loaded.ms.render_radiance(seed) if converged is None
                       else converged[0].render(converged[1], seed, poses))
                depth, object_id = loaded.ms.render_depth_ids(seed)
                write_frame(path, rgb, depth, object_id)
                frame_times.append(time.perf_counter() - tic)
                compiled.append(counter.take())
            bar.update(1)
            if on_frame is not None:
                on_frame(i)
    finally:
        bar.close()
    return RenderedFrames(frame_times, compiled, n_reused, time.perf_counter() - t_render)


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    return tqdm(total=total, desc="render", unit="frame", file=sys.stderr, dynamic_ncols=True)

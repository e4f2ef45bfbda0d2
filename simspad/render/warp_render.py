"""``--interpolation warp``: render the anchor keyframes with Mitsuba and synthesize the rest by reprojection.

:func:`render_with_warps` is what :func:`simspad.render.renderer.render_sequence` calls instead of rendering every
keyframe: it renders (or re-uses from the cache) the keyframes :mod:`simspad.render.warp_schedule` asks for,
and writes the synthesized ones (:mod:`simspad.render.warp`) as ordinary keyframes of the render directory
(same EXR layout: R, G, B, Z, and ``object_id`` when the scene animates objects). Rendered keyframes keep the
names (cache keys) of a linear render, so both schedules share them; synthesized ones are keyed by the same
fields plus the synthesis version and parameters. Where the warps disagree in places, :class:`BlockPatcher`
renders those blocks (:mod:`simspad.render.blocks`) into the synthesized keyframes. With the emission layer
(``emission_layer`` in the plan's warp settings), a rendered keyframe with an emitter in view gets an emission pass
(:meth:`~simspad.render.mitsuba_scene.MitsubaScene.render_emission`, not stored), only its reflected light is
warped, and a keyframe synthesized next to such a one gets its own emission pass added.

The render noise the warps are judged against comes from keyframe 0 and one *noise probe* (keyframe 0 again with
the next seed, kept in the render directory). ``simspad generate`` spreads a warp render over its workers in two
phases: the anchors (chunks of :func:`simspad.render.renderer.render_keyframes`) and the probe, then runs of
segments between anchors (:func:`render_with_warps` with ``anchors``), whose reports
(:func:`chunk_result`) merge into ``timeline.json`` (:func:`merge_chunk_results`); the bytes are those of a
one-process render.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.ndimage import gaussian_filter

from simspad.io.exr import read_exr, write_exr
from simspad.motion.trajectory import TrajectorySet
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.noise_budget import PROBE_SEED_OFFSET
from simspad.render.converged import plan_radiance
from simspad.render.blocks import block_window, blocks_of_tiles, render_fraction, tiles_of_blocks
from simspad.render.flow import object_poses
from simspad.render.keyframe_files import frame_key, frame_names, write_frame
from simspad.render.mitsuba_scene import PSF_REACH_PX, CompileCounter, MitsubaScene
from simspad.render.render_plan import RenderPlan
from simspad.render.reprojection import PinholeCamera
from simspad.render.warp import WarpSource
from simspad.render.warp_schedule import (
    WarpPlanResult,
    describe_patches,
    describe_scores,
    synthesize_keyframes,
)

#: Bumped when synthesized pixels from the same anchors would change: part of their cache key.
WARP_VERSION = 4  # 2: target geometry from a rendered depth + id pass instead of the forward splat; 3: blocks
# rendered where the warps disagree; 4: the emission layer (directly visible emission rendered, not warped)
#: Floor of the per-pixel render noise, as a fraction of its mean: a noiseless render (a flat scene) must not make
#: every synthesized keyframe fail on round-off.
MIN_NOISE = 0.05
#: Gaussian σ (pixels) that turns the squared difference of the two noise-probe renders into a noise level.
NOISE_SMOOTHING_PX = 2.0


class WarpedFrames(NamedTuple):
    names: list  # relative file of each keyframe
    plan: WarpPlanResult  # source of each keyframe, disagreement of the synthesized ones
    frame_times_s: list  # wall time of each keyframe rendered now, s
    compiled: list  # kernels new to the process while rendering each of them
    n_reused: int  # rendered keyframes taken from the cache
    render_s: float  # wall time of the whole loop (renders and synthesis), s
    stride: int  # anchor spacing used, keyframes
    threshold: float  # disagreement threshold used, in units of the render noise
    noise: float  # Monte Carlo noise of one render (RMS ÷ mean luminance), measured at the first keyframe
    n_geometry: int  # depth + id passes rendered for synthesized keyframes
    geometry_s: float  # wall time of those passes, s
    n_blocks: int  # blocks rendered into synthesized keyframes
    blocks_s: float  # wall time of those block renders, s
    emission_keyframes: list  # keyframes given an emission pass (emitter in view, or a target between such)
    probe_emission: bool  # whether the noise probe got one too


def warp_key(base_key: dict, warp: dict) -> dict:
    """Cache-key fields of synthesized keyframes, from a plan's :attr:`RenderPlan.warp` settings."""
    return dict(base_key, warp=WARP_VERSION, warp_stride=int(warp["stride"]), warp_threshold=float(warp["threshold"]),
                warp_emission=bool(warp.get("emission_layer", False)))


class BlockPatcher:
    """Renders image blocks (:mod:`simspad.render.blocks`) into synthesized keyframes: the
    :class:`simspad.render.warp_schedule.Patcher` of a Mitsuba scene."""

    def __init__(self, ms: MitsubaScene, pose_of, seed: int, written=lambda i: False):
        self.ms, self.pose_of, self.seed, self.written = ms, pose_of, seed, written
        self.n_blocks, self.seconds = 0, 0.0

    def blocks(self, tiles: np.ndarray) -> np.ndarray:
        return blocks_of_tiles(tiles, self.ms.block_px)

    def tiles(self, blocks: np.ndarray, tile_shape: tuple[int, int]) -> np.ndarray:
        return tiles_of_blocks(blocks, tile_shape, self.ms.block_px)

    def cost(self, blocks: np.ndarray) -> float:
        return render_fraction(blocks, self.ms.width, self.ms.height, self.ms.block_px, PSF_REACH_PX, self.ms.spp)

    def apply(self, i: int, blocks: np.ndarray, rgb: np.ndarray) -> np.ndarray:
        if self.written(i):  # a resumed render: the file holds these blocks already (and is not written again)
            return rgb
        tic = time.perf_counter()
        self.ms.set_pose(*self.pose_of(i))
        out = np.array(rgb, dtype=np.float32, copy=True)
        for row, col in zip(*np.nonzero(blocks)):
            out[block_window(row, col, self.ms.width, self.ms.height, self.ms.block_px)] = self.ms.render_radiance_block(
                self.seed, int(row), int(col))
            self.n_blocks += 1
        self.seconds += time.perf_counter() - tic
        return out


def _probe_objects(ts: TrajectorySet, plan: RenderPlan) -> dict:
    """The animated objects' poses at keyframe 0, as the plan has them (a faster render's shared keyframes were
    planned on the slower trajectory), else from the trajectory."""
    if plan.objects_to_world:
        return {k: np.asarray(m) for k, m in plan.objects_to_world[0].items()}
    return object_poses(ts, plan.times_s[0])


def noise_probe_name(plan: RenderPlan) -> str:
    """Relative file of the noise probe: keyframe 0 rendered again with the next seed (not a keyframe)."""
    return f"frames/noise-probe-{frame_key(dict(plan.base_key, noise_probe=1), plan.times_s[0])}.exr"


def render_noise_probe(ms: MitsubaScene, ts: TrajectorySet, plan: RenderPlan, out_dir: Path) -> bool:
    """Render the noise probe (keyframe 0's radiance with the plan's seed + 1) into ``out_dir`` unless it is
    there; True if it was rendered now. The warp schedule judges its warps against it, and every render's
    ``timeline.json`` states its render-noise budget from it (:func:`simspad.render.renderer.measure_render_noise`)."""
    path = out_dir / noise_probe_name(plan)
    if path.is_file():
        return False
    ms.set_pose(np.asarray(plan.camera_to_world[0]), _probe_objects(ts, plan))
    rgb = ms.render_radiance(plan.seed + PROBE_SEED_OFFSET)
    write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    return True


def noise_map(rgb_seed: np.ndarray, rgb_next_seed: np.ndarray) -> tuple[np.ndarray, float]:
    """Monte Carlo noise of one render per pixel (σ of luminance, absolute, floored at :data:`MIN_NOISE` of its
    mean) from two renders of the same pose with different seeds (they differ by √2 σ), smoothed over a few
    pixels so that it is a noise *level* rather than one draw; and that noise's RMS ÷ the mean luminance."""
    y0 = luminance_from_rgb(np.asarray(rgb_seed)).astype(np.float64)
    y1 = luminance_from_rgb(np.asarray(rgb_next_seed)).astype(np.float64)
    noise_y = np.sqrt(gaussian_filter((y1 - y0) ** 2 / 2, NOISE_SMOOTHING_PX, mode="nearest"))
    mean_y = float(np.mean(y0))
    noise = float(np.sqrt(np.mean(noise_y ** 2)) / mean_y) if mean_y > 0 else 0.0
    return np.maximum(noise_y, MIN_NOISE * noise_y.mean()), noise  # a noiseless render: round-off is no failure


def render_with_warps(ms: MitsubaScene, ts: TrajectorySet, plan: RenderPlan, out_dir: Path, counter: CompileCounter,
                      bar, *, anchors: list[int] | None = None) -> WarpedFrames:
    """Render and synthesize the keyframes of a warp ``plan`` (:attr:`RenderPlan.warp`: stride and threshold)
    into ``out_dir``; ``bar.update(1)`` per keyframe.

    With ``anchors`` (consecutive anchors of :func:`simspad.render.warp_schedule.anchor_indices`) only the
    keyframes from the first to the last of them: a chunk of the render, as ``simspad generate`` spreads them
    over workers. Anchors and the noise probe (:func:`render_noise_probe`) found in ``out_dir`` are re-used; the
    noise map is computed from keyframe 0's file and the probe's, so every chunk decides with the same numbers.
    """
    times, cam_poses, seed = np.asarray(plan.times_s), np.asarray(plan.camera_to_world), plan.seed
    radiance = plan_radiance(plan, ms, ts, out_dir)  # a converged render's cache (None: path tracing)
    stride, threshold = plan.warp["stride"], plan.warp["threshold"]
    with_emission = bool(plan.warp.get("emission_layer", False))
    render_names = plan.names  # a plan's names are those of rendered keyframes until the warp results replace them
    warp_names = frame_names(warp_key(plan.base_key, plan.warp), times)
    names = list(warp_names)
    camera = PinholeCamera.from_fov(ms.x_fov_deg, ms.width, ms.height)
    object_names = ms.object_names
    frame_times, compiled, reused = [], [], [0]
    geometry_times = []
    first = 0 if anchors is None else anchors[0]
    ready: dict = {}  # keyframe 0, when rendered or read for the noise map before the schedule asks for it

    def pose_at(i: int) -> tuple:
        """Camera-to-world and object poses (by name) of keyframe ``i``, as :meth:`MitsubaScene.set_pose` takes them."""
        return cam_poses[i], object_poses(ts, float(times[i]))

    def poses_of(i: int) -> tuple:
        objects = pose_at(i)[1]
        return tuple(objects[k] for k in object_names)

    emitting = set()  # rendered keyframes that show an emitter (each got an emission pass)

    def emission(i: int) -> np.ndarray | None:
        """Directly visible emission of rendered keyframe ``i`` (the pose must be set): None without the layer, or
        where a 1-spp pass sees no emitter (then its radiance is all reflected light, warped as it is)."""
        if not with_emission or not ms.emitter_in_view(seed):
            return None
        emitting.add(i)
        return ms.render_emission(seed)

    def render(i: int) -> WarpSource:
        names[i] = render_names[i]
        if i in ready:
            return ready.pop(i)
        path = out_dir / render_names[i]
        if path.is_file():
            reused[0] += 1
            data = read_exr(path)
            if with_emission:  # the emission pass is not stored: the keyframe file stays a linear render's
                ms.set_pose(*pose_at(i))
            return WarpSource(data["rgb"], data["z"], cam_poses[i], data.get("object_id"), poses_of(i),
                              emission(i))
        tic = time.perf_counter()
        ms.set_pose(*pose_at(i))
        rgb = ms.render_radiance(seed) if radiance is None else radiance(seed, pose_at(i)[1])
        depth, object_id = ms.render_depth_ids(seed)
        write_frame(path, rgb, depth, object_id)
        frame_times.append(time.perf_counter() - tic)
        compiled.append(counter.take())
        return WarpSource(rgb, depth, cam_poses[i], object_id, poses_of(i), emission(i))

    def geometry(i: int) -> tuple:
        """Depth and ids of keyframe ``i`` from a geometry pass (1 spp; the same seed as its radiance)."""
        tic = time.perf_counter()
        ms.set_pose(*pose_at(i))
        depth, object_id = ms.render_depth_ids(seed)
        geometry_times.append(time.perf_counter() - tic)
        return depth, object_id

    def target_emission(i: int) -> np.ndarray:
        """Directly visible emission of keyframe ``i`` (the same seed as its radiance)."""
        ms.set_pose(*pose_at(i))
        return ms.render_emission(seed)

    def write(i: int, rgb, depth, object_id) -> None:
        path = out_dir / warp_names[i]
        if not path.is_file():  # synthesis is deterministic: an existing file holds these very pixels
            write_frame(path, rgb, depth, object_id)

    tic = time.perf_counter()
    noise_y, noise = None, 0.0
    probe_emission = False  # the noise map needed the probe's emission pass (keyframe 0 shows an emitter)
    if len(times) > 2:
        if first == 0:
            ready[0] = render(0)
            key0 = ready[0].rgb
        else:
            key0 = read_exr(out_dir / render_names[0])["rgb"]
        render_noise_probe(ms, ts, plan, out_dir)
        if radiance is None:
            probe = read_exr(out_dir / noise_probe_name(plan))["rgb"]
        else:  # a converged render's warps are judged against its own noise: keyframe 0 from the same cache with
            # the next seed (kept in memory, the same in every chunk; the probe file stays path-traced: the budget's)
            ms.set_pose(*pose_at(0))
            probe = radiance(seed + PROBE_SEED_OFFSET, pose_at(0)[1])
        if with_emission:
            ms.set_pose(*pose_at(0))
            key0_emission = ready[0].emission if first == 0 else emission(0)
            if key0_emission is not None:  # the warps move reflected light only: judge them against its noise
                probe_emission = True
                key0 = np.maximum(key0 - key0_emission, 0.0)
                probe = np.maximum(probe - ms.render_emission(seed + PROBE_SEED_OFFSET), 0.0)
        noise_y, noise = noise_map(key0, probe)
    # Blocks are path-traced: a converged render re-renders whole keyframes where the warps disagree.
    patcher = (BlockPatcher(ms, pose_at, seed, lambda i: (out_dir / warp_names[i]).is_file()) if radiance is None
               else None)
    plan = synthesize_keyframes(camera, times, render, lambda i: (cam_poses[i], poses_of(i)), write,
                                stride=stride, threshold=threshold, noise_y=noise_y, geometry=geometry,
                                emission=target_emission if with_emission else None,
                                on_keyframe=lambda i: bar.update(1), patch=patcher, anchors=anchors)
    return WarpedFrames(names, plan, frame_times, compiled, reused[0], time.perf_counter() - tic, stride, threshold,
                        noise, len(geometry_times), float(sum(geometry_times)), patcher.n_blocks if patcher else 0,
                        patcher.seconds if patcher else 0.0,
                        sorted(emitting | plan.emission_passes), probe_emission)


def chunk_result(done: WarpedFrames, lo: int, hi: int) -> dict:
    """What a chunk of keyframes ``lo``..``hi`` (anchors included) reports, as plain data for the driver that
    writes ``timeline.json`` (:func:`merge_chunk_results`)."""
    plan = done.plan
    return {"lo": lo, "hi": hi, "names": done.names[lo:hi + 1], "sources": plan.sources[lo:hi + 1],
            "scores": {int(i): d.score() for i, d in plan.disagreement.items()},
            "holes": {int(i): d.hole_fraction for i, d in plan.disagreement.items()},
            "patched": {int(i): list(v) for i, v in plan.patched.items()},
            "noise": done.noise, "n_geometry": done.n_geometry, "n_blocks": done.n_blocks,
            "emission_keyframes": [int(i) for i in done.emission_keyframes], "probe_emission": done.probe_emission}


def merge_chunk_results(n_keyframes: int, chunks: list[dict], settings: dict) -> tuple[list, list, dict]:
    """Names and sources of every keyframe, and the ``schedule.warp`` fields of ``timeline.json``, from the
    chunks' :func:`chunk_result` (any order) and the plan's warp ``settings`` (:attr:`RenderPlan.warp`)."""
    names, sources = [None] * n_keyframes, [None] * n_keyframes
    scores, holes, patched = {}, {}, {}
    n_geometry = n_blocks = 0
    emission_keyframes, probe_emission = set(), False
    noise = 0.0
    for c in sorted(chunks, key=lambda c: c["lo"]):
        names[c["lo"]:c["hi"] + 1] = c["names"]
        sources[c["lo"]:c["hi"] + 1] = c["sources"]
        scores.update({int(k): v for k, v in c["scores"].items()})
        holes.update({int(k): v for k, v in c["holes"].items()})
        patched.update({int(k): tuple(v) for k, v in c["patched"].items()})
        n_geometry += c["n_geometry"]
        n_blocks += c["n_blocks"]
        emission_keyframes.update(c.get("emission_keyframes", ()))
        probe_emission |= bool(c.get("probe_emission", False))
        noise = c["noise"]
    if any(n is None for n in names):
        raise ValueError("the chunks do not cover every keyframe")
    layer = bool(settings.get("emission_layer", False))
    # Keyframes given an emission pass: rendered ones that show an emitter (to subtract), synthesized ones between
    # such (to add), and the noise probe when keyframe 0 shows one. Counted per keyframe (a union over chunks), so
    # the timeline does not depend on how the render was chunked (a chunk re-renders its first anchor's pass).
    n_emission = len(emission_keyframes) + int(probe_emission)
    warp = {"stride": settings["stride"], "threshold": settings["threshold"], "emission_layer": layer,
            "render_noise": noise, "n_geometry_passes": n_geometry, "n_emission_passes": n_emission,
            "n_block_renders": n_blocks,
            **describe_scores(scores, holes), **describe_patches(patched)}
    return names, sources, warp

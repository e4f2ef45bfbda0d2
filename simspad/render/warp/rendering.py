"""``--interpolation warp``: render the anchor keyframes with Mitsuba and synthesize the rest by reprojection.

:func:`render_with_warps` is what :func:`simspad.render.renderer.render_sequence` calls instead of rendering every
keyframe: it renders (or re-uses from the cache) the keyframes :mod:`simspad.render.warp.schedule` asks for,
and writes the synthesized ones (:mod:`simspad.render.warp.synthesis`) as ordinary keyframes of the render directory
(same EXR layout: R, G, B, Z, and ``object_id`` when the scene animates objects). Rendered keyframes keep the
names (cache keys) of a linear render, so both schedules share them; synthesized ones are keyed by the same
fields plus the synthesis version and parameters. Where the warps disagree in places, :class:`BlockPatcher`
renders those blocks (:mod:`simspad.render.blocks`) into the synthesized keyframes. With the emission layer
(``emission_layer`` in the layout's warp settings), a rendered keyframe with an emitter in view gets an emission pass
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
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.ndimage import gaussian_filter

from simspad.io.exr import read_exr, write_exr
from simspad.motion.trajectory import TrajectorySet
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.noise_budget import PROBE_SEED_OFFSET
from simspad.render.converged import converged_renderer, layout_convergence, layout_radiance
from simspad.render.blocks import block_window, blocks_of_tiles, render_fraction, tiles_of_blocks
from simspad.render.flow import object_poses
from simspad.render.keyframe_files import frame_key, frame_names, write_frame
from simspad.render.mitsuba_scene import PSF_REACH_PX, CompileCounter, MitsubaScene
from simspad.render.render_layout import RenderLayout
from simspad.render.reprojection import PinholeCamera
from simspad.render.warp.synthesis import WarpSource
from simspad.render.warp.schedule import (
    SynthesisReport,
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
    report: SynthesisReport  # source of each keyframe, disagreement of the synthesized ones
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
    """Cache-key fields of synthesized keyframes, from a layout's :attr:`RenderLayout.warp` settings."""
    return dict(base_key, warp=WARP_VERSION, warp_stride=int(warp["stride"]), warp_threshold=float(warp["threshold"]),
                warp_emission=bool(warp.get("emission_layer", False)))


class BlockPatcher:
    """Renders image blocks (:mod:`simspad.render.blocks`) into synthesized keyframes: the
    :class:`simspad.render.warp.schedule.Patcher` of a Mitsuba scene."""

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


def _probe_objects(ts: TrajectorySet, layout: RenderLayout) -> dict:
    """The animated objects' poses at keyframe 0, as the layout has them (a faster render's shared keyframes were
    laid out on the slower trajectory), else from the trajectory."""
    if layout.objects_to_world:
        return {k: np.asarray(m) for k, m in layout.objects_to_world[0].items()}
    return object_poses(ts, layout.times_s[0])


def noise_probe_name(layout: RenderLayout) -> str:
    """Relative file of the noise probe: keyframe 0 rendered again with the next seed (not a keyframe)."""
    return f"frames/noise-probe-{frame_key(dict(layout.base_key, noise_probe=1), layout.times_s[0])}.exr"


def cache_probe_names(layout: RenderLayout) -> tuple[str, str]:
    """Relative files of a converged render's cache probes: keyframe 0 (the render's seed) from each half of its
    irradiance cache (:meth:`~simspad.render.converged.IrradianceCache.half`)."""
    return tuple(f"frames/noise-probe-{frame_key(dict(layout.base_key, noise_probe=1, cache_half=k), layout.times_s[0])}"
                 f".exr" for k in (0, 1))


def render_noise_probe(ms: MitsubaScene, ts: TrajectorySet, layout: RenderLayout, out_dir: Path) -> bool:
    """Render the noise probe (keyframe 0's radiance with the layout's seed + 1) into ``out_dir`` unless it is
    there; True if it was rendered now. The warp schedule judges its warps against it, and every render's
    ``timeline.json`` states its render-noise budget from it (:func:`simspad.render.renderer.measure_render_noise`).

    A converged render's probe is its own keyframe 0 from the same cache with the next seed: the noise that
    changes from keyframe to keyframe (camera rays, glossy chains). The cache's noise stays on the surfaces, and
    is measured apart: keyframe 0 with the render's seed from each half of the cache (:func:`cache_probe_names`)."""
    path = out_dir / noise_probe_name(layout)
    if path.is_file():
        return False
    converged = layout_convergence(layout) is not None
    if converged:  # the cache is read or built first: building it poses the probe views
        cr, cache = converged_renderer(layout, ms, ts, out_dir)
    objects = _probe_objects(ts, layout)
    ms.set_pose(np.asarray(layout.camera_to_world[0]), objects)
    if not converged:
        rgb = ms.render_radiance(layout.seed + PROBE_SEED_OFFSET)
    else:
        halves = [cache.half(k) for k in (0, 1)]
        if None not in halves:
            for name, half in zip(cache_probe_names(layout), halves):
                _write_rgb(out_dir / name, cr.render(half, layout.seed, objects))
        rgb = cr.render(cache, layout.seed + PROBE_SEED_OFFSET, objects)
    _write_rgb(path, rgb)  # last: its presence means the probe is complete
    return True


def _write_rgb(path: Path, rgb: np.ndarray) -> None:
    write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})


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


class MitsubaKeyframes:
    """The :class:`~simspad.render.warp.schedule.KeyframeSource` of a loaded Mitsuba scene: the keyframes of a warp
    ``layout`` rendered into ``out_dir`` (files already there re-used), a 1-spp geometry pass per synthesized
    keyframe, emission passes with the emission layer, synthesized keyframes written under their own names; what
    it rendered is counted for :class:`WarpedFrames`."""

    def __init__(self, ms: MitsubaScene, ts: TrajectorySet, layout: RenderLayout, out_dir: Path,
                 counter: CompileCounter, bar, radiance=None):
        self.ms, self.ts, self.out_dir, self.counter, self.bar = ms, ts, out_dir, counter, bar
        #: A converged render's radiance (``radiance(seed, object_poses)`` from its cache); None: path tracing.
        self.radiance = radiance
        self.times, self.cam_poses, self.seed = (np.asarray(layout.times_s), np.asarray(layout.camera_to_world),
                                                 layout.seed)
        self.with_emission = bool(layout.warp.get("emission_layer", False))
        # A layout's names are those of rendered keyframes until the warp results replace them.
        self.render_names = layout.names
        self.warp_names = frame_names(warp_key(layout.base_key, layout.warp), self.times)
        self.names = list(self.warp_names)  # each keyframe's file as it turns out
        self.frame_times, self.compiled, self.n_reused = [], [], 0
        self.geometry_times = []
        #: Keyframe 0, when rendered or read for the noise map before the schedule asks for it.
        self.ready: dict = {}
        self.emitting = set()  # rendered keyframes that show an emitter (each got an emission pass)

    def poses_at(self, i: int) -> tuple:
        """Camera-to-world and object poses (by name) of keyframe ``i``, as :meth:`MitsubaScene.set_pose` takes them."""
        return self.cam_poses[i], object_poses(self.ts, float(self.times[i]))

    def pose(self, i: int) -> tuple:
        objects = self.poses_at(i)[1]
        return self.cam_poses[i], tuple(objects[k] for k in self.ms.object_names)

    def source_emission(self, i: int) -> np.ndarray | None:
        """Directly visible emission of rendered keyframe ``i`` (the pose must be set): None without the layer, or
        where a 1-spp pass sees no emitter (then its radiance is all reflected light, warped as it is)."""
        if not self.with_emission or not self.ms.emitter_in_view(self.seed):
            return None
        self.emitting.add(i)
        return self.ms.render_emission(self.seed)

    def render(self, i: int) -> WarpSource:
        ms = self.ms
        self.names[i] = self.render_names[i]
        if i in self.ready:
            return self.ready.pop(i)
        path = self.out_dir / self.render_names[i]
        if path.is_file():
            self.n_reused += 1
            data = read_exr(path)
            if self.with_emission:  # the emission pass is not stored: the keyframe file stays a linear render's
                ms.set_pose(*self.poses_at(i))
            return WarpSource(data["rgb"], data["z"], self.cam_poses[i], data.get("object_id"), self.pose(i)[1],
                              self.source_emission(i))
        tic = time.perf_counter()
        ms.set_pose(*self.poses_at(i))
        rgb = (ms.render_radiance(self.seed) if self.radiance is None
               else self.radiance(self.seed, self.poses_at(i)[1]))
        depth, object_id = ms.render_depth_ids(self.seed)
        write_frame(path, rgb, depth, object_id)
        self.frame_times.append(time.perf_counter() - tic)
        self.compiled.append(self.counter.take())
        return WarpSource(rgb, depth, self.cam_poses[i], object_id, self.pose(i)[1], self.source_emission(i))

    def geometry(self, i: int) -> tuple:
        """Depth and ids of keyframe ``i`` from a geometry pass (1 spp; the same seed as its radiance)."""
        tic = time.perf_counter()
        self.ms.set_pose(*self.poses_at(i))
        depth, object_id = self.ms.render_depth_ids(self.seed)
        self.geometry_times.append(time.perf_counter() - tic)
        return depth, object_id

    def emission(self, i: int) -> np.ndarray | None:
        """Directly visible emission of keyframe ``i`` (the same seed as its radiance); None without the layer."""
        if not self.with_emission:
            return None
        self.ms.set_pose(*self.poses_at(i))
        return self.ms.render_emission(self.seed)

    def write(self, i: int, rgb, depth, object_id) -> None:
        path = self.out_dir / self.warp_names[i]
        if not path.is_file():  # synthesis is deterministic: an existing file holds these very pixels
            write_frame(path, rgb, depth, object_id)

    def written(self, i: int) -> bool:
        """Synthesized keyframe ``i``'s file is there (a resumed render)."""
        return (self.out_dir / self.warp_names[i]).is_file()

    def final(self, i: int) -> None:
        self.bar.update(1)


def render_with_warps(ms: MitsubaScene, ts: TrajectorySet, layout: RenderLayout, out_dir: Path,
                      counter: CompileCounter, bar, *, anchors: list[int] | None = None) -> WarpedFrames:
    """Render and synthesize the keyframes of a warp ``layout`` (:attr:`RenderLayout.warp`: stride and threshold)
    into ``out_dir``; ``bar.update(1)`` per keyframe.

    With ``anchors`` (consecutive anchors of :func:`simspad.render.warp.schedule.anchor_indices`) only the
    keyframes from the first to the last of them: a chunk of the render, as ``simspad generate`` spreads them
    over workers. Anchors and the noise probe (:func:`render_noise_probe`) found in ``out_dir`` are re-used; the
    noise map is computed from keyframe 0's file and the probe's, so every chunk decides with the same numbers.
    """
    radiance = layout_radiance(layout, ms, ts, out_dir)  # a converged render's cache (None: path tracing)
    keyframes = MitsubaKeyframes(ms, ts, layout, out_dir, counter, bar, radiance)
    stride, threshold = layout.warp["stride"], layout.warp["threshold"]
    camera = PinholeCamera.from_fov(ms.x_fov_deg, ms.width, ms.height)
    first = 0 if anchors is None else anchors[0]
    tic = time.perf_counter()
    noise_y, noise = None, 0.0
    probe_emission = False  # the noise map needed the probe's emission pass (keyframe 0 shows an emitter)
    if len(keyframes.times) > 2:
        if first == 0:
            keyframes.ready[0] = keyframes.render(0)
            key0 = keyframes.ready[0].rgb
        else:
            key0 = read_exr(out_dir / keyframes.render_names[0])["rgb"]
        # (a converged render's probe is keyframe 0 from the same cache with the next seed: its warps are judged
        # against its own keyframe-to-keyframe noise)
        render_noise_probe(ms, ts, layout, out_dir)
        probe = read_exr(out_dir / noise_probe_name(layout))["rgb"]
        if keyframes.with_emission:
            ms.set_pose(*keyframes.poses_at(0))
            key0_emission = keyframes.ready[0].emission if first == 0 else keyframes.source_emission(0)
            if key0_emission is not None:  # the warps move reflected light only: judge them against its noise
                probe_emission = True
                key0 = np.maximum(key0 - key0_emission, 0.0)
                probe = np.maximum(probe - ms.render_emission(layout.seed + PROBE_SEED_OFFSET), 0.0)
        noise_y, noise = noise_map(key0, probe)
    # Blocks are path-traced: a converged render re-renders whole keyframes where the warps disagree.
    patcher = (BlockPatcher(ms, keyframes.poses_at, layout.seed, keyframes.written) if radiance is None
               else None)
    report = synthesize_keyframes(camera, keyframes.times, keyframes, stride=stride, threshold=threshold,
                                  noise_y=noise_y, patch=patcher, anchors=anchors)
    return WarpedFrames(keyframes.names, report, keyframes.frame_times, keyframes.compiled, keyframes.n_reused,
                        time.perf_counter() - tic, stride, threshold, noise, len(keyframes.geometry_times),
                        float(sum(keyframes.geometry_times)), patcher.n_blocks if patcher else 0,
                        patcher.seconds if patcher else 0.0,
                        sorted(keyframes.emitting | report.emission_passes), probe_emission)


@dataclass(frozen=True)
class SegmentReport:
    """What a chunk of a warp render (keyframes ``lo``..``hi``, anchors included) did: plain picklable data for the
    driver that writes ``timeline.json`` (:func:`merge_chunk_results`).

    Attributes
    ----------
    lo, hi : int
        First and last keyframe of the chunk.
    names, sources : tuple of str
        File and ``source`` of keyframes ``lo``..``hi``.
    scores, holes : dict
        Disagreement score and hole fraction of each synthesized keyframe (index → value).
    patched : dict
        Keyframes with blocks rendered for real: index → (cost as a fraction of a render, score after).
    noise : float
        Monte Carlo noise of one render (RMS ÷ mean luminance).
    n_geometry, n_blocks : int
        Geometry passes and blocks rendered.
    emission_keyframes : tuple of int
        Keyframes given an emission pass.
    probe_emission : bool
        Whether the noise probe got one too.
    """

    lo: int
    hi: int
    names: tuple
    sources: tuple
    scores: dict
    holes: dict
    patched: dict
    noise: float
    n_geometry: int
    n_blocks: int
    emission_keyframes: tuple = ()
    probe_emission: bool = False


def chunk_result(done: WarpedFrames, lo: int, hi: int) -> SegmentReport:
    """What a chunk of keyframes ``lo``..``hi`` (anchors included) reports (:class:`SegmentReport`)."""
    report = done.report
    return SegmentReport(lo=lo, hi=hi, names=tuple(done.names[lo:hi + 1]), sources=tuple(report.sources[lo:hi + 1]),
                         scores={int(i): d.score() for i, d in report.disagreement.items()},
                         holes={int(i): d.hole_fraction for i, d in report.disagreement.items()},
                         patched={int(i): tuple(v) for i, v in report.patched.items()},
                         noise=done.noise, n_geometry=done.n_geometry, n_blocks=done.n_blocks,
                         emission_keyframes=tuple(int(i) for i in done.emission_keyframes),
                         probe_emission=bool(done.probe_emission))


def merge_chunk_results(n_keyframes: int, chunks: list[SegmentReport], settings: dict) -> tuple[list, list, dict]:
    """Names and sources of every keyframe, and the ``schedule.warp`` fields of ``timeline.json``, from the
    chunks' :func:`chunk_result` (any order) and the layout's warp ``settings`` (:attr:`RenderLayout.warp`)."""
    names, sources = [None] * n_keyframes, [None] * n_keyframes
    scores, holes, patched = {}, {}, {}
    n_geometry = n_blocks = 0
    emission_keyframes, probe_emission = set(), False
    noise = 0.0
    for c in sorted(chunks, key=lambda c: c.lo):
        names[c.lo:c.hi + 1] = c.names
        sources[c.lo:c.hi + 1] = c.sources
        scores.update({int(k): v for k, v in c.scores.items()})
        holes.update({int(k): v for k, v in c.holes.items()})
        patched.update({int(k): tuple(v) for k, v in c.patched.items()})
        n_geometry += c.n_geometry
        n_blocks += c.n_blocks
        emission_keyframes.update(c.emission_keyframes)
        probe_emission |= c.probe_emission
        noise = c.noise
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

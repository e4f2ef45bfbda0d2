"""Which keyframes to render and which to synthesize (``--interpolation warp``).

The keyframe instants are those of the linear schedule (:func:`simspad.render.schedule.keyframe_schedule`), so a
warp timeline is as dense in time as a linear one; only every ``stride``-th keyframe (and the last) is rendered
up front. The keyframes between two rendered ones are synthesized by :func:`simspad.render.warp.synthesis.synthesize`.
If the worst of them disagrees by more than ``threshold`` (:meth:`simspad.render.warp.synthesis.Disagreement.score`), it
is usually in a few places only (a bright textured window behind thin mullions): then, with a ``patch``
(:class:`Patcher`), just the image blocks holding the failing tiles are rendered for real in every keyframe of the
segment (the same blocks throughout, so their Monte Carlo noise stays frozen as a whole render's does), as long
as they cost at most :data:`PATCH_MAX_FRACTION` of a render per keyframe and :data:`PATCH_MAX_RENDERS` renders
over the segment. Otherwise the keyframe in the middle is rendered for real and both halves are treated again
(recursive bisection), down to neighbours. The renderer's side is one object, a :class:`KeyframeSource`: it
renders keyframes, gives their poses, stores synthesized ones and hears when each is final; where it renders a
geometry pass (1-spp depth + ids) at each synthesized instant, the target's depth and ids are rendered rather
than splatted from the sources. Decisions depend only on the rendered pixels, so the schedule is deterministic; at most
``log2(stride)`` levels of re-synthesis are done per segment, and only two rendered keyframes per level are held
in memory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from simspad.render.reprojection import PinholeCamera
from simspad.render.warp.synthesis import Disagreement, WarpSource, prepare, synthesize

#: Rendered keyframes are at most this many keyframes of the linear schedule apart.
WARP_STRIDE = 16
#: Largest disagreement score of a synthesized keyframe (:meth:`simspad.render.warp.synthesis.Disagreement.score`):
#: the worst tile's RMS difference of the two warps in units of what two renders' Monte Carlo noise alone would give
#: (≈ 1 where the warps agree up to noise), plus holes. Two warps with independent errors s differ by √2·s and their
#: mid-way blend errs by s/√2: a ratio ≤ 2 keeps the blend's error within about √2 × a render's own noise.
WARP_THRESHOLD = 2.0
#: Largest cost (as a fraction of a whole render) of the blocks rendered into each keyframe of a segment whose
#: warps disagree; past it the segment is bisected instead. A block's noise pattern is not a whole render's, so
#: blocks cost events where they start and stop: office at 256×192, 16 spp, 48 ms, against linear's 49 renders:
#: this bound 35.1 renders, events +2.3 % ON / +1.9 % OFF; without it (only the segment bound below) 25.5 renders,
#: +5.0 % / +1.2 % ...
PATCH_MAX_FRACTION = 0.25
#: ... and at most this many whole renders over the segment: beyond that, rendering the middle keyframe (after which
#: the halves often agree) is the better bet. Measured (bench_warp, 64×48, 16 spp, 48 ms): office 14.0 → 11.6
#: renders with blocks; the fan, whose warps disagree along its moving blades, 24.0 → 21.9, where blocks without
#: this bound took 26.8 (15 keyframes of blocks instead of one render that settles the segment).
PATCH_MAX_RENDERS = 1.0
#: ``source`` of a keyframe in ``timeline.json``.
SOURCE_RENDER, SOURCE_WARP = "render", "warp"


def anchor_indices(n_keyframes: int, stride: int) -> list[int]:
    """Indices rendered up front: 0, stride, 2·stride, ..., and the last."""
    if n_keyframes < 1 or stride < 1:
        raise ValueError("n_keyframes and stride must be >= 1")
    idx = list(range(0, n_keyframes, stride))
    if idx[-1] != n_keyframes - 1:
        idx.append(n_keyframes - 1)
    return idx


class KeyframeSource(Protocol):
    """The keyframes of a render as :func:`synthesize_keyframes` sees them, by index: the renderer's side
    (:class:`simspad.render.warp.rendering.MitsubaKeyframes` for a Mitsuba scene)."""

    def render(self, i: int) -> WarpSource:
        """Keyframe ``i`` rendered for real (or read from its file) and written."""

    def pose(self, i: int) -> tuple[np.ndarray, tuple]:
        """``(camera_to_world, object_poses)`` of keyframe ``i`` (object poses in the order of
        :attr:`WarpSource.object_poses`)."""

    def geometry(self, i: int) -> tuple[np.ndarray, np.ndarray | None] | None:
        """``(depth_z, object_id)`` of keyframe ``i`` from a rendered geometry pass, asked once per synthesized
        keyframe; None: the target geometry is splatted from the sources
        (:func:`simspad.render.warp.synthesis.synthesize`)."""

    def emission(self, i: int) -> np.ndarray | None:
        """The directly visible emission of keyframe ``i`` (an emission pass; the sources then carry theirs,
        :class:`~simspad.render.warp.synthesis.WarpSource`), asked for each keyframe synthesized between sources
        of which at least one shows emission; None without an emission layer. Between two sources that show
        none, the warp needs none: an emitter that would come into view only between them is warped like any
        surface."""

    def write(self, i: int, rgb: np.ndarray, depth_z: np.ndarray, object_id: np.ndarray | None) -> None:
        """Store synthesized keyframe ``i``."""

    def final(self, i: int) -> None:
        """Keyframe ``i`` is final, rendered or synthesized (progress)."""


class Patcher(Protocol):
    """Renders parts of a synthesized keyframe for real (:class:`simspad.render.warp.rendering.BlockPatcher` for a
    Mitsuba scene)."""

    def blocks(self, tiles: np.ndarray) -> np.ndarray:
        """The blocks (bool, block grid) that hold ``tiles`` (bool, tile grid of the disagreement)."""

    def tiles(self, blocks: np.ndarray, tile_shape: tuple[int, int]) -> np.ndarray:
        """The tiles (bool, tile grid of ``tile_shape``) that ``blocks`` cover."""

    def cost(self, blocks: np.ndarray) -> float:
        """What rendering ``blocks`` costs, as a fraction of a whole render."""

    def apply(self, i: int, blocks: np.ndarray, rgb: np.ndarray) -> np.ndarray:
        """``rgb`` of keyframe ``i`` with ``blocks`` rendered for real."""


@dataclass
class SynthesisReport:
    """What the synthesis did.

    Attributes
    ----------
    sources : list of str
        ``"render"`` or ``"warp"`` per keyframe.
    disagreement : dict
        Score of each keyframe that was finally synthesized (index → :class:`Disagreement`), before patching.
    patched : dict
        Keyframes with blocks rendered for real: index → (cost as a fraction of a render, score of what stayed
        synthesized).
    emission_passes : set
        Keyframes given an emission pass as targets of a synthesis (whether they stayed synthesized or not).
    """

    sources: list
    disagreement: dict = field(default_factory=dict)
    patched: dict = field(default_factory=dict)
    emission_passes: set = field(default_factory=set)

    @property
    def n_rendered(self) -> int:
        return sum(s == SOURCE_RENDER for s in self.sources)

    @property
    def patch_renders(self) -> float:
        """Render work of the patched blocks, in whole renders."""
        return float(sum(cost for cost, _ in self.patched.values()))


def synthesize_keyframes(camera: PinholeCamera, times_s: np.ndarray, keyframes: KeyframeSource, *,
                         stride: int = WARP_STRIDE, threshold: float = WARP_THRESHOLD,
                         noise_y: np.ndarray | None = None, patch: Patcher | None = None,
                         anchors: list[int] | None = None) -> SynthesisReport:
    """Render the anchors, synthesize the rest, render where the warps disagree.

    Parameters
    ----------
    camera : PinholeCamera
    times_s : ndarray (K,)
        All keyframe instants, s.
    keyframes : KeyframeSource
        Renders, poses, geometry and emission passes of keyframes by index, stores synthesized ones, and hears
        when each is final (:class:`simspad.render.warp.rendering.MitsubaKeyframes` for a Mitsuba scene).
    stride : int
        Rendered keyframes up front are this many keyframes apart (:data:`WARP_STRIDE`).
    threshold : float
        Largest :meth:`Disagreement.score` accepted (:data:`WARP_THRESHOLD`: in units of the render noise when
        ``noise_y`` is given).
    noise_y : ndarray [H, W], optional
        Monte Carlo noise of one render per pixel (absolute σ of luminance), see
        :func:`simspad.render.warp.synthesis.synthesize`.
    patch : Patcher, optional
        Renders the blocks of a segment's synthesized keyframes where the warps disagree, instead of bisecting,
        when that costs at most :data:`PATCH_MAX_FRACTION` of a render per keyframe and :data:`PATCH_MAX_RENDERS`
        renders in all (needs ``noise_y``).
    anchors : list of int, optional
        Consecutive anchors of :func:`anchor_indices` (``stride`` apart): only the keyframes from the first to
        the last of them are treated (a chunk of a render spread over processes; the segments between anchors
        are independent). Default: all.

    Returns
    -------
    SynthesisReport
    """
    times = np.asarray(times_s, dtype=np.float64)
    n = times.size
    sources = [SOURCE_WARP] * n
    result = SynthesisReport(sources)
    tick = keyframes.final
    geometries: dict = {}  # keyframe → its geometry pass, until it is written or rendered (≤ stride frames)
    emissions: dict = {}  # keyframe → its emission pass, likewise

    def geometry_of(i: int):
        if i not in geometries:
            geometries[i] = keyframes.geometry(i)
        return geometries[i]

    def emission_of(i: int):
        if i not in emissions:
            emissions[i] = keyframes.emission(i)
            if emissions[i] is not None:
                result.emission_passes.add(i)
        return emissions[i]

    def rendered(i: int):
        geometries.pop(i, None)
        emissions.pop(i, None)
        sources[i] = SOURCE_RENDER
        p = prepare(keyframes.render(i))
        tick(i)
        return p

    def fill(i0: int, p0, i1: int, p1) -> None:
        if i1 - i0 <= 1:
            return
        frames = {}
        for i in range(i0 + 1, i1):
            pose, objects = keyframes.pose(i)
            w = float((times[i] - times[i0]) / (times[i1] - times[i0]))
            target_emission = emission_of(i) if p0.emits or p1.emits else None
            frames[i] = synthesize(camera, p0, p1, w, pose, objects, noise_y, geometry_of(i), target_emission)
        worst = max(f[3].score() for f in frames.values())
        if worst <= threshold:
            for i, (rgb, depth, ids, dis) in frames.items():
                keyframes.write(i, rgb, depth, ids)
                geometries.pop(i, None)
                emissions.pop(i, None)
                result.disagreement[i] = dis
                tick(i)
            return
        if patch is not None and noise_y is not None:
            failing = np.logical_or.reduce([f[3].failing_tiles(threshold) for f in frames.values()])
            blocks = patch.blocks(failing)
            cost = patch.cost(blocks)
            if cost <= PATCH_MAX_FRACTION and (i1 - i0 - 1) * cost <= PATCH_MAX_RENDERS:
                covered = patch.tiles(blocks, failing.shape)
                for i, (rgb, depth, ids, dis) in frames.items():
                    keyframes.write(i, patch.apply(i, blocks, rgb), depth, ids)
                    geometries.pop(i, None)
                    emissions.pop(i, None)
                    result.disagreement[i] = dis
                    result.patched[i] = (cost, dis.score_outside(covered))
                    tick(i)
                return
        del frames
        m = (i0 + i1) // 2
        pm = rendered(m)
        fill(i0, p0, m, pm)
        fill(m, pm, i1, p1)

    if anchors is None:
        anchors = anchor_indices(n, stride)
    prev_i, prev_p = anchors[0], rendered(anchors[0])
    for i in anchors[1:]:
        p = rendered(i)
        fill(prev_i, prev_p, i, p)
        prev_i, prev_p = i, p
    return result


def describe_disagreement(dis: dict) -> dict:
    """Summary of the synthesized keyframes' disagreement for ``timeline.json`` (max and median scores)."""
    return describe_scores({i: d.score() for i, d in dis.items()}, {i: d.hole_fraction for i, d in dis.items()})


def describe_scores(scores: dict, holes: dict) -> dict:
    """:func:`describe_disagreement` from each synthesized keyframe's score and hole fraction (index → value)."""
    if not scores:
        return {"n_warped": 0}
    values = np.array([scores[i] for i in sorted(scores)])
    return {"n_warped": len(scores), "max_score": float(values.max()), "median_score": float(np.median(values)),
            "max_hole_fraction": float(max(holes.values()))}


def describe_patches(patched: dict) -> dict:
    """Summary of the blocks rendered into synthesized keyframes for ``timeline.json``."""
    if not patched:
        return {"n_patched": 0, "patch_renders": 0.0}
    costs = np.array([c for c, _ in patched.values()])
    return {"n_patched": len(patched), "patch_renders": float(costs.sum()), "max_patch_fraction": float(costs.max()),
            "max_score_after_patch": float(max(r for _, r in patched.values()))}


__all__ = ["PATCH_MAX_FRACTION", "PATCH_MAX_RENDERS", "SOURCE_RENDER", "SOURCE_WARP", "WARP_STRIDE",
           "WARP_THRESHOLD", "Disagreement", "KeyframeSource", "Patcher", "SynthesisReport", "anchor_indices",
           "describe_disagreement",
           "describe_patches", "describe_scores", "synthesize_keyframes"]

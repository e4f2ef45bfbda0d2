"""The layout of one render: every keyframe's instant, pose and file name, and what ``timeline.json`` will say.

A render runs in three stages (:mod:`simspad.render.renderer`): *layout* (load the scene once, predict the image
motion, choose the keyframe instants: :func:`~simspad.render.renderer.layout_render` gives a
:class:`RenderLayout`), *render* any subset of keyframe indices, in any number of processes or machines, and
*finalize* (write ``timeline.json`` once every keyframe file exists). Each keyframe is rendered with the same
fixed seed and named by a hash of everything that determines its pixels, so its bytes do not depend on which
chunk, process or order rendered it. A layout is plain data (picklable, and JSON-serialisable through
:meth:`RenderLayout.to_dict`), so it travels to workers as a job argument and finalizing needs no Mitsuba.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class RenderLayout:
    """Everything the render and finalize stages need, computed once by the layout stage.

    Attributes
    ----------
    times_s : tuple of float
        Keyframe instants, seconds, strictly increasing.
    names : tuple of str
        Keyframe files relative to the render directory (``frames/<index>-<cache key>.exr``).
    camera_to_world : tuple
        4×4 camera-to-world matrix of each keyframe (nested lists).
    width, height, spp, seed : int
        Image size (px), samples per pixel and Monte Carlo seed of every keyframe.
    variant : str
        Mitsuba variant the layout was made with; every render stage must use the same one.
    scene_hash, trajectory_hash : str
        Content hashes of the scene and the trajectory, checked by each render stage.
    timeline : dict
        The top-level fields of ``timeline.json`` other than size and keyframes (scene, trajectory, span,
        renderer settings, schedule).
    objects_to_world : tuple of dict
        Per keyframe, each animated object's 4×4 object-to-world matrix (empty when nothing moves).
    sources : tuple of str
        Per keyframe ``"render"`` or ``"warp"`` (empty: every keyframe is rendered).
    base_key : dict
        What determines a rendered keyframe's pixels (its cache key, from which the file names derive).
    """

    times_s: tuple
    names: tuple
    camera_to_world: tuple
    width: int
    height: int
    spp: int
    seed: int
    variant: str
    scene_hash: str
    trajectory_hash: str
    timeline: dict = field(default_factory=dict)
    objects_to_world: tuple = ()
    sources: tuple = ()
    base_key: dict = field(default_factory=dict)

    @property
    def n_keyframes(self) -> int:
        return len(self.times_s)

    @property
    def warp(self) -> dict | None:
        """``{"stride", "threshold", "emission_layer"}`` when keyframes are to be synthesized by warping (``--interpolation warp``
        and a sequence long enough), else None."""
        schedule = self.timeline.get("schedule", {})
        return schedule.get("warp") if schedule.get("interpolation") == "warp" else None

    @property
    def n_shared(self) -> int:
        """How many of the first keyframes are another render's (the same sequence played slower): linked from
        its directory, not rendered."""
        return int(self.timeline.get("schedule", {}).get("shared_keyframes", {}).get("n_keyframes", 0))

    def keyframes(self) -> list[dict]:
        """The ``keyframes`` list of ``timeline.json``."""
        keyframes = [{"t": float(t), "file": name, "camera_to_world": [list(row) for row in pose],
                      "source": self.sources[i] if self.sources else "render"}
                     for i, (t, name, pose) in enumerate(zip(self.times_s, self.names, self.camera_to_world))]
        for kf, objects in zip(keyframes, self.objects_to_world):
            kf["object_to_world"] = objects
        return keyframes

    def to_dict(self) -> dict:
        return {"times_s": list(self.times_s), "names": list(self.names),
                "camera_to_world": [[list(row) for row in pose] for pose in self.camera_to_world],
                "width": self.width, "height": self.height, "spp": self.spp, "seed": self.seed,
                "variant": self.variant, "scene_hash": self.scene_hash, "trajectory_hash": self.trajectory_hash,
                "timeline": self.timeline, "objects_to_world": list(self.objects_to_world),
                "sources": list(self.sources), "base_key": self.base_key}

    @classmethod
    def from_dict(cls, d: dict) -> "RenderLayout":
        return cls(times_s=tuple(float(t) for t in d["times_s"]), names=tuple(d["names"]),
                   camera_to_world=tuple(tuple(tuple(float(v) for v in row) for row in pose)
                                         for pose in d["camera_to_world"]),
                   width=int(d["width"]), height=int(d["height"]), spp=int(d["spp"]), seed=int(d["seed"]),
                   variant=str(d["variant"]), scene_hash=str(d["scene_hash"]),
                   trajectory_hash=str(d["trajectory_hash"]), timeline=dict(d["timeline"]),
                   objects_to_world=tuple(d.get("objects_to_world", ())), sources=tuple(d.get("sources", ())),
                   base_key=dict(d.get("base_key", {})))


def keyframe_chunks(indices, chunk_size: int) -> list[list[int]]:
    """Split keyframe ``indices`` into consecutive chunks of at most ``chunk_size`` (neighbouring keyframes share
    the most kernels and scene state, so a chunk is a run of consecutive indices)."""
    indices = list(indices)
    chunk_size = max(1, int(chunk_size))
    return [indices[i:i + chunk_size] for i in range(0, len(indices), chunk_size)]


def chunk_size_for(n_keyframes: int, workers: int, per_worker: int = 4, largest: int = 64) -> int:
    """Keyframes per chunk: about ``per_worker`` chunks per worker, so a slow chunk does not leave the others idle
    at the end, but at most ``largest`` so progress and resume stay fine-grained."""
    return max(1, min(largest, math.ceil(n_keyframes / max(1, workers * per_worker))))

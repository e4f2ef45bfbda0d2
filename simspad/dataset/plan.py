"""The job plan: every render and recording a spec asks for, with the seeds and hashes that make it reproducible.

One render per (sequence, speed) (shared by all lux levels and sensors), one simulation per (sequence, speed, lux).
Every recording draws from ``child_seed(spec.seed, sequence, lux, kind)`` (stream key ``(sequence, lux)``), every
render from ``child_seed(spec.seed, sequence, "render")``, so outputs are the same whatever the executor, the
worker count or the order. A speed factor k ≠ 1 (:mod:`simspad.dataset.speed`) appends ``("speed", k)`` to both
keys and ``_x<k>`` to the names; k = 1 keeps them as a spec without a speed axis has them. A faster render that
shares the next slower one's keyframes (:func:`shares_keyframes`) takes that render's seed. Each task carries a
hash of everything its output depends on (spec content, scene and trajectory bytes, package versions, the speed
factor, :data:`JOB_SCHEME_VERSION`), which decides on a re-run whether it must be redone.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from simspad import __version__, defaults
from simspad.dataset.directory import RENDERS_DIR, recording_rel_path
from simspad.dataset.portable import portable_sequence, portable_trajectory
from simspad.dataset.spec_hashing import canonical_json, sequence_hash, spec_hash
from simspad.dataset.speed import speed_keys
from simspad.io.names import speed_suffix
from simspad.physics.radiometry import Optics
from simspad.physics.seeding import child_seed
from simspad.scenes.library import resolve_scene
from simspad.sensors.recording_settings import RecordingSettings

#: Bump when the job's output for an unchanged spec would change (part of every recording and render hash).
JOB_SCHEME_VERSION = 2  # 2: renders carry geometry passes at the ground-truth instants; recordings their flow


@dataclass(frozen=True)
class RenderTask:
    """One render: a sequence into ``<out>/<rel_dir>`` with Monte Carlo seed ``seed``."""

    sequence: Any  # simspad.dataset.spec.SequenceSpec
    render_hash: str
    rel_dir: str
    seed: int
    speed_factor: float = 1.0  # trajectory played this many times faster (simspad.dataset.speed)
    #: The same sequence's render at the next slower speed, whose keyframes are this render's first ones (the
    #: same poses, seed and settings: :func:`shares_keyframes`), or None.
    prefix: "RenderTask | None" = None
    #: Ground-truth rate, Hz: the render draws a geometry pass (depth, instance ids) at each ground-truth instant.
    gt_rate_hz: float = defaults.GT_RATE_HZ


@dataclass(frozen=True)
class RecordingTask:
    """One simulation: a (sequence, lux) recording at ``<out>/<rel_path>`` from the render ``render_rel_dir``.

    ``settings`` is what the simulator is given, built once here (lux, sensors, span, seed and stream key,
    ground-truth rate, optics); the executors pass it through.
    """

    sequence_name: str
    scene: str
    rel_path: str
    render_rel_dir: str
    recording_hash: str
    settings: RecordingSettings
    metadata: tuple  # ((key, value), ...): root attrs of the recording
    speed_factor: float = 1.0  # trajectory played this many times faster (simspad.dataset.speed)

    @property
    def lux(self) -> float:
        """The recording's illuminance, lx (``settings.lux``)."""
        return self.settings.lux


@dataclass(frozen=True)
class DatasetPlan:
    """Every render and every recording a dataset spec asks for (:func:`make_plan`): the driver's to-do list."""

    renders: tuple[RenderTask, ...]
    recordings: tuple[RecordingTask, ...]



def _versions() -> dict[str, str]:
    out = {"simspad": __version__, "job_scheme": str(JOB_SCHEME_VERSION)}
    for pkg in ("mitsuba", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "absent"
    return out


def _render_seed(dataset_seed: int, sequence_name: str, speed: float = 1.0) -> int:
    return int(child_seed(dataset_seed, sequence_name, "render", *speed_keys(speed)).generate_state(1)[0])


def scene_name(scene: str) -> str:
    return resolve_scene(scene).name


def make_plan(spec, created_utc: str) -> DatasetPlan:
    """Every render and recording of ``spec``, with the hashes that decide whether each must be (re)done.

    Resolving the scenes and hashing the scene and trajectory files happens here, in the calling process, so
    an unknown scene or a missing file fails before any work starts.
    """
    shared = _Shared(versions=_versions(), optics=Optics(), created_utc=created_utc)
    renders, recordings = [], []
    for seq in spec.sequences:
        seq_hash = sequence_hash(seq, spec)
        scene = scene_name(seq.scene)
        slower = {}  # speed -> its render, for the faster ones to share
        for k in sorted(float(v) for v in spec.speed):
            prev = slower[max(slower)] if slower and shares_keyframes(seq) else None
            slower[k] = _render_task(spec, seq, k, shared.versions, prev)
        for k in spec.speed:
            render = slower[float(k)]
            renders.append(render)
            for lux in spec.lux:
                recordings.append(_recording_task(spec, render, float(lux), seq_hash, scene, shared))
    return DatasetPlan(tuple(renders), tuple(recordings))


def shares_keyframes(seq) -> bool:
    """Whether the renders of ``seq`` at several speeds share keyframes: played k times faster from t = 0 the
    sequence passes through the slower one's poses, in 1/k of the time, so a faster render's first keyframes
    can be the slower render's files. Only linear renders from t = 0 (a later start plays a different part of
    the trajectory at each speed; warp renders choose their own keyframes to render), path-traced (a converged
    render lights its keyframes from its own irradiance cache, filled over its own span)."""
    return float(seq.start_s) == 0.0 and seq.interpolation == "linear" and seq.convergence == "off"


def _render_task(spec, seq, k: float, versions: dict, prefix: RenderTask | None = None) -> RenderTask:
    """The render of ``seq`` at speed ``k`` (k = 1: exactly the render of a spec without a speed axis); with
    ``prefix`` (the next slower speed's render) its first keyframes are the prefix's, so it takes the prefix's
    seed (the same pixels) and its hash depends on the prefix's."""
    seed = _render_seed(spec.seed, seq.name, k) if prefix is None else prefix.seed
    key = {"render": sequence_hash(seq), "seed": seed, "versions": versions,
           "gt_rate_hz": float(spec.evaluation.rate_hz)}
    if k != 1.0:
        key["speed_factor"] = k
    if prefix is not None:
        key["prefix"] = prefix.render_hash
    render_hash = spec_hash(key)
    return RenderTask(seq, render_hash, f"{RENDERS_DIR}/{seq.name}{speed_suffix(k)}-{render_hash[:12]}", seed,
                      speed_factor=k, prefix=prefix, gt_rate_hz=float(spec.evaluation.rate_hz))


@dataclass(frozen=True)
class _Shared:
    """What every recording of a plan shares, worked out once: package versions, optics, creation time."""

    versions: dict
    optics: Optics
    created_utc: str


def _recording_task(spec, render: RenderTask, lux: float, seq_hash: str, scene: str, shared: _Shared) -> RecordingTask:
    """The recording of ``render`` (a sequence at one speed k; k = 1: exactly the recording of a spec without a
    speed axis) at ``lux``; ``seq_hash`` and ``scene`` are the sequence's hash and scene name."""
    seq, k = render.sequence, render.speed_factor
    settings = RecordingSettings(
        lux=lux, sensors={kind: s.params for kind, s in spec.sensors.items()}, start_s=seq.start_s,
        duration_s=seq.duration_s, seed=spec.seed, stream_key=(seq.name, lux, *speed_keys(k)),
        gt_rate_hz=spec.evaluation.rate_hz, optics=shared.optics)
    optics = dataclasses.asdict(settings.optics)
    # What the file depends on; stored in the recording as its "spec" attr, so the hash and the file agree.
    rec_spec = {"dataset": spec.name, "seed": spec.seed, "sequence": portable_sequence(seq, spec.source_path),
                "lux": settings.lux, "stream_key": list(settings.stream_key),
                "sensors": {kind: s.to_dict() for kind, s in spec.sensors.items()},
                "evaluation": spec.evaluation.to_dict(), "optics": optics}
    hash_key = {"dataset": spec.name, "sequence": seq_hash, "render": render.render_hash, "lux": settings.lux,
                "stream_key": list(settings.stream_key), "optics": optics, "versions": shared.versions}
    metadata = {"sequence": seq.name, "scene": scene, "dataset": spec.name,
                "trajectory": portable_trajectory(seq, spec.source_path)}
    if k != 1.0:
        rec_spec["speed_factor"] = hash_key["speed_factor"] = metadata["speed_factor"] = k
    rec_hash = spec_hash(hash_key)
    metadata.update({"spec": canonical_json(rec_spec), "recording_hash": rec_hash,
                     "created_utc": shared.created_utc})
    return RecordingTask(sequence_name=seq.name, scene=scene, rel_path=recording_rel_path(seq.name, lux, k),
                         render_rel_dir=render.rel_dir, recording_hash=rec_hash, settings=settings,
                         metadata=tuple(sorted(metadata.items())), speed_factor=k)

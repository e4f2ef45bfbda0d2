"""Content hashes of dataset specs and sequences: what decides whether a render or a recording must be redone.

The hash of a spec or sequence covers the data it determines, not where it lives: scene and trajectory paths are
replaced by the bytes they name, and the output folder is left out, so one spec checked out elsewhere hashes the
same. Hashes are SHA-256 of a canonical JSON text (sorted keys, no whitespace).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from simspad.dataset.spec import DatasetSpec, SequenceSpec
from simspad.io.hashing import file_sha256
from simspad.scenes.library import content_hash, resolve_scene


def _jsonable(obj):
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_dict"):
            return obj.to_dict()
        return dataclasses.asdict(obj)
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot hash object of type {type(obj).__name__}")


def canonical_json(obj) -> str:
    """Canonical JSON text: sorted keys, no whitespace, dataclasses/Paths/numpy values converted."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False,
                      default=_jsonable)


def spec_hash(obj) -> str:
    """SHA-256 (hex) of the canonical JSON of ``obj``.

    For a :class:`DatasetSpec` the hash covers what decides the data: ``to_dict()`` without ``output``, with each
    sequence's scene and trajectory paths replaced by their contents (:func:`sequence_hash`), so the same spec
    checked out elsewhere or writing to another folder has the same hash.
    """
    if isinstance(obj, DatasetSpec):
        d = {k: v for k, v in obj.to_dict().items() if k != "output"}
        d["sequences"] = [{"name": s.name, "content": sequence_hash(s)} for s in obj.sequences]
        obj = d
    return hashlib.sha256(canonical_json(obj).encode("utf-8")).hexdigest()


def sequence_hash(seq: SequenceSpec, spec: DatasetSpec | None = None) -> str:
    """Content hash of what a sequence's data depends on.

    Without ``spec``: what the *render* depends on — the sequence fields (but not its name), the trajectory
    file's bytes instead of its path, and the scene's content hash (:func:`simspad.scenes.content_hash`).
    With ``spec``: additionally the dataset seed, every sensor's resolved parameters and the evaluation rate
    (the ground-truth rate), i.e. what a recording of the sequence depends on apart from its lux level.
    """
    d = seq.to_dict()
    d.pop("name")
    info = resolve_scene(seq.scene)
    d["scene"] = {"name": info.name, "content": content_hash(info)}
    trajectory = seq.trajectory if seq.trajectory is not None else info.default_trajectory
    d["trajectory"] = None if trajectory is None else file_sha256(trajectory)
    if spec is not None:
        d["dataset"] = {"seed": spec.seed, "sensors": {k: s.to_dict() for k, s in spec.sensors.items()},
                        "gt_rate_hz": spec.evaluation.rate_hz}
    return spec_hash(d)

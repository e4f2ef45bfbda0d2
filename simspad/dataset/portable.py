"""What a recording stores about where its inputs came from, independent of the checkout's absolute path.

A spec names its trajectory and user scene by path; :mod:`simspad.dataset.spec_validation` resolves them to
absolute paths. Stored as such in each recording (its ``spec`` and ``trajectory`` attrs), they would make the
file's bytes depend on where the repository or the spec folder lives. Stored relative to the spec's folder,
the same spec generates the same bytes from any checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

from simspad.scenes.library import resolve_scene


def portable_path(path: str | Path | None, base: Path | None) -> str | None:
    """``path`` relative to ``base`` (POSIX, possibly with ``..``) when both are absolute; otherwise as given."""
    if path is None:
        return None
    p = Path(path)
    if base is None or not p.is_absolute():
        return str(path)
    return Path(os.path.relpath(p, base)).as_posix()


def portable_sequence(seq, source_path: Path | None) -> dict:
    """``seq.to_dict()`` with its scene (a user's folder) and trajectory paths relative to the spec's folder."""
    base = Path(source_path).parent if source_path is not None else None
    d = seq.to_dict()
    d["trajectory"] = portable_path(seq.trajectory, base)
    if Path(seq.scene).is_absolute():
        d["scene"] = portable_path(seq.scene, base)
    return d


def portable_trajectory(seq, source_path: Path | None) -> str:
    """The trajectory the render used (the sequence's own or its scene's default), relative to the spec folder."""
    base = Path(source_path).parent if source_path is not None else None
    trajectory = seq.trajectory if seq.trajectory is not None else resolve_scene(seq.scene).default_trajectory
    return portable_path(trajectory, base) or ""

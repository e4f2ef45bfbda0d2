"""What a recording stores about where its inputs came from, independent of the checkout's absolute path.

A spec names its trajectory and user scene by path; :mod:`simspad.dataset.spec_validation` resolves them to
absolute paths. Stored as such in each recording (its ``spec`` and ``trajectory`` attrs), they would make the
file's bytes depend on where the repository or the spec folder lives. Stored relative to the spec's folder (the
user's files) or to the bundled specs' folder (SimSPAD's bundled trajectories), the same spec generates the same
bytes from any checkout and from any folder it is copied to.
"""

from __future__ import annotations

import os
from pathlib import Path

from simspad.bundled import DATASETS_DIR, bundled_relative
from simspad.scenes.library import resolve_scene


def portable_path(path: str | Path | None, base: Path | None) -> str | None:
    """``path`` relative to ``base`` (POSIX, possibly with ``..``) when both are absolute; otherwise as given.

    A file of SimSPAD's bundled data (a bundled trajectory, found when the spec's folder has no file of that
    name) is stored relative to the bundled specs' folder instead, as the bundled specs themselves name it
    (``../trajectories/<file>``): the same string wherever the spec sits, and the very bytes that the bundled
    specs' recordings always had.
    """
    if path is None:
        return None
    p = Path(path)
    if not p.is_absolute():
        return str(path)
    if bundled_relative(p) is not None:
        return Path(os.path.relpath(p.resolve(), DATASETS_DIR.resolve())).as_posix()
    if base is None:
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

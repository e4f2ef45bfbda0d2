"""Keyframe files of a render directory as the renderer keeps them: cache-keyed names, EXR writes, clean-up.

Each keyframe is one EXR (R, G, B, Z) written atomically, named ``frames/<index>-<key>.exr`` where the key
hashes everything that determines its pixels (renderer version, Mitsuba version and variant, scene content,
trajectory, size, spp, seed, sampler, PSF) and the instant. So a re-run re-uses frames, an interrupted render
resumes, and frames of an earlier render with other settings are recognised as stale. ``timeline.json``
(:mod:`simspad.io.render_dir`) is written last.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from simspad.errors import SimSpadError
from simspad.io.exr import OBJECT_ID_CHANNEL, read_exr, write_exr


def make_out_dir(out_dir: Path) -> list[Path]:
    """Create ``out_dir`` (and ``frames/``) now, so an unwritable output fails before any work; return what was
    created so it can be removed again if a later check fails."""
    created = []
    for d in reversed([out_dir / "frames", out_dir, *out_dir.parents]):
        if d.exists():
            if not d.is_dir():
                raise SimSpadError(f"{d} is a file, not a directory", path=out_dir, field="out")
            continue
        try:
            d.mkdir()
        except FileExistsError:  # another process (a chunk of the same render) created it since the check
            if d.is_dir():
                continue
            remove_created(created)
            raise SimSpadError(f"{d} is a file, not a directory", path=out_dir, field="out") from None
        except OSError as exc:
            remove_created(created)
            raise SimSpadError(f"cannot create the output directory ({exc.strerror})", path=out_dir,
                               field="out") from None
        created.append(d)
    if not os.access(out_dir / "frames", os.W_OK | os.X_OK):
        remove_created(created)
        raise SimSpadError("output directory is not writable", path=out_dir, field="out")
    return created


def remove_created(created: list[Path]) -> None:
    """Remove the directories :func:`make_out_dir` created (deepest first), leaving any that are not empty."""
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            pass


def frame_key(base: dict, t: float) -> str:
    """16 hex digits of SHA-256 over the cache-key fields ``base`` and the instant ``t`` (s)."""
    doc = dict(base, t=repr(float(t)))
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def frame_names(base: dict, times: np.ndarray, first_index: int = 0) -> list[str]:
    """Relative paths of the keyframes at ``times`` (s) inside the render directory, numbered from
    ``first_index``."""
    return [f"frames/{i:06d}-{frame_key(base, t)}.exr" for i, t in enumerate(times, start=first_index)]


def write_frame(path: Path, rgb: np.ndarray, depth: np.ndarray, object_id: np.ndarray | None = None) -> None:
    """Write linear radiance ``rgb`` [H, W, 3] and depth ``depth`` [H, W] (m) as channels R, G, B, Z, plus the
    per-pixel object id (:data:`simspad.io.exr.OBJECT_ID_CHANNEL`) when given."""
    channels = {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "Z": depth}
    if object_id is not None:
        channels[OBJECT_ID_CHANNEL] = object_id
    write_exr(path, channels)


def frame_is_intact(path: Path) -> bool:
    """True if the cached keyframe at ``path`` decodes completely (every scanline; ZIP blocks carry checksums),
    holds radiance and depth, and is finite: a truncated or damaged EXR is then re-rendered, not re-used."""
    try:
        data = read_exr(path)
    except Exception:  # noqa: BLE001 - InputError or whatever OpenEXR raises on a damaged file: not intact
        return False
    rgb, depth = data.get("rgb"), data.get("z")
    return (rgb is not None and depth is not None and rgb.shape[:2] == depth.shape
            and bool(np.isfinite(rgb).all()) and bool(np.isfinite(depth).all()))


def remove_stale_frames(out_dir: Path, keep: set[str]) -> None:
    """Delete frames and noise probes of earlier renders into the same directory that the new timeline does not
    reference (``keep``: relative paths, ``frames/…``)."""
    for pattern in ("[0-9][0-9][0-9][0-9][0-9][0-9]-*.exr", "noise-probe-*.exr"):
        for path in (out_dir / "frames").glob(pattern):
            if f"frames/{path.name}" not in keep:
                path.unlink(missing_ok=True)

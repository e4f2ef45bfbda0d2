"""Conventional-frame captures: a multi-page TIFF stack or a folder of PNG/TIFF images, and their timestamps.

Frames are read one at a time (memory flat in the number of frames) as raw digital numbers, uint16 ``[H, W]``
(mono; a colour image is refused). Exposure windows come from a CSV file with columns ``t_start_s`` and
``t_end_s`` (SimSPAD's ``frames/timestamps.csv``; an ``index`` column and others are ignored), one row per
frame in order, or from a frame rate and an exposure time (frame k exposed over
``[t_start_s + k/frame_rate_hz, … + exposure_s)``).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Iterator

import numpy as np
import tifffile

from simspad.errors import InputError

#: Image suffixes of a frame folder, sorted by name.
FOLDER_SUFFIXES = (".png", ".tif", ".tiff")


class FrameStack:
    """An opened frame capture: ``n_frames``, ``shape`` (H, W) and :meth:`frames`."""

    def __init__(self, fmt: str, path: Path):
        self.fmt, self.path = fmt, Path(path)
        if fmt == "png":
            self.files = sorted(p for p in self.path.iterdir() if p.suffix.lower() in FOLDER_SUFFIXES)
            if not self.files:
                raise InputError(f"no {', '.join(FOLDER_SUFFIXES)} images in the folder", path=path,
                                 field="frames.path")
            self.n_frames = len(self.files)
            first = self._read_file(self.files[0])
        else:
            try:
                with tifffile.TiffFile(self.path) as tf:
                    self.n_frames = len(tf.pages)
                    first = tf.pages[0].asarray()
            except (OSError, ValueError, tifffile.TiffFileError) as exc:
                raise InputError(f"not a readable TIFF stack ({exc})", path=path, field="frames.path") from None
        self.shape = self._check(first, self.path, 0).shape

    @staticmethod
    def _read_file(p: Path) -> np.ndarray:
        import imageio.v3 as iio  # deferred: only PNG folders need it
        try:
            return iio.imread(p)
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable image ({exc})", path=p) from None

    def _check(self, img: np.ndarray, path: Path, k: int) -> np.ndarray:
        img = np.asarray(img)
        if img.ndim != 2:
            raise InputError(f"frame {k} has shape {img.shape}: expected a mono image [H, W] of raw DN", path=path,
                             field="frames.path")
        if img.dtype.kind not in "ui" or img.dtype.itemsize > 2:
            raise InputError(f"frame {k} is {img.dtype}: expected 8- or 16-bit integer DN", path=path,
                             field="frames.path")
        if hasattr(self, "shape") and img.shape != self.shape:
            raise InputError(f"frame {k} is {img.shape}, the first frame {self.shape}", path=path,
                             field="frames.path")
        return img.astype(np.uint16)

    def frames(self) -> Iterator[np.ndarray]:
        """Every frame in order, uint16 [H, W]."""
        if self.fmt == "png":
            for k, p in enumerate(self.files):
                yield self._check(self._read_file(p), p, k)
            return
        with tifffile.TiffFile(self.path) as tf:
            for k, page in enumerate(tf.pages):
                yield self._check(page.asarray(), self.path, k)


def read_timestamps(path: Path, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """``(t_start_s, t_end_s)`` of ``n_frames`` exposures from a CSV file (see the module docstring)."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"unreadable timestamps file ({exc})", path=path) from None
    for col in ("t_start_s", "t_end_s"):
        if not rows or col not in rows[0]:
            raise InputError("missing column (expected t_start_s, t_end_s)", path=path, field=col)
    if len(rows) != n_frames:
        raise InputError(f"{len(rows)} rows for {n_frames} frames", path=path, field="t_start_s")
    out = []
    for col in ("t_start_s", "t_end_s"):
        try:
            out.append(np.array([float(r[col]) for r in rows], np.float64))
        except (TypeError, ValueError):
            bad = next(i for i, r in enumerate(rows) if not _is_float(r[col]))
            raise InputError(f"row {bad + 1}: expected a number, got {rows[bad][col]!r}", path=path,
                             field=col) from None
    ts, te = out
    if not (np.all(np.isfinite(ts)) and np.all(np.isfinite(te)) and np.all(te > ts)):
        bad = int(np.flatnonzero(~(te > ts))[0]) if np.any(~(te > ts)) else 0
        raise InputError(f"row {bad + 1}: exposure end must be finite and after its start", path=path,
                         field="t_end_s")
    if np.any(np.diff(ts) <= 0):
        bad = int(np.flatnonzero(np.diff(ts) <= 0)[0]) + 1
        raise InputError(f"row {bad + 1}: frames must start in increasing time", path=path, field="t_start_s")
    return ts, te


def _is_float(v) -> bool:
    try:
        float(v)
        return True
    except (TypeError, ValueError):
        return False

"""Saved reconstructions of a results directory: ``reconstructions/<rec>/<method>.h5``.

Layout: ``/t`` [N] float64 s, ``/flux`` [N,H,W] float32 ph s⁻¹ m⁻² (one chunk per frame, byte shuffle + Zstandard:
:data:`simspad.io.compression.FLOAT_FRAMES_STORAGE`; an outside reader imports ``hdf5plugin`` first), root
attributes ``method``, ``recording``, ``units``. Frames are written as the method produces them, a few at a
time (one HDF5 write per run of frames costs less than one per frame; the file's bytes are the same). A write or
close that fails on a full disk keeps the sink alive (:func:`simspad.io.recording.writer.keep_after_disk_full`):
freeing its HDF5 objects would crash the process.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from simspad.io.atomic import is_disk_full
from simspad.io.compression import FLOAT_FRAMES_STORAGE
from simspad.io.recording.writer import keep_after_disk_full

#: Most bytes of frames held before they are written (memory does not grow with the sequence length).
BUFFER_BYTES = 8 * 2**20


class ReconstructionSink:
    """Appends frames to a reconstruction file as they are produced; call :meth:`close` when done.

    Parameters
    ----------
    path : Path
        The file (its directory is created).
    times_s : array of float
        The N instants, s.
    shape : (H, W)
        Frame shape, pixels.
    attrs : dict
        Root attributes.
    """

    def __init__(self, path: Path, times_s: np.ndarray, shape: tuple[int, int], attrs: dict):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.h5 = h5py.File(path, "w")
        try:
            self.h5.create_dataset("t", data=np.asarray(times_s, np.float64), track_times=False)
            self.ds = self.h5.create_dataset("flux", shape=(len(times_s), *shape), dtype=np.float32,
                                             chunks=(1, *shape), track_times=False, **FLOAT_FRAMES_STORAGE)
            for k, v in attrs.items():
                self.h5.attrs[k] = v
        except BaseException as exc:
            self._failed(exc)
            raise
        frame_bytes = max(1, int(np.prod(shape)) * 4)
        self._buffer = np.empty((max(1, min(len(times_s), BUFFER_BYTES // frame_bytes)), *shape), np.float32)
        self._first = 0  # index of the frame in _buffer[0]
        self._held = 0  # frames held in _buffer

    def __call__(self, i: int, img: np.ndarray) -> None:
        """Store frame ``i`` (written with the next frames, at the latest on :meth:`close`)."""
        if self._held and (i != self._first + self._held or self._held == len(self._buffer)):
            self.flush()
        if not self._held:
            self._first = i
        self._buffer[self._held] = img
        self._held += 1

    def flush(self) -> None:
        """Write the frames held."""
        if self._held:
            try:
                self.ds[self._first:self._first + self._held] = self._buffer[:self._held]
            except BaseException as exc:
                self._failed(exc)
                raise
            self._held = 0

    def close(self) -> None:
        try:
            self.flush()
        finally:
            try:
                self.h5.close()
            except BaseException as exc:
                self._failed(exc)
                raise

    def _failed(self, exc: BaseException) -> None:
        """On a full disk, keep the file object alive (freeing it would crash HDF5: see
        :func:`simspad.io.recording.writer.keep_after_disk_full`)."""
        if is_disk_full(exc):
            keep_after_disk_full(self)  # the file and its dataset object

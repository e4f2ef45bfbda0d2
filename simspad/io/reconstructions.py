"""Saved reconstructions of a results directory: ``reconstructions/<rec>/<method>.h5``.

Layout: ``/t`` [N] float64 s, ``/flux`` [N,H,W] float32 ph s⁻¹ m⁻² (one chunk per frame, byte shuffle + Zstandard:
:data:`simspad.io.compression.FLOAT_FRAMES_STORAGE`; an outside reader imports ``hdf5plugin`` first), root
attributes ``method``, ``recording``, ``units``. Frames are written as the method produces them, a few at a
time (one HDF5 write per run of frames costs less than one per frame; the file's bytes are the same). A write or
close that fails on a full disk keeps the sink alive (:func:`simspad.io.recording.writer.keep_after_disk_full`):
freeing its HDF5 objects would crash the process.

:func:`open_reconstruction` reads one back, validated like every input (attributes are strings, ``/t`` finite
and increasing, ``/flux`` float32 ``[N, H, W]``, finite and ≥ 0, checked a few frames at a time): a damaged or
foreign file is one :class:`~simspad.errors.InputError` naming the file, the dataset and the first bad index.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

from simspad import defaults
from simspad.errors import InputError
from simspad.io.atomic import is_disk_full
from simspad.io.compression import FLOAT_FRAMES_STORAGE
from simspad.io.hdf5 import decode_attr
from simspad.io.recording.writer import keep_after_disk_full
from simspad.io.safe_paths import refuse_hdf5_links

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


#: Root attributes of a reconstruction file, all strings.
ATTRS = ("method", "recording", "units")


class SavedReconstruction:
    """A reconstruction file read back (open it with :func:`open_reconstruction`; use as a context manager).

    Attributes
    ----------
    path : Path
    method, recording, units : str
        The root attributes.
    t : ndarray [N] float64
        The instants, s.
    shape : (H, W)
        Frame shape, pixels.
    """

    def __init__(self, path: Path, h5: h5py.File, attrs: dict, t: np.ndarray):
        self.path = path
        self._h5 = h5
        self.method, self.recording, self.units = (attrs[k] for k in ATTRS)
        self.t = t
        self.shape = tuple(h5["flux"].shape[1:])

    def frames(self, chunk: int = 8) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_index, flux[n, H, W])`` blocks of ``chunk`` frames (ph s⁻¹ m⁻²)."""
        ds = self._h5["flux"]
        for i in range(0, ds.shape[0], chunk):
            yield i, _read(ds, np.s_[i:i + chunk], "/flux", self.path)

    def close(self) -> None:
        self._h5.close()

    def __enter__(self) -> "SavedReconstruction":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _read(ds, selection, field: str, path: Path) -> np.ndarray:
    try:
        return ds[selection]
    except Exception as exc:  # noqa: BLE001 - the library's own errors for damaged data or a missing filter
        raise InputError(f"unreadable ({str(exc)[:100]})", path=path, field=field) from None


def open_reconstruction(path: str | Path) -> SavedReconstruction:
    """Open and validate a reconstruction file of a results directory.

    Raises
    ------
    InputError
        Missing, not HDF5, a link inside, an attribute missing or not a string, ``/t`` or ``/flux`` missing, of
        another dtype or shape, or holding a value out of range; the message names the file, the field and the
        first bad index.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such reconstruction file", path=path)
    try:
        h5 = h5py.File(path, "r")
    except OSError:
        raise InputError("not a readable HDF5 file (corrupt or truncated?)", path=path) from None
    try:
        refuse_hdf5_links(h5, path)
        attrs = {}
        for key in ATTRS:
            try:
                value = decode_attr(h5.attrs[key]) if key in h5.attrs else None
            except Exception:  # noqa: BLE001 - an attribute type h5py cannot read
                value = None
            if not isinstance(value, str):
                raise InputError(f"expected a string attribute, got {str(value)[:40]!r}", path=path,
                                 field=f"/.{key}")
            attrs[key] = value
        for name, dtype, rank in (("t", "float64", 1), ("flux", "float32", 3)):
            if not isinstance(h5.get(name), h5py.Dataset):
                raise InputError("dataset missing", path=path, field=f"/{name}")
            ds = h5[name]
            if ds.dtype != np.dtype(dtype) or ds.ndim != rank:
                raise InputError(f"dtype {ds.dtype.str}, shape {ds.shape}: expected {dtype} with {rank} "
                                 "dimension(s)", path=path, field=f"/{name}")
        n, H, W = h5["flux"].shape
        if h5["t"].shape[0] != n:
            raise InputError(f"{n} frames but {h5['t'].shape[0]} instants", path=path, field="/flux")
        if H * W > defaults.MAX_RENDER_PIXELS or n > defaults.MAX_SAMPLES_PER_RECORDING:
            raise InputError(f"{n} frames of {W} × {H} pixels, above the limits", path=path, field="/flux")
        t = _read(h5["t"], (), "/t", path)
        bad_t = ~np.isfinite(t) | (t <= np.concatenate(([-np.inf], t[:-1])))
        if bad_t.any():
            i = int(np.argmax(bad_t))
            raise InputError(f"index {i}: {t[i].item()!r} s, expected finite instants, increasing", path=path,
                             field="/t")
        rec = SavedReconstruction(path, h5, attrs, t)
        for i, block in rec.frames():
            bad = ~(np.isfinite(block) & (block >= 0))
            if bad.any():
                k, r, c = (int(v) for v in np.argwhere(bad)[0])
                raise InputError(f"flux {block[k, r, c].item()!r} at pixel (row {r}, col {c}) of frame {i + k} "
                                 "(expected finite values ≥ 0)", path=path, field="/flux")
    except BaseException:
        h5.close()
        raise
    return rec

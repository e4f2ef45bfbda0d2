"""Writing a recording (docs/format.md) atomically, with bytes that depend only on the data.

:class:`RecordingWriter` writes a temporary sibling and renames it only when the ``with`` block completes, so a
reader never sees a half-written file. Object modification times are not stored, so identical data and attrs give
bit-identical files (the dataset manifest compares sha256). :class:`Appender` grows a dataset one whole HDF5 chunk
at a time, so the byte layout does not depend on how the simulator batches its rows either.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path

import h5py
import numpy as np

from simspad.io.atomic import (
    check_output_path,
    disk_full_error,
    ensure_writable_dir,
    fsync_file,
    is_disk_full,
    remove_stale_temporaries,
    temporary_sibling,
)
from simspad.io.recording.layout import FORMAT, FORMAT_VERSION

#: HDF5 library version bounds of the file (fixed: the byte layout depends on them).
_LIBVER = ("v110", "v110")
#: Set when closing an HDF5 file failed (full disk): the library keeps a half-closed file that it tries to close
#: again at process exit, where it crashes (SIGSEGV). :func:`hdf5_close_failed` lets the CLI exit without that.
_CLOSE_FAILED = False


def hdf5_close_failed() -> bool:
    """True once an HDF5 close failed in this process (the process should then end with ``os._exit``)."""
    return _CLOSE_FAILED


def _attr_value(value):
    """Convert a Python value to something h5py stores faithfully (dicts and lists of str become JSON)."""
    if value is None:
        return "none"
    if isinstance(value, dict):
        return json.dumps(value, sort_keys=True, default=str)
    if isinstance(value, (list, tuple)):
        if all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) for v in value) and value:
            return np.asarray(value)
        return json.dumps(list(value), default=str)
    if isinstance(value, Path):
        return str(value)
    return value


def _mark_close_failed() -> None:
    global _CLOSE_FAILED
    _CLOSE_FAILED = True


#: HDF5 files whose write or close failed on a full disk, kept alive: freeing one makes HDF5 retry its close,
#: which crashes the process (SIGSEGV) in the middle of its work instead of at an exit the CLI skips.
_FAILED_FILES: list = []


def keep_after_disk_full(obj) -> None:
    """For any writer of HDF5 files (exporters, saved reconstructions): after a write or close failed on a full
    disk, keep ``obj`` (the h5py file, or an object holding it and its datasets) alive and mark the process
    (:func:`hdf5_close_failed`), so that it ends with one line rather than a crash."""
    _FAILED_FILES.append(obj)
    _install_quiet_dealloc_hook()
    _mark_close_failed()


def _install_quiet_dealloc_hook() -> None:
    """Drop h5py's "Exception ignored in ObjectID.__dealloc__" tracebacks caused by a full disk: each failed write
    frees temporary HDF5 objects whose release fails again; the writer reports the full disk once, as one line.
    Every other unraisable exception passes to the previous hook."""
    previous = sys.unraisablehook
    if getattr(previous, "_simspad_quiet_dealloc", False):
        return

    def hook(unraisable):
        exc = unraisable.exc_value
        if isinstance(exc, RuntimeError) and "id ref count" in str(exc) and is_disk_full(exc):
            return
        previous(unraisable)

    hook._simspad_quiet_dealloc = True
    sys.unraisablehook = hook


class Appender:
    """A resizable dataset grown along axis 0 by :meth:`append`.

    Rows are buffered and written one whole HDF5 chunk per resize, so the sequence of HDF5 operations (and with
    it the file's byte layout) depends only on the rows appended, never on how callers batch them: the same
    data gives the same bytes whatever the chunking, thread count or executor of the simulator.

    ``create(chunk_rows)`` makes the dataset ``name``. A growable one is made when its first whole chunk is
    written, or at :meth:`flush` with one chunk exactly as long as its rows if fewer came: HDF5 stores an
    unfiltered chunk whole, so a few hundred events in chunks of 65 536 rows took ≈ 0.9 MiB of zeros (21 % of the
    mini dataset's bytes). A presized one (``n_rows`` known) is made at once, its chunks no longer than itself.
    """

    def __init__(self, name: str, create, chunk_rows: int, tail_shape: tuple, dtype, presized: bool):
        self.name = name
        self._create = create
        self.chunk_rows = int(chunk_rows)
        self.tail_shape = tuple(tail_shape)
        self.dtype = np.dtype(dtype)
        # A dataset created at its final, fixed length (the caller knew it) is filled in place: no resize per chunk
        self._presized = presized
        self.dataset = None
        if presized:
            self._open(self.chunk_rows)
        self.n = 0
        self._written = 0
        self._pending: list[np.ndarray] = []
        self._pending_rows = 0

    def _open(self, rows: int) -> h5py.Dataset:
        """The dataset, created now with chunks of at most ``rows`` rows if it does not exist yet."""
        if self.dataset is None:
            self.dataset = self._create(max(1, min(self.chunk_rows, rows)))
            self.chunk_rows = int(self.dataset.chunks[0])
            # A whole chunk of an unfiltered numeric dataset goes to the file as it is (H5Dwrite_chunk): half the
            # CPU time of a selection write, same bytes in the same place.
            self._direct = self.dtype.kind in "biuf" and self.dataset.id.get_create_plist().get_nfilters() == 0
        return self.dataset

    def append(self, data) -> None:
        """Append rows (``data.shape[1:]`` must equal the dataset's tail shape)."""
        data = np.asarray(data, dtype=self.dtype)
        if data.shape[1:] != self.tail_shape:
            raise ValueError(f"{self.name}: rows of shape {data.shape[1:]}, expected {self.tail_shape}")
        if data.shape[0] == 0:
            return
        if self._presized and self.n + data.shape[0] > self.dataset.shape[0]:
            raise ValueError(f"{self.name}: {self.n + data.shape[0]} rows appended to a dataset created "
                             f"with {self.dataset.shape[0]}")
        self._pending.append(data)
        self._pending_rows += data.shape[0]
        self.n += data.shape[0]
        if self._pending_rows >= self.chunk_rows:
            self._write(final=False)
        else:
            self._pending[-1] = data.copy()  # kept past this call (less than a chunk): the caller may reuse its buffer

    def flush(self) -> None:
        """Write every buffered row (called by :class:`RecordingWriter` before closing)."""
        self._open(self._pending_rows)
        self._write(final=True)
        if self._presized and self._written != self.dataset.shape[0]:
            raise ValueError(f"{self.name}: {self._written} rows appended to a dataset created with "
                             f"{self.dataset.shape[0]}")

    def _write(self, final: bool) -> None:
        if not self._pending:
            return
        rows = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
        dataset = self._open(rows.shape[0])
        step = self.chunk_rows
        full = (rows.shape[0] // step) * step
        end = rows.shape[0] if final else full
        for i in range(0, end, step):
            block = rows[i : min(i + step, end)]
            if not self._presized:
                dataset.resize(self._written + block.shape[0], axis=0)
            if self._direct and block.shape[0] == step:
                dataset.id.write_direct_chunk((self._written,) + (0,) * (rows.ndim - 1), np.ascontiguousarray(block))
            else:
                dataset[self._written : self._written + block.shape[0]] = block
            self._written += block.shape[0]
        rest = rows[end:].copy()  # less than a chunk, kept: a copy, so callers may reuse their buffers
        self._pending = [rest] if rest.shape[0] else []
        self._pending_rows = rest.shape[0]


class RecordingWriter:
    """Write a recording atomically.

    Parameters
    ----------
    path : str or Path
        Final file name (``.h5``). Nothing exists there until the ``with`` block completes.
    attrs : dict
        Root attributes; ``format`` and ``format_version`` are added.

    Examples
    --------
    >>> with RecordingWriter("rec.h5", {"lux": 10.0}) as w:               # doctest: +SKIP
    ...     bits = w.append_dataset("spad/bits", (H, (W + 7) // 8), np.uint8, chunk_rows=256)
    ...     bits.append(chunk)
    """

    def __init__(self, path: str | Path, attrs: dict | None = None):
        self.path = Path(path)
        self.attrs = dict(attrs or {})
        self.tmp_path: Path | None = None
        self.h5: h5py.File | None = None
        self._appenders: list[Appender] = []

    def __enter__(self) -> "RecordingWriter":
        check_output_path(self.path, kind="file")
        ensure_writable_dir(self.path.parent)
        remove_stale_temporaries(self.path)
        _install_quiet_dealloc_hook()
        self.tmp_path = temporary_sibling(self.path)
        try:
            # No chunk cache: HDF5 then allocates each chunk's file space when it is written, in write order. With
            # the default 1 MiB cache a chunk is placed when it is evicted or its dataset closed, which depends on
            # object lifetimes in the process, so the same data could get a different byte layout on a Dask worker
            # than in a local pool worker. (The writers write whole chunks, so the cache saved nothing.)
            self.h5 = h5py.File(self.tmp_path, "w", libver=_LIBVER, rdcc_nbytes=0)
            self.set_attrs("/", format=FORMAT, format_version=FORMAT_VERSION, **self.attrs)
        except BaseException as exc:
            self._discard()
            if is_disk_full(exc):
                raise disk_full_error(self.path) from None
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        # The file gets its final name only after every row is written, the HDF5 file closed and its bytes
        # fsynced, all without error; on any failure the temporary is removed (a full disk: one line naming it).
        failure = exc
        try:
            if failure is None:
                for appender in self._appenders:
                    appender.flush()
        except BaseException as e:
            failure = e
        self._appenders = []
        if failure is not None and is_disk_full(failure):
            _mark_close_failed()  # before h5py frees this file's objects, which fail again on the full disk
        try:
            try:
                self.h5.close()
            except BaseException:
                _mark_close_failed()
                raise
            self.h5 = None
            if failure is None:
                fsync_file(self.tmp_path)
                check_output_path(self.path, kind="file")
                os.replace(self.tmp_path, self.path)
                return
        except BaseException as e:
            failure = failure or e
        self._discard()
        if is_disk_full(failure):
            raise disk_full_error(self.path) from None
        if failure is not exc:
            raise failure

    def _discard(self) -> None:
        """Close (best effort) and delete the temporary file."""
        if self.h5 is not None:
            try:
                self.h5.close()
            except Exception:  # noqa: BLE001 - closing a file whose write failed may fail again; it is deleted
                _mark_close_failed()
        if self.tmp_path is not None:
            with contextlib.suppress(OSError):
                os.truncate(self.tmp_path, 0)  # HDF5 may still hold it open: free its blocks now
            self.tmp_path.unlink(missing_ok=True)

    def set_attrs(self, group: str, **attrs) -> None:
        """Set attributes on ``group`` (created if needed); dicts are stored as JSON text."""
        obj = self.h5.require_group(group) if group != "/" else self.h5
        for key, value in attrs.items():
            obj.attrs[key] = _attr_value(value)

    def write_dataset(self, name: str, data, attrs: dict | None = None, *, chunks=None) -> h5py.Dataset:
        """Write a whole (small) dataset."""
        data = np.asarray(data)
        ds = self.h5.create_dataset(name, data=data, chunks=chunks, track_times=False)
        for key, value in (attrs or {}).items():
            ds.attrs[key] = _attr_value(value)
        return ds

    def append_dataset(self, name: str, tail_shape: tuple, dtype, chunk_rows: int,
                       attrs: dict | None = None, n_rows: int | None = None,
                       storage: dict | None = None) -> Appender:
        """A dataset of shape ``(0, *tail_shape)`` growable along axis 0, chunked ``chunk_rows`` rows (fewer when it
        ends shorter than a chunk: it is created once its first chunk is full, or when the writer closes).

        With ``n_rows`` (the final length, when the caller knows it) the dataset is created at that length and
        filled in place (no resize per chunk); exactly ``n_rows`` rows must then be appended. ``storage``: the
        ``create_dataset`` keyword arguments of a filter (:data:`simspad.io.compression.SPAD_COMPRESSIONS`);
        unfiltered without.
        """
        tail_shape = tuple(int(s) for s in tail_shape)
        chunk_rows = max(1, int(chunk_rows))
        if n_rows:  # fixed length; an empty dataset stays growable (HDF5 has no 0-row chunks)
            rows, max_rows, chunk_rows = int(n_rows), int(n_rows), min(chunk_rows, int(n_rows))  # chunk ≤ length
        else:
            rows, max_rows = 0, None

        def create(chunks: int) -> h5py.Dataset:
            ds = self.h5.create_dataset(name, shape=(rows, *tail_shape), maxshape=(max_rows, *tail_shape),
                                        dtype=dtype, chunks=(chunks, *tail_shape), track_times=False,
                                        **(storage or {}))
            for key, value in (attrs or {}).items():
                ds.attrs[key] = _attr_value(value)
            return ds

        appender = Appender(name, create, chunk_rows, tail_shape, dtype, presized=n_rows is not None)
        self._appenders.append(appender)
        return appender

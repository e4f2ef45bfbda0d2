"""Writing a recording (DESIGN §5) atomically, with bytes that depend only on the data.

:class:`RecordingWriter` writes a temporary sibling and renames it only when the ``with`` block completes, so a
reader never sees a half-written file. Object modification times are not stored, so identical data and attrs give
bit-identical files (the dataset manifest compares sha256). :class:`Appender` grows a dataset one whole HDF5 chunk
at a time, so the byte layout does not depend on how the simulator batches its rows either.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from simspad.io.atomic import ensure_writable_dir, temporary_sibling
from simspad.io.recording.layout import FORMAT, FORMAT_VERSION

#: HDF5 library version bounds of the file (fixed: the byte layout depends on them).
_LIBVER = ("v110", "v110")


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


class Appender:
    """A resizable dataset grown along axis 0 by :meth:`append`.

    Rows are buffered and written one whole HDF5 chunk per resize, so the sequence of HDF5 operations (and with
    it the file's byte layout) depends only on the rows appended, never on how callers batch them: the same
    data gives the same bytes whatever the chunking, thread count or executor of the simulator.
    """

    def __init__(self, dataset: h5py.Dataset):
        self.dataset = dataset
        self.chunk_rows = int(dataset.chunks[0])
        self.n = dataset.shape[0]
        self._written = self.n
        self._pending: list[np.ndarray] = []
        self._pending_rows = 0

    def append(self, data) -> None:
        """Append rows (``data.shape[1:]`` must equal the dataset's tail shape)."""
        data = np.asarray(data, dtype=self.dataset.dtype)
        if data.shape[1:] != self.dataset.shape[1:]:
            raise ValueError(f"{self.dataset.name}: rows of shape {data.shape[1:]}, expected {self.dataset.shape[1:]}")
        if data.shape[0] == 0:
            return
        self._pending.append(data)
        self._pending_rows += data.shape[0]
        self.n += data.shape[0]
        if self._pending_rows >= self.chunk_rows:
            self._write(final=False)

    def flush(self) -> None:
        """Write every buffered row (called by :class:`RecordingWriter` before closing)."""
        self._write(final=True)

    def _write(self, final: bool) -> None:
        if not self._pending:
            return
        rows = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
        step = self.chunk_rows
        full = (rows.shape[0] // step) * step
        end = rows.shape[0] if final else full
        for i in range(0, end, step):
            block = rows[i : min(i + step, end)]
            self.dataset.resize(self._written + block.shape[0], axis=0)
            self.dataset[self._written : self._written + block.shape[0]] = block
            self._written += block.shape[0]
        rest = rows[end:]
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
        ensure_writable_dir(self.path.parent)
        self.tmp_path = temporary_sibling(self.path)
        self.h5 = h5py.File(self.tmp_path, "w", libver=_LIBVER)
        self.set_attrs("/", format=FORMAT, format_version=FORMAT_VERSION, **self.attrs)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                for appender in self._appenders:
                    appender.flush()
        finally:
            self._close(exc_type)

    def _close(self, exc_type) -> None:
        try:
            self.h5.close()
        finally:
            if exc_type is None:
                os.replace(self.tmp_path, self.path)
            else:
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
                       attrs: dict | None = None, compression: str | None = None) -> Appender:
        """Create a dataset of shape ``(0, *tail_shape)`` growable along axis 0, chunked ``chunk_rows`` rows."""
        tail_shape = tuple(int(s) for s in tail_shape)
        ds = self.h5.create_dataset(name, shape=(0, *tail_shape), maxshape=(None, *tail_shape), dtype=dtype,
                                    chunks=(max(1, int(chunk_rows)), *tail_shape), compression=compression,
                                    track_times=False)
        for key, value in (attrs or {}).items():
            ds.attrs[key] = _attr_value(value)
        appender = Appender(ds)
        self._appenders.append(appender)
        return appender

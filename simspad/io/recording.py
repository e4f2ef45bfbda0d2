"""The recording file (DESIGN §5): one HDF5 file per sequence × lux.

Writing goes through :class:`RecordingWriter`, which writes a temporary sibling and renames it only when the
``with`` block completes, so a reader never sees a half-written file. Object modification times are not
stored, so identical data and attrs give bit-identical files (the dataset manifest compares sha256).

Reading goes through :func:`open_recording`, which refuses missing, corrupt or foreign files with one clear
message naming the file and the field. Methods read recordings only through :class:`Recording`, so they run
unchanged on real captures converted to this layout.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import ensure_writable_dir, temporary_sibling

FORMAT = "simspad-recording"
FORMAT_VERSION = 1
#: The sensor kinds, in the order their groups are listed; every layer takes the names from here.
SENSOR_KINDS = ("spad", "frames", "events")
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


def _decode(value):
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


class Recording:
    """Read access to a recording; open it with :func:`open_recording`.

    All arrays are read lazily; the bulk streams (SPAD bits, events) are read in chunks.
    """

    def __init__(self, path: Path, h5: h5py.File):
        self.path = path
        self.h5 = h5
        self.attrs = {k: _decode(v) for k, v in h5.attrs.items()}
        self._events_index = None

    # -- basics -------------------------------------------------------------------------------------------
    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.h5.close()

    def has(self, kind: str) -> bool:
        """Whether the group ``kind`` ("gt", "spad", "frames", "events", "poses") is present."""
        return kind in self.h5

    @property
    def sensors(self) -> tuple[str, ...]:
        return tuple(k for k in SENSOR_KINDS if k in self.h5)

    @property
    def width(self) -> int:
        return int(self.attrs["width"])

    @property
    def height(self) -> int:
        return int(self.attrs["height"])

    @property
    def duration_s(self) -> float:
        return float(self.attrs["duration_s"])

    @property
    def lux(self) -> float:
        return float(self.attrs["lux"])

    @property
    def scene(self) -> str:
        return str(self.attrs.get("scene", ""))

    @property
    def sequence(self) -> str:
        return str(self.attrs.get("sequence", self.scene))

    @property
    def spec(self) -> dict:
        try:
            return json.loads(self.attrs.get("spec", "{}"))
        except (TypeError, json.JSONDecodeError):
            return {}

    def group_attrs(self, group: str) -> dict:
        """Attributes of ``group`` as plain Python values (JSON text left as text)."""
        return {k: _decode(v) for k, v in self.h5[group].attrs.items()}

    def _dataset(self, name: str) -> h5py.Dataset:
        try:
            return self.h5[name]
        except KeyError:
            raise InputError("dataset missing from the recording", path=self.path, field=name) from None

    # -- ground truth and poses ------------------------------------------------------------------------
    @property
    def gt_t(self) -> np.ndarray:
        """Ground-truth instants, s."""
        return self._dataset("gt/t")[()]

    def gt_flux(self, index=slice(None)) -> np.ndarray:
        """Sharp photon irradiance at the sensor plane, photons s⁻¹ m⁻² (``[H,W]`` or ``[n,H,W]``)."""
        return self._dataset("gt/flux")[index]

    def gt_depth(self, index=slice(None)) -> np.ndarray | None:
        return self.h5["gt/depth"][index] if "gt/depth" in self.h5 else None

    @property
    def poses_t(self) -> np.ndarray | None:
        return self.h5["poses/t"][()] if "poses/t" in self.h5 else None

    @property
    def poses_camera_to_world(self) -> np.ndarray | None:
        return self.h5["poses/camera_to_world"][()] if "poses/camera_to_world" in self.h5 else None

    # -- SPAD ------------------------------------------------------------------------------------------------
    @property
    def spad_attrs(self) -> dict:
        return self.group_attrs("spad")

    @property
    def spad_t_start(self) -> np.ndarray:
        """Start time of every binary frame, s."""
        return self._dataset("spad/t_start")[()]

    @property
    def spad_n_bins(self) -> int:
        return int(self._dataset("spad/bits").shape[0])

    @property
    def dcr_cps(self) -> np.ndarray:
        """Dark count rate map, counts s⁻¹."""
        return self._dataset("spad/dcr_cps")[()]

    def spad_bits(self, start: int, stop: int) -> np.ndarray:
        """Binary frames ``start:stop`` unpacked to ``[n,H,W]`` uint8 (0/1)."""
        packed = self._dataset("spad/bits")[start:stop]
        return np.unpackbits(packed, axis=2, count=self.width, bitorder="little")

    def iter_spad_bits(self, start: int = 0, stop: int | None = None, chunk: int = 1024) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_index, bits[n,H,W])`` over ``start:stop`` in chunks of ``chunk`` frames."""
        stop = self.spad_n_bins if stop is None else min(stop, self.spad_n_bins)
        for i in range(start, stop, chunk):
            yield i, self.spad_bits(i, min(i + chunk, stop))

    def spad_counts(self, start: int, stop: int, chunk: int = 1024) -> np.ndarray:
        """Number of ones per pixel over binary frames ``start:stop`` (``[H,W]`` int32), read in chunks."""
        total = np.zeros((self.height, self.width), np.int32)
        for _, bits in self.iter_spad_bits(start, stop, chunk):
            total += bits.sum(axis=0, dtype=np.int32)
        return total

    # -- frames ---------------------------------------------------------------------------------------------
    @property
    def frames_attrs(self) -> dict:
        return self.group_attrs("frames")

    @property
    def frames_t_start(self) -> np.ndarray:
        return self._dataset("frames/t_start")[()]

    @property
    def frames_t_end(self) -> np.ndarray:
        return self._dataset("frames/t_end")[()]

    @property
    def n_frames(self) -> int:
        return int(self._dataset("frames/dn").shape[0])

    def frames_dn(self, index=slice(None)) -> np.ndarray:
        """Raw frames in DN (uint16), ``[H,W]`` or ``[n,H,W]``."""
        return self._dataset("frames/dn")[index]

    # -- events ----------------------------------------------------------------------------------------------
    @property
    def events_attrs(self) -> dict:
        return self.group_attrs("events")

    @property
    def n_events(self) -> int:
        return int(self._dataset("events/t").shape[0])

    @property
    def ms_to_idx(self) -> np.ndarray:
        if self._events_index is None:
            self._events_index = self._dataset("events/ms_to_idx")[()].astype(np.int64)
        return self._events_index

    def _event_index(self, t_s: float) -> int:
        """Index of the first event with timestamp ≥ ``t_s`` (µs resolution)."""
        t_us = int(np.ceil(round(t_s * 1e6, 6)))
        ms = t_us // 1000
        idx = self.ms_to_idx
        if ms < 0:
            return 0
        if ms >= len(idx) - 1:
            lo, hi = int(idx[-1]) if len(idx) else 0, self.n_events
        else:
            lo, hi = int(idx[ms]), int(idx[ms + 1])
        if lo >= hi:
            return lo
        t = self.h5["events/t"][lo:hi]
        return lo + int(np.searchsorted(t, t_us, side="left"))

    def event_slice(self, t0_s: float, t1_s: float) -> tuple[int, int]:
        """Index range of events with ``t0_s ≤ t < t1_s``."""
        return self._event_index(t0_s), self._event_index(t1_s)

    def events_by_index(self, i0: int, i1: int) -> dict[str, np.ndarray]:
        g = self.h5["events"]
        out = {k: g[k][i0:i1] for k in ("t", "x", "y", "p")}
        out["label"] = g["label"][i0:i1] if "label" in g else np.zeros(i1 - i0, np.uint8)
        return out

    def events(self, t0_s: float, t1_s: float) -> dict[str, np.ndarray]:
        """Events with ``t0_s ≤ t < t1_s``: dict of ``t`` (int64 µs), ``x``, ``y`` (uint16), ``p``, ``label`` (uint8)."""
        return self.events_by_index(*self.event_slice(t0_s, t1_s))

    def iter_events(self, chunk: int = 1 << 20, t0_s: float | None = None,
                    t1_s: float | None = None) -> Iterator[dict[str, np.ndarray]]:
        """Yield events in time order, ``chunk`` at a time, optionally restricted to ``[t0_s, t1_s)``."""
        i0 = 0 if t0_s is None else self._event_index(t0_s)
        i1 = self.n_events if t1_s is None else self._event_index(t1_s)
        for i in range(i0, i1, chunk):
            yield self.events_by_index(i, min(i + chunk, i1))


_REQUIRED_ROOT = ("width", "height", "duration_s", "lux")
_REQUIRED = {
    "gt": ("gt/t", "gt/flux"),
    "spad": ("spad/bits", "spad/t_start", "spad/dcr_cps"),
    "frames": ("frames/dn", "frames/t_start", "frames/t_end"),
    "events": ("events/t", "events/x", "events/y", "events/p", "events/ms_to_idx"),
}
_SPAD_ATTRS = ("bin_s", "gate_s", "pixel_pitch_m", "fill_factor", "qe")
_FRAME_ATTRS = ("gain_dn_per_e", "black_level_dn", "bit_depth", "qe", "pixel_pitch_m", "fill_factor")
_EVENT_ATTRS = ("threshold_on", "threshold_off")


def open_recording(path: str | Path) -> Recording:
    """Open and validate a recording.

    Raises
    ------
    InputError
        Missing file, not HDF5 (corrupt or truncated), a foreign HDF5 (``format`` attr), an unsupported
        version, or a missing dataset/attribute; the message names the file and the field.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such recording file", path=path)
    try:
        h5 = h5py.File(path, "r")
    except OSError:
        raise InputError("not a readable HDF5 file (corrupt or truncated?)", path=path) from None
    try:
        fmt = _decode(h5.attrs.get("format"))
        if fmt != FORMAT:
            raise InputError(f"not a SimSPAD recording (format attr is {fmt!r}, expected {FORMAT!r})",
                             path=path, field="/.format")
        version = _decode(h5.attrs.get("format_version"))
        if version != FORMAT_VERSION:
            raise InputError(f"unsupported format_version {version!r} (this SimSPAD reads {FORMAT_VERSION})",
                             path=path, field="/.format_version")
        for key in _REQUIRED_ROOT:
            if key not in h5.attrs:
                raise InputError("missing root attribute", path=path, field=f"/.{key}")
        H, W = int(h5.attrs["height"]), int(h5.attrs["width"])
        for group, names in _REQUIRED.items():
            if group not in h5:
                continue
            for name in names:
                if name not in h5:
                    raise InputError("dataset missing", path=path, field=f"/{name}")
        for group, keys in (("spad", _SPAD_ATTRS), ("frames", _FRAME_ATTRS), ("events", _EVENT_ATTRS)):
            if group in h5:
                for key in keys:
                    if key not in h5[group].attrs:
                        raise InputError("attribute missing", path=path, field=f"/{group}.{key}")
        checks = [("gt/flux", (H, W), 1), ("spad/bits", (H, (W + 7) // 8), 1), ("frames/dn", (H, W), 1),
                  ("spad/dcr_cps", (H, W), 0)]
        for name, tail, axis0 in checks:
            if name in h5 and tuple(h5[name].shape[axis0:]) != tail:
                raise InputError(f"shape {h5[name].shape} does not match width {W} × height {H}",
                                 path=path, field=f"/{name}")
        if "events" in h5:
            n = h5["events/t"].shape[0]
            for k in ("x", "y", "p"):
                if h5[f"events/{k}"].shape[0] != n:
                    raise InputError(f"length {h5[f'events/{k}'].shape[0]} differs from events/t ({n})",
                                     path=path, field=f"/events/{k}")
    except InputError:
        h5.close()
        raise
    return Recording(path, h5)

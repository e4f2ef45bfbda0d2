"""Event captures read in chunks: Prophesee EVT 3.0 ``.raw``, DSEC ``events.h5``, AEDAT 4 (dv-processing) and
tonic-style structured ``.npy`` arrays.

Every reader is a generator of dicts ``t`` (int64 µs on the capture's own clock), ``x``, ``y`` (int64) and ``p``
(uint8, 1 ON / 0 OFF), ``chunk`` events or so at a time, so memory does not grow with the capture's length. Each
reader also has a ``*_size`` function returning the sensor size the file states (None when it states none).

**EVT 3.0** (Prophesee's public format description): an ASCII header of ``%`` lines closed by ``% end``, then
little-endian 16-bit words whose top 4 bits are the type:

======  =================  =====================================================================
type    name               payload (bits 11…0)
======  =================  =====================================================================
0x0     EVT_ADDR_Y         y (bits 10…0)
0x2     EVT_ADDR_X         polarity (bit 11) and x (bits 10…0): one event at (x, current y)
0x3     VECT_BASE_X        polarity (bit 11) and the base x of the vector words that follow
0x4     VECT_12            12-bit mask: events at base x + i for each set bit i; base x += 12
0x5     VECT_8             8-bit mask (bits 7…0): as VECT_12 for 8 pixels; base x += 8
0x6     EVT_TIME_LOW       timestamp bits 11…0
0x8     EVT_TIME_HIGH      timestamp bits 23…12; a decrease is a wrap of the 24-bit time (+2²⁴ µs)
0xA     EXT_TRIGGER        ignored
0x7/E/F CONTINUED, OTHERS  ignored
======  =================  =====================================================================

The decoder is vectorised over each chunk of words: the last TIME_HIGH, TIME_LOW, ADDR_Y and VECT_BASE_X before
every word are forward-filled, and the state carries over to the next chunk. SimSPAD's own exporter writes the
header line ``% simspad_t_offset_us``; when present it is added to every timestamp.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import h5py
import hdf5plugin  # noqa: F401  (registers the Blosc filter DSEC's own files use)
import numpy as np

from simspad.errors import InputError, SimSpadError

#: Events (or EVT 3.0 words) per chunk.
CHUNK_EVENTS = 1 << 20
_HEADER_MAX_BYTES = 1 << 20


# -- EVT 3.0 ---------------------------------------------------------------------------------------------------

def evt3_header(path: Path) -> tuple[dict, int]:
    """The header of an EVT 3.0 file as ``{key: value}`` (the text after ``%``) and the byte offset of the data."""
    header: dict[str, str] = {}
    with open(path, "rb") as f:
        pos = 0
        while True:
            line = f.readline(_HEADER_MAX_BYTES)
            if not line.startswith(b"%"):
                break
            pos += len(line)
            text = line[1:].decode("ascii", "replace").strip()
            if text == "end":
                break
            key, _, value = text.partition(" ")
            header[key] = value.strip()
    evt = header.get("evt")
    fmt = header.get("format", "")
    if (evt and evt != "3.0") or (fmt and not fmt.upper().startswith("EVT3")):
        raise InputError(f"not an EVT 3.0 file (header says evt {evt!r}, format {fmt!r})", path=path,
                         field="header")
    return header, pos


def evt3_size(path: Path) -> tuple[int, int] | None:
    """Sensor (width, height) from the header's ``geometry WxH`` or ``format …;width=…;height=…`` line."""
    header, _ = evt3_header(path)
    try:
        if "geometry" in header:
            w, h = header["geometry"].lower().split("x")
            return int(w), int(h)
        fields = dict(kv.split("=", 1) for kv in header.get("format", "").split(";")[1:] if "=" in kv)
        if "width" in fields and "height" in fields:
            return int(fields["width"]), int(fields["height"])
    except ValueError:
        raise InputError(f"unreadable sensor size {header.get('geometry') or header.get('format')!r}", path=path,
                         field="header geometry") from None
    return None


class Evt3Decoder:
    """Decodes EVT 3.0 words chunk by chunk, carrying the time, row and vector base across chunks."""

    def __init__(self):
        self.high = -1            # last TIME_HIGH (12 bits); -1: none yet
        self.wraps = 0            # 2²⁴ µs wraps counted so far
        self.low = 0
        self.y = -1
        self.base_x = 0           # vector base x, already advanced past earlier vector words
        self.base_p = 0

    def decode(self, words: np.ndarray) -> dict[str, np.ndarray]:
        """Events encoded by ``words`` (uint16), in file order."""
        w = words.astype(np.int64)
        kind, val = w >> 12, w & 0xFFF
        n = w.size
        idx = np.arange(n)

        def last(mask, values, initial):
            """For each word, ``values`` at the last word (at or before it) where ``mask``; ``initial`` before."""
            pos = np.where(mask, idx, -1)
            np.maximum.accumulate(pos, out=pos)
            ext = np.concatenate(([initial], values))
            return ext[pos + 1] if n else ext[:0]

        is_high = kind == 0x8
        highs = val[is_high]
        prev = np.concatenate(([self.high], highs[:-1]))
        wrap = np.cumsum((highs < prev) & (prev >= 0)) + self.wraps
        unwrapped = np.zeros(n, np.int64)
        unwrapped[is_high] = wrap * (1 << 12) + highs
        high_now = last(is_high, unwrapped, self.wraps * (1 << 12) + max(self.high, 0))
        low_now = last(kind == 0x6, val, self.low)
        time_now = (high_now << 12) | low_now
        y_now = last(kind == 0x0, val & 0x7FF, self.y)
        # Vector words: base x from the last VECT_BASE_X, advanced by the vector words since it.
        is_base = kind == 0x3
        step = np.where(kind == 0x4, 12, np.where(kind == 0x5, 8, 0))
        csum = np.cumsum(step)
        base_pos = np.where(is_base, idx, -1)
        np.maximum.accumulate(base_pos, out=base_pos)
        csum_at_base = np.where(base_pos >= 0, csum[np.maximum(base_pos, 0)], 0)
        before = csum - step  # vector steps before this word
        base_x_now = np.where(base_pos >= 0, val[np.maximum(base_pos, 0)] & 0x7FF, self.base_x) + \
            np.where(base_pos >= 0, before - csum_at_base, before)
        base_p_now = np.where(base_pos >= 0, val[np.maximum(base_pos, 0)] >> 11, self.base_p)

        single = kind == 0x2
        parts_t, parts_x, parts_y, parts_p, parts_i = [time_now[single]], [val[single] & 0x7FF], [y_now[single]], \
            [val[single] >> 11], [idx[single]]
        for code, bits in ((0x4, 12), (0x5, 8)):
            sel = np.flatnonzero(kind == code)
            if sel.size:
                mask = (val[sel, None] >> np.arange(bits)) & 1
                r, c = np.nonzero(mask)
                parts_t.append(time_now[sel][r])
                parts_x.append(base_x_now[sel][r] + c)
                parts_y.append(y_now[sel][r])
                parts_p.append(base_p_now[sel][r])
                parts_i.append(sel[r] + c / 16.0)  # file order: the word, then its bits
        order_key = np.concatenate(parts_i)
        order = np.argsort(order_key, kind="stable")
        out = {"t": np.concatenate(parts_t)[order], "x": np.concatenate(parts_x)[order],
               "y": np.concatenate(parts_y)[order], "p": np.concatenate(parts_p)[order].astype(np.uint8)}
        if n:
            if highs.size:
                self.high, self.wraps = int(highs[-1]), int(wrap[-1])
            self.low, self.y = int(low_now[-1]), int(y_now[-1])
            self.base_x = int(base_x_now[-1]) + int(step[-1])
            self.base_p = int(base_p_now[-1])
        return out


def read_evt3(path: Path, chunk: int = CHUNK_EVENTS) -> Iterator[dict[str, np.ndarray]]:
    """Events of an EVT 3.0 ``.raw`` file, ``chunk`` words at a time (see the module docstring)."""
    header, start = evt3_header(path)
    try:
        offset_us = int(header.get("simspad_t_offset_us", "0"))
    except ValueError:
        raise InputError(f"expected an integer, got {header['simspad_t_offset_us']!r}", path=path,
                         field="header simspad_t_offset_us") from None
    decoder = Evt3Decoder()
    size = Path(path).stat().st_size
    if (size - start) % 2:
        raise InputError(f"the data after the header is {size - start} bytes, not a whole number of 16-bit words "
                         "(truncated file?)", path=path, field="data")
    with open(path, "rb") as f:
        f.seek(start)
        while True:
            buf = f.read(2 * chunk)
            if not buf:
                break
            ev = decoder.decode(np.frombuffer(buf, "<u2"))
            if offset_us:
                ev["t"] = ev["t"] + offset_us
            if ev["t"].size and (ev["y"] < 0).any():
                raise InputError("an event word (EVT_ADDR_X or a vector) comes before any EVT_ADDR_Y", path=path,
                                 field="data")
            yield ev


# -- DSEC events.h5 --------------------------------------------------------------------------------------------

def _dsec_file(path: Path) -> h5py.File:
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", path=path) from None
    for name in ("events/t", "events/x", "events/y", "events/p"):
        if name not in h5 or not isinstance(h5[name], h5py.Dataset):
            h5.close()
            raise InputError("dataset missing (a DSEC events.h5 has /events/t, x, y, p)", path=path,
                             field=f"/{name}")
    return h5


def dsec_size(path: Path) -> None:
    """DSEC files state no sensor size (give width and height in the calibration, else it is the largest x, y)."""
    return None


def read_dsec(path: Path, chunk: int = CHUNK_EVENTS) -> Iterator[dict[str, np.ndarray]]:
    """Events of a DSEC ``events.h5`` (``/events/{t,x,y,p}``, timestamps ``t + /t_offset`` µs)."""
    h5 = _dsec_file(path)
    with h5:
        offset = int(h5["t_offset"][()]) if "t_offset" in h5 else 0
        cols = {k: h5[f"events/{k}"] for k in ("t", "x", "y", "p")}
        n = cols["t"].shape[0]
        for k, ds in cols.items():
            if ds.shape != (n,):
                raise InputError(f"shape {ds.shape}, expected ({n},) like /events/t", path=path, field=f"/events/{k}")
        for i in range(0, n, chunk):
            j = min(i + chunk, n)
            yield {"t": cols["t"][i:j].astype(np.int64) + offset, "x": cols["x"][i:j].astype(np.int64),
                   "y": cols["y"][i:j].astype(np.int64), "p": (cols["p"][i:j] > 0).astype(np.uint8)}


# -- AEDAT 4 ---------------------------------------------------------------------------------------------------

def _dv(path: Path):
    try:
        import dv_processing  # deferred: optional dependency (simspad[export]), only AEDAT 4 needs it
    except ImportError:
        raise SimSpadError("reading AEDAT 4 needs the dv-processing library: pip install 'simspad[export]' (or pip "
                           "install dv-processing)", path=path, field="events.format") from None
    return dv_processing


def _aedat4_reader(path: Path):
    dv = _dv(path)
    if not path.name.endswith(".aedat4"):
        # dv-processing aborts the process (no exception) on some malformed names; refuse before calling it
        raise InputError("an AEDAT 4 file's name must end in .aedat4", path=path, field="events.path")
    try:
        reader = dv.io.MonoCameraRecording(str(path))
    except RuntimeError as exc:
        raise InputError(f"not a readable AEDAT 4 file ({_dv_reason(exc)})", path=path, field="events.path") from None
    if not reader.isEventStreamAvailable():
        raise InputError("the AEDAT 4 file has no event stream", path=path, field="events")
    return reader


def _dv_reason(exc: Exception) -> str:
    """dv-processing's one-line reason from its multi-line message (source location, reason, C++ stack trace)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    info = next((line for line in lines if line.startswith("Error info:")), None)
    return (info[len("Error info:"):].strip() if info else (lines[0] if lines else type(exc).__name__))[:200]


def aedat4_size(path: Path) -> tuple[int, int] | None:
    res = _aedat4_reader(path).getEventResolution()
    return (int(res[0]), int(res[1])) if res is not None else None


def read_aedat4(path: Path, chunk: int = CHUNK_EVENTS) -> Iterator[dict[str, np.ndarray]]:
    """Events of an AEDAT 4 file's event stream, through dv-processing (its batches, as stored)."""
    reader = _aedat4_reader(path)
    while reader.isRunning():
        try:
            batch = reader.getNextEventBatch()
        except RuntimeError as exc:
            raise InputError(f"unreadable event data ({_dv_reason(exc)})", path=path, field="events") from None
        if batch is None:
            break
        arr = batch.numpy()
        if arr.size == 0:
            continue
        yield {"t": arr["timestamp"].astype(np.int64), "x": arr["x"].astype(np.int64),
               "y": arr["y"].astype(np.int64), "p": (arr["polarity"] > 0).astype(np.uint8)}


# -- tonic-style structured arrays -----------------------------------------------------------------------------

def read_npy(path: Path, chunk: int = CHUNK_EVENTS) -> Iterator[dict[str, np.ndarray]]:
    """Events of a structured ``.npy`` array with fields ``x``, ``y``, ``t`` (µs) and ``p`` (> 0: ON), read
    memory-mapped."""
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"not a readable .npy array ({exc})", path=path) from None
    names = arr.dtype.names or ()
    for k in ("x", "y", "t", "p"):
        if k not in names:
            raise InputError(f"structured array lacks the field {k!r} (has {', '.join(names) or 'no fields'})",
                             path=path, field=k)
    if arr.ndim != 1:
        raise InputError(f"expected a 1-D array of events, got shape {arr.shape}", path=path, field="shape")
    for i in range(0, arr.shape[0], chunk):
        block = arr[i:i + chunk]
        yield {"t": np.asarray(block["t"]).astype(np.int64), "x": np.asarray(block["x"]).astype(np.int64),
               "y": np.asarray(block["y"]).astype(np.int64), "p": (np.asarray(block["p"]) > 0).astype(np.uint8)}


READERS = {"evt3": read_evt3, "dsec": read_dsec, "aedat4": read_aedat4, "npy": read_npy}
SIZES = {"evt3": evt3_size, "dsec": dsec_size, "aedat4": aedat4_size, "npy": lambda path: None}


def read_events(fmt: str, path: Path, chunk: int = CHUNK_EVENTS) -> Iterator[dict[str, np.ndarray]]:
    """Events of the capture ``path`` in format ``fmt`` (one of :data:`READERS`), chunk by chunk."""
    return READERS[fmt](Path(path), chunk)

"""SPAD photon cubes read in chunks of binary frames: bit-packed ``.npy`` / ``.npz`` cubes and raw packed ``.bin``.

Every reader yields ``(first_index, bits)`` with ``bits`` uint8 ``[n, H, W]`` of 0/1, ``chunk`` binary frames at
a time (memory flat in the capture's length), after :func:`open_cube` has checked the layout and stated the
cube's size.

Layouts read:

- **``.npy``** (visionsim's photon cubes): uint8 ``[N, H, ceil(W/8)]`` (or ``[N, H, ceil(W/8), 1]``) packed along
  the width (``bitpack_dim = 2``) or ``[N, ceil(H/8), W]`` packed along the height (``bitpack_dim = 1``), with
  ``numpy.packbits``'s default big bit order unless ``bit_order = "little"``. A ``transforms.json`` beside the cube
  (visionsim's metadata) supplies ``bitpack``, ``bitpack_dim``, ``w`` and ``h`` when the calibration does not.
  An unpacked 0/1 cube (``bitpack = false`` there, or a last axis already the width) is read as is.
- **``.npz``**: key ``bits`` as above (SimSPAD's own ``simspad export --to npz`` writes it little-endian along the
  width, or unpacked), and optionally ``t_start_s`` [N] (start of each bin, s), ``dcr_cps`` [H, W], ``bin_s``,
  ``gate_s``; the calibration's values win over them.
- **``.bin``**: a raw stream of frames, each ``frame_header_bytes`` (skipped) then ``H·ceil(W/8)`` bytes packed
  along the width in ``bit_order`` (SwissSPAD2's readout is little); the frame size must be stated.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from simspad.errors import InputError

#: Binary frames per chunk.
CHUNK_BINS = 1024


@dataclass
class Cube:
    """An opened photon cube: its size, how it is packed, and extras an ``.npz`` may carry."""

    path: Path
    fmt: str
    n_bins: int
    width: int
    height: int
    packed_dim: int | None       # 1 rows, 2 columns, None unpacked
    bit_order: str
    data: object                 # a memory-mapped array, or for .bin the byte layout
    t_start_s: np.ndarray | None = None
    dcr_cps: np.ndarray | None = None
    bin_s: float | None = None
    gate_s: float | None = None
    frame_header_bytes: int = 0


def _load_npz_member(path: Path, key: str):
    """One member of an ``.npz``: memory-mapped when stored uncompressed (SimSPAD's export, ``numpy.savez``),
    else loaded whole (``numpy.savez_compressed``); None when absent."""
    with zipfile.ZipFile(path) as zf:
        name = f"{key}.npy"
        if name not in zf.namelist():
            return None
        info = zf.getinfo(name)
        with zf.open(info) as f:
            if info.compress_type != zipfile.ZIP_STORED:
                return np.load(f, allow_pickle=False)
            major, _ = np.lib.format.read_magic(f)
            read_header = (np.lib.format.read_array_header_1_0 if major == 1
                           else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read_header(f)
            header_len = f.tell()
        if fortran or dtype.hasobject:
            with zf.open(info) as f:
                return np.load(f, allow_pickle=False)
    # the member's data follow its local header, whose extra field may differ from the central directory's
    with open(path, "rb") as raw:
        raw.seek(info.header_offset + 26)
        n_name, n_extra = (int(v) for v in np.frombuffer(raw.read(4), "<u2"))
    data_start = info.header_offset + 30 + n_name + n_extra + header_len
    return np.memmap(path, dtype=dtype, mode="r", offset=data_start, shape=shape)


def _visionsim_meta(path: Path) -> dict:
    meta = path.parent / "transforms.json"
    if not meta.is_file():
        return {}
    try:
        data = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"unreadable visionsim metadata ({exc})", path=meta) from None
    return data if isinstance(data, dict) else {}


def _layout(path: Path, arr: np.ndarray, width, height, bitpack_dim, bit_order, packed: bool | None) -> Cube:
    if arr.dtype != np.uint8:
        raise InputError(f"expected uint8 bit planes, got {arr.dtype}", path=path, field="bits")
    if arr.ndim == 4 and arr.shape[3] == 1:
        arr = arr[..., 0]
    if arr.ndim != 3:
        raise InputError(f"expected a cube [N, H, W/8] (or [N, H, W/8, 1]), got shape {arr.shape}", path=path,
                         field="bits")
    n, a, b = arr.shape
    if packed is None:  # infer: unpacked when the stated size matches the array as it is
        packed = not (width == b and height == a)
    if not packed:
        w, h = b, a
        if (width and width != w) or (height and height != h):
            raise InputError(f"an unpacked cube of {w} × {h} pixels, the calibration says {width} × {height}",
                             path=path, field="width")
        return Cube(path, "npy", n, w, h, None, bit_order, arr)
    if bitpack_dim == 2:
        h, w = a, width or 8 * b
        if h != (height or h) or -(-w // 8) != b:
            raise InputError(f"shape {arr.shape} does not hold {w} × {height or h} pixels packed along the width",
                             path=path, field="width")
    else:
        w, h = b, height or 8 * a
        if w != (width or w) or -(-h // 8) != a:
            raise InputError(f"shape {arr.shape} does not hold {width or w} × {h} pixels packed along the height",
                             path=path, field="height")
    return Cube(path, "npy", n, w, h, bitpack_dim, bit_order, arr)


def open_cube(fmt: str, path: Path, *, width=None, height=None, bit_order="little", bitpack_dim=2,
              frame_header_bytes=0) -> Cube:
    """Open a photon cube and check its layout (see the module docstring).

    Raises
    ------
    InputError
        Naming the file and the field (shape, dtype, size) that does not fit.
    """
    path = Path(path)
    if fmt == "bin":
        frame = height * (-(-width // 8)) + frame_header_bytes
        size = path.stat().st_size
        if size % frame:
            raise InputError(f"{size} bytes are not a whole number of frames of {frame} bytes ({width} × {height} "
                             f"px packed, {frame_header_bytes} header bytes): wrong frame size or truncated file",
                             path=path, field="spad.width")
        return Cube(path, "bin", size // frame, width, height, 2, bit_order, None,
                    frame_header_bytes=frame_header_bytes)
    if fmt == "npy":
        meta = _visionsim_meta(path)
        try:
            arr = np.load(path, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable .npy array ({exc})", path=path) from None
        packed = bool(meta["bitpack"]) if "bitpack" in meta else None
        width = width or meta.get("w")
        height = height or meta.get("h")
        if packed and "bitpack_dim" in meta:
            bitpack_dim = int(meta["bitpack_dim"])
        return _layout(path, arr, width, height, bitpack_dim, bit_order, packed)
    try:
        bits = _load_npz_member(path, "bits")
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"not a readable .npz archive ({exc})", path=path) from None
    if bits is None:
        raise InputError("the archive has no 'bits' array", path=path, field="bits")
    cube = _layout(path, bits, width, height, bitpack_dim, bit_order, None)
    cube.fmt = "npz"
    with np.load(path, allow_pickle=False) as z:
        if "t_start_s" in z.files:
            cube.t_start_s = np.asarray(z["t_start_s"], np.float64)
            if cube.t_start_s.shape != (cube.n_bins,):
                raise InputError(f"shape {cube.t_start_s.shape}, expected ({cube.n_bins},)", path=path,
                                 field="t_start_s")
        if "dcr_cps" in z.files:
            cube.dcr_cps = np.asarray(z["dcr_cps"], np.float64)
        for key in ("bin_s", "gate_s"):
            if key in z.files:
                setattr(cube, key, float(z[key]))
    return cube


def _unpack(block: np.ndarray, cube: Cube) -> np.ndarray:
    if cube.packed_dim is None:
        return (np.asarray(block) > 0).astype(np.uint8)
    if cube.packed_dim == 2:
        return np.unpackbits(block, axis=2, count=cube.width, bitorder=cube.bit_order)
    return np.unpackbits(block, axis=1, count=cube.height, bitorder=cube.bit_order)


def iter_bits(cube: Cube, chunk: int = CHUNK_BINS, start: int = 0, stop: int | None = None
              ) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(first_index, bits[n, H, W] uint8 0/1)`` over binary frames ``start:stop``, ``chunk`` at a time."""
    stop = cube.n_bins if stop is None else min(stop, cube.n_bins)
    if cube.fmt == "bin":
        row = -(-cube.width // 8)
        frame = cube.height * row + cube.frame_header_bytes
        with open(cube.path, "rb") as f:
            for i in range(start, stop, chunk):
                n = min(chunk, stop - i)
                f.seek(i * frame)
                raw = np.frombuffer(f.read(n * frame), np.uint8).reshape(n, frame)
                block = raw[:, cube.frame_header_bytes:].reshape(n, cube.height, row)
                yield i, _unpack(block, cube)
        return
    for i in range(start, stop, chunk):
        yield i, _unpack(np.asarray(cube.data[i:min(i + chunk, stop)]), cube)

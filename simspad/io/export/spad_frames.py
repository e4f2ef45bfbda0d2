"""A recording as plain files for SPAD and frame pipelines: ``.npz`` bit planes, 16-bit images, OpenEXR truth.

The directory ``out`` holds::

    metadata.json        the recording's root and sensor attributes (units in their names), and this layout
    spad.npz             bits       uint8 [n, H, ceil(W/8)] packed 8 pixels a byte along x, little bit order
                                    (pixel x is bit x % 8 of byte x // 8: np.unpackbits(bits, axis=2,
                                    count=W, bitorder="little")), or with packing="unpacked" uint8 [n, H, W] 0/1
                         t_start_s  float64 [n]  start of each binary frame's gate, s
                         dcr_cps    float64 [H, W] dark count rate, counts s⁻¹
                         bin_s, gate_s  float64 scalars: frame period and gate length, s
    frames/000000.png …  raw frames in DN, 16-bit grayscale PNG, one per frame (frames_format="png"), or
    frames/frames.tif    all frames as one multi-page 16-bit TIFF stack (frames_format="tiff")
    frames/timestamps.csv  index, t_start_s, t_end_s of each exposure
    gt/000000.exr …      ground truth, 32-bit float OpenEXR: channel Y = sharp photon irradiance
                         (ph s⁻¹ m⁻²), channel Z = depth (m) when the recording has it
    gt/timestamps.csv    index, t_s
    gt/geometry.npz      (recordings with geometry) instance uint16 [N, H, W] (0: nothing; names in
                         metadata.json), flow float32 [N, H, W, 2] (forward motion field over the next
                         ground-truth interval, px, x right, y down; NaN undefined), flow_valid uint8 [N, H, W],
                         velocity float32 [N, H, W, 2] (px s⁻¹), camera_to_world float64 [N, 4, 4],
                         object_to_world float64 [N, K, 4, 4] (when objects move), t_s float64 [N]

``metadata.json`` also holds the camera model (``camera``: K in px, field of view, principal point, pixel
convention) and the instance and object names, when the recording has them.

    .simspad-export-npz  the marker: the files this export wrote (simspad.io.output_dirs)

Groups the recording lacks are left out. Everything streams: SPAD bits go into the ``.npz`` (an uncompressed ZIP
of ``.npy`` files, written entry by entry) in chunks of binary frames, images one at a time. The files are built
in a temporary folder and moved in when complete; an existing ``out`` must be empty or an earlier npz export.
"""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tifffile

from simspad.errors import SimSpadError
from simspad.io.export import FRAME_FORMATS, PACKINGS
from simspad.io.exr import write_exr
from simspad.io.output_dirs import owned_output_dir

#: Binary frames read and written per step.
SPAD_CHUNK_BINS = 4096


def export_spad_frames(rec, out: Path, *, packing: str = "packed", frames_format: str = "png",
                       chunk_bins: int = SPAD_CHUNK_BINS) -> Path:
    """Write the recording's SPAD bits, frames and ground truth as files in the directory ``out``.

    Parameters
    ----------
    rec : Recording
        An open recording.
    out : Path
        The directory: new, empty, or an earlier npz export (whose files are replaced; files others put there
        are kept, see :mod:`simspad.io.output_dirs`). Anything else is refused.
    packing : {"packed", "unpacked"}
        SPAD bits as stored (8 pixels a byte) or one uint8 0/1 per pixel (8× larger).
    frames_format : {"png", "tiff"}
        One 16-bit PNG per frame, or one multi-page TIFF stack.
    chunk_bins : int
        Binary frames per step.
    """
    if packing not in PACKINGS:
        raise SimSpadError(f"unknown SPAD packing {packing!r} (expected one of {', '.join(PACKINGS)})",
                           field="--spad-packing")
    if frames_format not in FRAME_FORMATS:
        raise SimSpadError(f"unknown frame format {frames_format!r} (expected one of {', '.join(FRAME_FORMATS)})",
                           field="--frames-format")
    if not any(rec.has(g) for g in ("spad", "frames", "gt")):
        raise SimSpadError("the recording has no /spad, /frames or /gt group to export", path=rec.path)
    meta = {"layout": "simspad-export-npz", "layout_version": 1, "recording": str(rec.path), "attrs": rec.attrs,
            "groups": {}}
    with owned_output_dir(out, "export-npz", legacy=_legacy_export) as tmp:
        if rec.has("spad"):
            _write_spad(rec, tmp / "spad.npz", packing, chunk_bins)
            meta["groups"]["spad"] = {"file": "spad.npz", "packing": packing, "bitorder": "little",
                                      "axis": "x", "attrs": rec.spad.attrs}
        if rec.has("frames"):
            _write_frames(rec, tmp / "frames", frames_format)
            meta["groups"]["frames"] = {"format": frames_format, "unit": "DN", "attrs": rec.frames.attrs}
        if rec.has("gt"):
            _write_gt(rec, tmp / "gt")
            meta["groups"]["gt"] = {"format": "exr", "channels": {"Y": "photon irradiance, ph s-1 m-2",
                                                                  "Z": "depth, m"}}
            if rec.gt.has_geometry:
                _write_geometry(rec, tmp / "gt" / "geometry.npz")
                camera = rec.gt.camera
                camera["K"] = camera["K"].tolist()
                meta["camera"] = camera
                meta["groups"]["gt"]["geometry"] = {
                    "file": "gt/geometry.npz", "instance_names": rec.gt.instance_names,
                    "objects": rec.gt.object_names, "flow": rec.gt._dataset("flow").attrs["definition"],
                    "flow_interval_s": float(rec.gt._dataset("flow").attrs["interval_s"]),
                    "velocity_units": "px s-1", "pose_convention": "mitsuba: camera looks along +Z, up +Y, +X left"}
        (tmp / "metadata.json").write_text(json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
    return out


_LEGACY_FILES = re.compile(r"(metadata\.json|spad\.npz|frames/[^/]+|gt/[^/]+)")


def _legacy_export(path: Path) -> set[str] | None:
    """The files of an npz export written before folders carried a marker (its ``metadata.json`` names the
    layout), else None."""
    try:
        meta = json.loads((path / "metadata.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or meta.get("layout") != "simspad-export-npz":
        return None
    return {rel for p in path.rglob("*") if p.is_file() and not p.is_symlink()
            and _LEGACY_FILES.fullmatch(rel := p.relative_to(path).as_posix())}


def _npy_entry(zf: zipfile.ZipFile, name: str, dtype, shape: tuple, chunks) -> None:
    """Write one ``.npy`` member of ``shape`` into the open ZIP, from an iterable of row blocks."""
    # A fixed entry time (the ZIP epoch), so the same recording gives the same bytes.
    info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
    with zf.open(info, "w", force_zip64=True) as f:
        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
                  "shape": tuple(int(s) for s in shape)}
        np.lib.format.write_array_header_2_0(f, header)
        for block in chunks:
            f.write(np.ascontiguousarray(block, dtype=dtype).tobytes())


def _write_spad(rec, path: Path, packing: str, chunk_bins: int) -> None:
    spad, H, W = rec.spad, rec.height, rec.width
    n = spad.n_bins
    packed_ds = spad._dataset("bits")
    attrs = spad.attrs
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        if packing == "packed":
            blocks = (packed_ds[i:min(i + chunk_bins, n)] for i in range(0, n, chunk_bins))
            _npy_entry(zf, "bits", np.uint8, (n, H, (W + 7) // 8), blocks)
        else:
            blocks = (bits for _, bits in spad.iter_bits(chunk=chunk_bins))
            _npy_entry(zf, "bits", np.uint8, (n, H, W), blocks)
        _npy_entry(zf, "t_start_s", np.float64, (n,), [spad.t_start])
        _npy_entry(zf, "dcr_cps", np.float64, (H, W), [spad.dcr_cps])
        for key in ("bin_s", "gate_s"):
            _npy_entry(zf, key, np.float64, (), [np.float64(attrs[key])])


def _write_frames(rec, directory: Path, frames_format: str) -> None:
    directory.mkdir()
    frames = rec.frames
    t_start, t_end = frames.t_start, frames.t_end
    if frames_format == "png":
        for i in range(frames.n_frames):
            iio.imwrite(directory / f"{i:06d}.png", np.asarray(frames.dn(i), dtype=np.uint16))
    else:
        with tifffile.TiffWriter(directory / "frames.tif", bigtiff=True) as tw:
            for i in range(frames.n_frames):
                tw.write(np.asarray(frames.dn(i), dtype=np.uint16), contiguous=True)
    _write_csv(directory / "timestamps.csv", ("index", "t_start_s", "t_end_s"),
               np.column_stack([np.arange(t_start.size), t_start, t_end]))


def _write_gt(rec, directory: Path) -> None:
    directory.mkdir()
    t = rec.gt.t
    for i in range(t.size):
        channels = {"Y": rec.gt.flux(i)}
        depth = rec.gt.depth(i)
        if depth is not None:
            channels["Z"] = depth
        write_exr(directory / f"{i:06d}.exr", channels)
    _write_csv(directory / "timestamps.csv", ("index", "t_s"), np.column_stack([np.arange(t.size), t]))


def _write_geometry(rec, path: Path, rows: int = 16) -> None:
    """The ground truth's geometry as one uncompressed ``.npz``, streamed ``rows`` instants at a time."""
    gt, H, W = rec.gt, rec.height, rec.width
    n = gt.t.size

    def blocks(read):
        return (read(slice(i, min(i + rows, n))) for i in range(0, n, rows))

    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        _npy_entry(zf, "t_s", np.float64, (n,), [gt.t])
        _npy_entry(zf, "instance", np.uint16, (n, H, W), blocks(gt.instance))
        _npy_entry(zf, "flow", np.float32, (n, H, W, 2), blocks(gt.flow))
        _npy_entry(zf, "flow_valid", np.uint8, (n, H, W), blocks(gt.flow_valid))
        _npy_entry(zf, "velocity", np.float32, (n, H, W, 2), blocks(gt.velocity))
        _npy_entry(zf, "camera_to_world", np.float64, (n, 4, 4), [gt.camera_to_world])
        objects = gt.object_to_world
        if objects is not None:
            _npy_entry(zf, "object_to_world", np.float64, objects.shape, [objects])


def _write_csv(path: Path, header: tuple[str, ...], rows: np.ndarray) -> None:
    lines = [",".join(header)]
    lines += [",".join([str(int(r[0]))] + [repr(float(v)) for v in r[1:]]) for r in rows]
    path.write_text("\n".join(lines) + "\n")

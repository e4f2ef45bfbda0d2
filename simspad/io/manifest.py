"""The dataset manifest (docs/format.md): ``<dataset>/manifest.json``.

The manifest is the dataset's table of contents: the spec it was generated from, the spec hash, the seed, and
for every recording its relative path, size, sha256, status and timings. It is rewritten atomically (temporary
name, fsync, rename) each time a recording completes, so a crash leaves either the old or the new manifest,
never a torn one.

Layout::

    {"format": "simspad-dataset", "version": 1, "name": ..., "spec": {...}, "spec_hash": ..., "seed": ...,
     "created_utc": ..., "updated_utc": ..., "simspad_version": ...,
     "recordings": [{"sequence", "scene", "speed_factor", "lux", "path", "size", "sha256", "status",
                     "recording_hash", "render": "renders/<sequence>-<hash>", "timings": {...},
                     "motion"?: {speed_factor, image_speed_px_s_p50, image_speed_px_s_p95, frame_blur_px_p95,
                                 frame_blur_exposure_s}, "error"?}],
     "renders": [{"sequence", "scene", "speed_factor", "path", "render_hash", "status", "n_keyframes"?,
                  "timings"}]}

``status`` is ``"complete"``, ``"pending"`` or ``"failed"``. ``recording_hash`` is the hash of everything that
affects that one file (render inputs, lux, sensor parameters, seed, stream key, ground-truth rate, optics,
software versions), so a spec change redoes only the recordings whose hash changed.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.hashing import file_sha256
from simspad.io.safe_paths import confined_path

MANIFEST_NAME = "manifest.json"
FORMAT = "simspad-dataset"
VERSION = 1
STATUSES = ("complete", "pending", "failed")
_HASH_CHUNK_BYTES = 8 << 20


def manifest_path(dataset_dir: str | Path) -> Path:
    """``<dataset_dir>/manifest.json``."""
    return Path(dataset_dir) / MANIFEST_NAME


def content_sha256(path: str | Path, *, rows_per_read: int = 4096) -> str:
    """Hex sha256 of an HDF5 file's *content*: every group, dataset (name, dtype, shape, values) and attribute
    (name, value), in sorted order, read ``rows_per_read`` rows at a time.

    Two files with equal content hash hold the same data even where their bytes differ (the HDF5 library may
    place objects differently in the file); :func:`file_sha256` is the stricter, byte-level check the manifest
    records.
    """
    import h5py  # deferred: h5py (0.4 s) only for this check; the manifest itself is JSON

    h = hashlib.sha256()

    def attrs(obj) -> None:
        for key in sorted(obj.attrs):
            value = obj.attrs[key]
            h.update(f"@{key}=".encode())
            h.update(np.asarray(value).tobytes() if isinstance(value, np.ndarray) else repr(value).encode())

    def visit(group) -> None:
        attrs(group)
        for name in sorted(group):
            obj = group[name]
            h.update(f"/{obj.name}:".encode())
            if isinstance(obj, h5py.Dataset):
                h.update(f"{obj.dtype.str}{obj.shape}".encode())
                attrs(obj)
                if obj.shape == ():
                    h.update(np.asarray(obj[()]).tobytes())
                else:
                    for i in range(0, obj.shape[0], rows_per_read):
                        h.update(np.ascontiguousarray(obj[i : i + rows_per_read]).tobytes())
            else:
                visit(obj)

    with h5py.File(path, "r") as f:
        visit(f)
    return h.hexdigest()


def write_manifest(dataset_dir: str | Path, manifest: dict[str, Any]) -> Path:
    """Write ``manifest`` to ``<dataset_dir>/manifest.json`` atomically (fsynced before the rename)."""
    final = manifest_path(dataset_dir)
    text = json.dumps(manifest, indent=1, sort_keys=False, default=_json_default) + "\n"
    with atomic_path(final) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    return final


def read_manifest(dataset_dir: str | Path) -> dict[str, Any]:
    """Read and validate ``<dataset_dir>/manifest.json``.

    Raises
    ------
    InputError
        Missing, unreadable, not JSON, or not a SimSPAD dataset manifest (naming file and field).
    """
    path = manifest_path(dataset_dir)
    if not path.is_file():
        raise InputError("no manifest.json: not a SimSPAD dataset directory", path=Path(dataset_dir))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read ({exc})", path=path) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON (line {exc.lineno}, column {exc.colno})", path=path) from None
    validate_manifest(data, path)
    return data


def validate_manifest(data: Any, path: str | Path) -> None:
    """Check the structure of a manifest; :class:`InputError` naming the first bad field."""
    if not isinstance(data, dict):
        raise InputError("expected a JSON object", path=path)
    if data.get("format") != FORMAT:
        raise InputError(f"expected {FORMAT!r}, got {data.get('format')!r}", path=path, field="format")
    if data.get("version") != VERSION:
        raise InputError(f"unsupported version {data.get('version')!r} (this SimSPAD reads {VERSION})",
                         path=path, field="version")
    recs = data.get("recordings")
    if not isinstance(recs, list):
        raise InputError("expected a list", path=path, field="recordings")
    for i, rec in enumerate(recs):
        if not isinstance(rec, dict):
            raise InputError("expected an object", path=path, field=f"recordings[{i}]")
        for key, typ in (("sequence", str), ("path", str), ("status", str), ("lux", (int, float))):
            if not isinstance(rec.get(key), typ):
                raise InputError("missing or of the wrong type", path=path, field=f"recordings[{i}].{key}")
        if rec["status"] not in STATUSES:
            raise InputError(f"expected one of {', '.join(STATUSES)}, got {rec['status']!r}", path=path,
                             field=f"recordings[{i}].status")
        if Path(rec["path"]).is_absolute() or ".." in Path(rec["path"]).parts:
            raise InputError("must be a path relative to the dataset directory", path=path,
                             field=f"recordings[{i}].path")
        if rec["status"] == "complete" and not (isinstance(rec.get("size"), int) and isinstance(rec.get("sha256"), str)):
            raise InputError("a complete recording needs its size and sha256", path=path, field=f"recordings[{i}]")
    for i, ren in enumerate(data.get("renders") or []):
        rel = ren.get("path") if isinstance(ren, dict) else None
        if isinstance(rel, str) and (Path(rel).is_absolute() or ".." in Path(rel).parts):
            raise InputError("must be a path relative to the dataset directory", path=path,
                             field=f"renders[{i}].path")


def recording_mismatch(dataset_dir: str | Path, entry: dict[str, Any]) -> str | None:
    """Why a complete entry's file does not match the manifest (missing, size, sha256), or None if it does."""
    path = confined_path(dataset_dir, entry.get("path"), source=manifest_path(dataset_dir), field="recordings.path")
    try:
        size = path.stat().st_size
    except OSError:
        return "file missing"
    if size != entry.get("size"):
        return f"size {size} bytes differs from the manifest's {entry.get('size')}"
    if not isinstance(entry.get("sha256"), str):
        return "no sha256 in the manifest"
    if file_sha256(path) != entry["sha256"]:
        return "sha256 differs from the manifest's"
    return None


def recording_is_complete(dataset_dir: str | Path, entry: dict[str, Any], recording_hash: str) -> bool:
    """True if ``entry`` is complete, its hash is ``recording_hash`` and the file's bytes match its sha256."""
    if entry.get("status") != "complete" or entry.get("recording_hash") != recording_hash:
        return False
    path = Path(dataset_dir) / entry["path"]
    try:
        if path.stat().st_size != entry.get("size"):
            return False
    except OSError:
        return False
    return file_sha256(path) == entry.get("sha256")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (_dt.date, _dt.datetime, _dt.time)):
        return obj.isoformat()
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")

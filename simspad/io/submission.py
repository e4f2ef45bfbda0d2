"""The submission file of ``simspad score``: an external method's reconstructions in one HDF5 file.

The layout is documented in ``docs/submission.md``: root attributes ``format = "simspad-submission"``,
``format_version`` (optional, 1), ``method``, ``label``, ``sensors``, ``absolute_scale``,
``bandwidth_khz_per_pixel``, ``bandwidth_bits_per_pixel_s``; one group per recording holding ``t`` [N] float64
(the ground-truth evaluation instants, s) and ``flux`` [N,H,W] float32 (ph s⁻¹ m⁻², finite, ≥ 0).

Each problem is reported as one :class:`~simspad.errors.InputError` naming the submission file and the field
(an attribute as ``/.name``, a dataset as ``/group/name``). Only numeric datasets and scalar/string attributes
are read: nothing is executed, evaluated or unpickled. Which groups a dataset expects, and the instants, are the
evaluation protocol's business (:mod:`simspad.evaluate.score`); this module checks the file against them.
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np

from simspad.errors import InputError
from simspad.io.hdf5 import open_checked

FORMAT = "simspad-submission"
FORMAT_VERSION = 1
#: Root attributes every submission carries, with their kind.
REQUIRED_ATTRS = {
    "method": "str", "label": "str", "sensors": "str", "absolute_scale": "bool",
    "bandwidth_khz_per_pixel": "float", "bandwidth_bits_per_pixel_s": "float",
}
#: Largest difference between a submitted instant and the ground-truth instant, s.
TIME_ATOL_S = 1e-7
#: Frames checked at a time for NaN, inf and negative values.
_CHECK_FRAMES = 8


def open_submission(path: str | Path) -> h5py.File:
    """Open a submission read-only (InputError for a missing, corrupt or foreign file or another version)."""
    return open_checked(path, kind="submission", format=FORMAT, format_version=FORMAT_VERSION,
                        default_version=FORMAT_VERSION)


def read_attrs(h5: h5py.File, path: Path) -> dict:
    """The required root attributes, checked and converted (str, bool, float ≥ 0)."""
    return {k: _attr(h5, k, kind, path) for k, kind in REQUIRED_ATTRS.items()}


def _attr(h5, name: str, kind: str, path: Path):
    field = f"/.{name}"
    if name not in h5.attrs:
        raise InputError("required attribute missing", path=path, field=field)
    try:
        v = h5.attrs[name]
    except Exception:  # unreadable attribute type (references, opaque, ...)
        raise InputError("attribute of an unsupported type", path=path, field=field) from None
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        if v.shape not in ((), (1,)):
            raise InputError(f"expected a scalar, got an array of shape {v.shape}", path=path, field=field)
        v = v.reshape(-1)[0]
    if isinstance(v, np.generic):
        v = v.item()
    if kind == "str":
        if not isinstance(v, str) or not v.strip():
            raise InputError(f"expected a non-empty string, got {v!r}", path=path, field=field)
        return v
    if kind == "bool":
        if isinstance(v, bool) or (isinstance(v, int) and v in (0, 1)):
            return bool(v)
        if isinstance(v, str) and v.lower() in ("true", "false"):
            return v.lower() == "true"
        raise InputError(f"expected a boolean (true/false or 1/0), got {v!r}", path=path, field=field)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"expected a number, got {v!r}", path=path, field=field)
    if not math.isfinite(v) or v < 0:
        raise InputError(f"expected a finite number ≥ 0, got {v!r}", path=path, field=field)
    return float(v)


def recording_groups(h5: h5py.File, path: Path) -> dict[str, h5py.Group]:
    """Groups holding the per-recording datasets, by name (without the leading '/')."""
    groups: dict[str, h5py.Group] = {}
    problems: list[tuple[str, str]] = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            parent = name.rsplit("/", 1)[0] if "/" in name else ""
            if not parent:
                problems.append((f"/{name}", "datasets must sit inside one group per recording"))
            else:
                groups[parent] = obj.parent
        elif not isinstance(obj, h5py.Group):
            problems.append((f"/{name}", "unsupported HDF5 object"))

    h5.visititems(visit)
    if problems:
        field, msg = problems[0]
        raise InputError(msg, path=path, field=field)
    if not groups:
        raise InputError("no recording groups (expected one group per recording holding t and flux)", path=path)
    return groups


def _numeric(ds, field: str, path: Path, kind: str):
    if ds.dtype.kind not in "fiu" or ds.dtype.names is not None or ds.dtype.subdtype is not None:
        raise InputError(f"dtype {ds.dtype} is not numeric", path=path, field=field)
    if ds.dtype != np.dtype(kind):
        raise InputError(f"dtype {ds.dtype}, expected {kind}", path=path, field=field)


def _read(ds, selection, field: str, path: Path) -> np.ndarray:
    """``ds[selection]``; a read error of the HDF5 library (a corrupt chunk, a filter this installation lacks) is
    an InputError naming the dataset."""
    try:
        return ds[selection]
    except Exception as exc:  # noqa: BLE001 - the library's own errors for damaged data
        raise InputError(f"unreadable ({str(exc)[:100]})", path=path, field=field) from None


def check_group_members(group: h5py.Group, name: str, path: Path) -> None:
    """The group holds exactly ``t`` (float64) and ``flux`` (float32) datasets."""
    for member in group:
        if member not in ("t", "flux"):
            raise InputError("unexpected member (a recording group holds only t and flux)", path=path,
                             field=f"/{name}/{member}")
    for member in ("t", "flux"):
        if member not in group or not isinstance(group[member], h5py.Dataset):
            raise InputError("dataset missing", path=path, field=f"/{name}/{member}")
    _numeric(group["t"], f"/{name}/t", path, "float64")
    _numeric(group["flux"], f"/{name}/flux", path, "float32")


def check_group_frames(group: h5py.Group, name: str, gt_t: np.ndarray, shape: tuple[int, int], recording: str,
                       path: Path) -> None:
    """``t`` matches the ground-truth evaluation instants ``gt_t`` (s) of ``recording``; ``flux`` is
    ``[N, H, W]`` with ``shape = (H, W)``, finite and ≥ 0 (read ``_CHECK_FRAMES`` frames at a time)."""
    t_ds, f_ds = group["t"], group["flux"]
    H, W = shape
    if t_ds.ndim != 1:
        raise InputError(f"shape {t_ds.shape}, expected [N] with N = {gt_t.size}", path=path, field=f"/{name}/t")
    if t_ds.shape[0] != gt_t.size:
        raise InputError(f"{t_ds.shape[0]} instants, expected the {gt_t.size} ground-truth evaluation instants "
                         f"of {recording}", path=path, field=f"/{name}/t")
    t = _read(t_ds, (), f"/{name}/t", path)
    if not np.all(np.isfinite(t)):
        raise InputError("timestamps hold NaN or inf", path=path, field=f"/{name}/t")
    bad = np.nonzero(np.abs(t - gt_t) > TIME_ATOL_S)[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(f"timestamps do not match the ground-truth instants (t[{i}] = {float(t[i])!r} s, expected "
                         f"{float(gt_t[i])!r} s; {bad.size} differ by more than {TIME_ATOL_S:g} s)",
                         path=path, field=f"/{name}/t")
    if f_ds.shape != (gt_t.size, H, W):
        raise InputError(f"shape {f_ds.shape}, expected {(gt_t.size, H, W)} (N instants × height × width)",
                         path=path, field=f"/{name}/flux")
    for i in range(0, gt_t.size, _CHECK_FRAMES):
        block = _read(f_ds, np.s_[i:i + _CHECK_FRAMES], f"/{name}/flux", path)
        if not np.all(np.isfinite(block)):
            j = i + int(np.nonzero(~np.isfinite(block).reshape(block.shape[0], -1).all(axis=1))[0][0])
            raise InputError(f"frame {j} holds NaN or inf values", path=path, field=f"/{name}/flux")
        if np.any(block < 0):
            j = i + int(np.nonzero((block < 0).reshape(block.shape[0], -1).any(axis=1))[0][0])
            raise InputError(f"frame {j} holds negative values (photon irradiance is ≥ 0)", path=path,
                             field=f"/{name}/flux")

"""Reading a recording (docs/format.md): :func:`open_recording` validates the file, :class:`Recording` reads it.

:func:`open_recording` refuses missing, corrupt or foreign files with one clear message naming the file and the
field. Methods read recordings only through :class:`Recording` and its views (``rec.gt``, ``rec.poses``,
``rec.spad``, ``rec.frames``, ``rec.events``), so they run unchanged on real captures converted to this layout.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from simspad.errors import InputError
from simspad.io.hdf5 import decode_attr, open_checked
from simspad.io.recording.events import EventsView
from simspad.io.recording.frames import FramesView
from simspad.io.recording.ground_truth import GroundTruthView, PosesView
from simspad.io.recording.layout import (
    FORMAT,
    FORMAT_VERSION,
    REQUIRED_DATASETS,
    REQUIRED_GROUP_ATTRS,
    REQUIRED_ROOT_ATTRS,
    SENSOR_KINDS,
)
from simspad.io.recording.spad import SpadView


class Recording:
    """Read access to a recording; open it with :func:`open_recording`.

    All arrays are read lazily, through one view per group; the bulk streams (SPAD bits, events) are read in
    chunks.

    Attributes
    ----------
    gt : GroundTruthView
        ``/gt``: instants ``t``, ``flux(index)``, ``depth(index)``.
    poses : PosesView
        ``/poses``: ``t``, ``camera_to_world`` (None when absent).
    spad : SpadView
        ``/spad``: ``attrs``, ``t_start``, ``n_bins``, ``dcr_cps``, ``bits``, ``iter_bits``, ``counts``.
    frames : FramesView
        ``/frames``: ``attrs``, ``t_start``, ``t_end``, ``n_frames``, ``dn(index)``.
    events : EventsView
        ``/events``: ``attrs``, ``n_events``, ``ms_to_idx``, ``window(t0_s, t1_s)``, ``iter_chunks``, …
    """

    def __init__(self, path: Path, h5: h5py.File):
        self.path = path
        self.h5 = h5
        self.attrs = {k: decode_attr(v) for k, v in h5.attrs.items()}
        self.gt = GroundTruthView(h5, path, "gt")
        self.poses = PosesView(h5, path, "poses")
        self.spad = SpadView(h5, path, self.width, self.height)
        self.frames = FramesView(h5, path, "frames")
        self.events = EventsView(h5, path)

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
        """The sensor groups present, in the order of ``SENSOR_KINDS``."""
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
        """The dataset spec the recording was generated from ({} when absent or unreadable)."""
        try:
            return json.loads(self.attrs.get("spec", "{}"))
        except (TypeError, json.JSONDecodeError):
            return {}


def open_recording(path: str | Path) -> Recording:
    """Open and validate a recording.

    Raises
    ------
    InputError
        Missing file, not HDF5 (corrupt or truncated), a foreign HDF5 (``format`` attr), an unsupported
        version, or a missing dataset/attribute; the message names the file and the field.
    """
    path = Path(path)
    h5 = open_checked(path, kind="recording", format=FORMAT, format_version=FORMAT_VERSION)
    try:
        _check_layout(h5, path)
    except BaseException:
        h5.close()
        raise
    return Recording(path, h5)


def _scalar_attr(h5: h5py.File, key: str, path: Path, *, integer: bool) -> None:
    """A required root attribute is one finite number (a positive integer for width and height)."""
    value = decode_attr(h5.attrs[key])
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(()).item()
    if isinstance(value, np.generic):
        value = value.item()
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
    if ok and integer:
        ok = float(value).is_integer() and value > 0
    if not ok:
        expected = "a positive integer" if integer else "a finite number"
        raise InputError(f"expected {expected}, got {str(value)[:60]!r}", path=path, field=f"/.{key}")


def _check_layout(h5: h5py.File, path: Path) -> None:
    """InputError naming the first missing root attribute, dataset or group attribute, or a mismatched shape."""
    for key in REQUIRED_ROOT_ATTRS:
        if key not in h5.attrs:
            raise InputError("missing root attribute", path=path, field=f"/.{key}")
        _scalar_attr(h5, key, path, integer=key in ("width", "height"))
    H, W = int(h5.attrs["height"]), int(h5.attrs["width"])
    for group, names in REQUIRED_DATASETS.items():
        if group not in h5:
            continue
        if not isinstance(h5[group], h5py.Group):
            raise InputError("expected a group, found a dataset", path=path, field=f"/{group}")
        for name in names:
            if name not in h5:
                raise InputError("dataset missing", path=path, field=f"/{name}")
            if not isinstance(h5[name], h5py.Dataset):
                raise InputError("expected a dataset, found a group", path=path, field=f"/{name}")
    for group, keys in REQUIRED_GROUP_ATTRS.items():
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

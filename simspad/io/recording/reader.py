"""Reading a recording (docs/format.md): :func:`open_recording` validates the file, :class:`Recording` reads it.

:func:`open_recording` refuses missing, corrupt or foreign files, and any file that breaks docs/format.md in its
structure or in one of its values (:mod:`.validation`), with one clear message naming the file, the field and the
first bad index; a file validated before in the process and unchanged since is not read again. Methods read
recordings only through :class:`Recording` and its views (``rec.gt``, ``rec.poses``, ``rec.spad``, ``rec.frames``,
``rec.events``; one per row of the sensor table :data:`~simspad.io.recording.layout.SENSOR_LAYOUTS`), so they run
unchanged on real captures converted to this layout.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import h5py

from simspad.io.hdf5 import decode_attr, open_checked
from simspad.io.recording.events import EventsView
from simspad.io.recording.frames import FramesView
from simspad.io.recording.ground_truth import GroundTruthView, PosesView
from simspad.io.recording.group import GroupView
from simspad.io.recording.layout import FORMAT, FORMAT_VERSION, SENSOR_KINDS, SENSOR_LAYOUTS
from simspad.io.recording.spad import SpadView
from simspad.io.recording.validation import validate_recording


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

    Every sensor kind of :data:`~simspad.io.recording.layout.SENSOR_LAYOUTS` has its view as the attribute of its
    name (a registered sensor ``toy`` as ``rec.toy``), built by its layout row's ``view``; :meth:`view` gives it
    by name.
    """

    spad: SpadView
    frames: FramesView
    events: EventsView

    def __init__(self, path: Path, h5: h5py.File, attrs: dict[str, dict] | None = None):
        self.path = path
        self.h5 = h5
        attrs = attrs or {}
        self.attrs = attrs["/"] if "/" in attrs else {k: decode_attr(v) for k, v in h5.attrs.items()}
        self.gt = GroundTruthView(h5, path, "gt")
        self.poses = PosesView(h5, path, "poses")
        self._views: dict[str, GroupView] = {kind: row.view(h5, path, self.width, self.height)
                                             for kind, row in SENSOR_LAYOUTS.items()}
        for view in (self.gt, self.poses, *self._views.values()):
            view.preset_attrs(attrs.get(view.name))
        self.__dict__.update(self._views)

    def view(self, kind: str) -> GroupView:
        """The read view of the sensor group ``kind`` (KeyError naming the known kinds for another name)."""
        try:
            return self._views[kind]
        except KeyError:
            raise KeyError(f"no sensor {kind!r} (expected one of {', '.join(self._views)})") from None

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
    """Open a recording and validate it against docs/format.md (:mod:`.validation`: structure and every value,
    streamed in chunks).

    A file validated before in this process and unchanged since (same device, inode, size, modification and
    change times; unchanged for a second before it was validated) is not read again: ``simspad evaluate`` opens
    each recording once per job.

    Raises
    ------
    InputError
        Missing file, not HDF5 (corrupt or truncated), a foreign HDF5 (``format`` attr), an unsupported
        version, or any violation of the format (a missing dataset or attribute, a wrong dtype or shape, a value
        out of range); the message names the file, the field and the first bad index.
    """
    path = Path(path)
    h5 = open_checked(path, kind="recording", format=FORMAT, format_version=FORMAT_VERSION)
    try:
        key, settled = _file_identity(path)
        attrs = None
        if key not in _VALIDATED:
            attrs = validate_recording(h5, path)
            if len(_VALIDATED) >= _VALIDATED_MAX:
                _VALIDATED.clear()
            if settled:
                _VALIDATED.add(key)
        return Recording(path, h5, attrs)
    except BaseException:
        h5.close()
        raise


#: Identities of the files validated in this process (see :func:`open_recording`); forked workers inherit it.
_VALIDATED: set[tuple] = set()
_VALIDATED_MAX = 4096
#: Seconds since a file's last change after which its identity is trusted to show the next change.
_SETTLED_S = 1.0


def _file_identity(path: Path) -> tuple[tuple, bool]:
    """What changes when a file is replaced or rewritten (its resolved path, device, inode, size, m- and ctime),
    and whether it has been left alone for :data:`_SETTLED_S`: file times tick with the kernel's coarse clock
    (milliseconds), so a rewrite right after the last one could keep the same times; a file changed that recently
    is validated again at every open."""
    st = os.stat(path)
    settled = time.time() - max(st.st_mtime, st.st_ctime) > _SETTLED_S
    return (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns), settled

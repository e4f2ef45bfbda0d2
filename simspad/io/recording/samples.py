"""A recording as indexable samples for machine learning: event windows, SPAD bit blocks, frames, ground truth.

Each sequence has ``len`` and ``[i]`` (random access, read lazily from the open file) and iterates in time order,
so it is a ``torch.utils.data.Dataset`` as it stands, with no torch dependency here::

    with open_recording("rec.h5") as rec:
        for events in rec.events.windows(0.010):        # 10 ms windows
            voxels = tonic.transforms.ToVoxelGrid(sensor_size=(rec.width, rec.height, 2), n_time_bins=5)(events)

Event windows are numpy structured arrays ``EVENT_DTYPE`` (fields ``x``, ``y`` uint16, ``t`` int64 µs, ``p``
int8 with **+1 ON / −1 OFF**): the layout tonic's transforms expect. The file stores ``p`` as uint8 1/0, on which
``ToVoxelGrid`` overflows (it writes −1 into the array) or, as bool, miscounts; the signed copy avoids both.
"""

from __future__ import annotations

from abc import abstractmethod
import math
from collections.abc import Sequence

import numpy as np

#: Events as tonic and most event libraries take them: ON = +1, OFF = −1.
EVENT_DTYPE = np.dtype([("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "i1")])


def events_to_structured(events: dict[str, np.ndarray]) -> np.ndarray:
    """Event columns as read from a recording (``p`` 1 ON / 0 OFF) → ``EVENT_DTYPE`` array with signed polarity."""
    out = np.empty(events["t"].shape[0], dtype=EVENT_DTYPE)
    out["x"] = events["x"]
    out["y"] = events["y"]
    out["t"] = events["t"]
    out["p"] = np.where(np.asarray(events["p"]) > 0, 1, -1)
    return out


class _Lazy(Sequence):
    """A read-only sequence of ``n`` items computed by ``_item(i)``; negative indices count from the end."""

    def __init__(self, n: int):
        self._n = int(n)

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._n))]
        i = int(i)
        if i < 0:
            i += self._n
        if not 0 <= i < self._n:
            raise IndexError(f"index {i} out of range for {self._n} items")
        return self._item(i)

    @abstractmethod
    def _item(self, i: int):
        """Item ``i`` (0 ≤ i < len): each subclass says what it reads."""


class EventWindows(_Lazy):
    """Fixed-length event windows ``[t0_s + i·window_s, t0_s + (i+1)·window_s)``; item ``i``: ``EVENT_DTYPE`` array.

    Parameters
    ----------
    events : EventsView
        The recording's ``/events``.
    window_s : float
        Window length, s (> 0).
    t0_s, t1_s : float
        The span cut into windows, s; a last partial window is dropped so every window has the same length.
    """

    def __init__(self, events, window_s: float, t0_s: float, t1_s: float):
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"window_s must be a finite number > 0, got {window_s!r}")
        self.events = events
        self.window_s = float(window_s)
        self.t0_s = float(t0_s)
        # round(): 0.1 / 0.01 is 9.999999999999998 in binary floating point, yet ten windows fit.
        super().__init__(max(0, math.floor(round((t1_s - t0_s) / window_s, 9))))

    def bounds(self, i: int) -> tuple[float, float]:
        """Start and end of window ``i``, s."""
        return self.t0_s + i * self.window_s, self.t0_s + (i + 1) * self.window_s

    def _item(self, i: int) -> np.ndarray:
        return events_to_structured(self.events.window(*self.bounds(i)))


class SpadBlocks(_Lazy):
    """Consecutive blocks of ``n_bins`` SPAD binary frames; item ``i``: ``(t_start_s, bits[n_bins,H,W] uint8)``.

    A last partial block is dropped, so every block has the same shape (stackable in a batch).
    """

    def __init__(self, spad, n_bins: int):
        if int(n_bins) < 1:
            raise ValueError(f"n_bins must be ≥ 1, got {n_bins!r}")
        self.spad = spad
        self.n_bins = int(n_bins)
        super().__init__(spad.n_bins // self.n_bins)

    def _item(self, i: int) -> tuple[float, np.ndarray]:
        start = i * self.n_bins
        t_start = float(self.spad._dataset("t_start")[start])
        return t_start, self.spad.bits(start, start + self.n_bins)


class Frames(_Lazy):
    """The conventional frames; item ``i``: ``(t_start_s, t_end_s, dn[H,W] uint16)``."""

    def __init__(self, frames):
        self.frames = frames
        self._t_start = frames.t_start
        self._t_end = frames.t_end
        super().__init__(frames.n_frames)

    def _item(self, i: int) -> tuple[float, float, np.ndarray]:
        return float(self._t_start[i]), float(self._t_end[i]), self.frames.dn(i)


class GroundTruth(_Lazy):
    """The ground truth; item ``i``: ``(t_s, flux[H,W] ph s⁻¹ m⁻², depth[H,W] m or None)``."""

    def __init__(self, gt):
        self.gt = gt
        self._t = gt.t
        super().__init__(self._t.shape[0])

    def _item(self, i: int) -> tuple[float, np.ndarray, np.ndarray | None]:
        return float(self._t[i]), self.gt.flux(i), self.gt.depth(i)

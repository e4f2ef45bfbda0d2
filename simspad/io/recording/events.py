"""The event stream of a recording (``/events``), read by time window through the millisecond index.

Timestamps ``t`` are int64 µs on the recording's time base; ``ms_to_idx[k]`` is the index of the first event with
``t ≥ 1000·k`` µs, so a window is found by reading one millisecond of timestamps at each end.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from simspad.errors import InputError
from simspad.io.recording.group import GroupView
from simspad.io.recording.samples import EventWindows

#: Events per chunk of :meth:`EventsView.iter_chunks` by default.
CHUNK_EVENTS = 1 << 20
_FIELDS = ("t", "x", "y", "p")


class EventsView(GroupView):
    """``/events``: ``t`` (int64 µs), ``x``, ``y`` (uint16), ``p`` (1 ON / 0 OFF), ``label`` (uint8, optional)."""

    def __init__(self, h5, path):
        super().__init__(h5, path, "events")
        self._ms_to_idx = None
        self._fields: dict = {}  # dataset handles, looked up once: an HDF5 name lookup costs more than a window

    def _field(self, name: str):
        """The dataset ``/events/<name>`` (None when absent), its handle kept for the next reads."""
        if name not in self._fields:
            g = self._h5["events"]
            self._fields[name] = g[name] if name in g else None
        return self._fields[name]

    @property
    def n_events(self) -> int:
        """Number of events."""
        t = self._field("t") if "events" in self._h5 else None
        return int(t.shape[0]) if t is not None else int(self._dataset("t").shape[0])

    @property
    def ms_to_idx(self) -> np.ndarray:
        """Index of the first event of each millisecond (int64; read once)."""
        if self._ms_to_idx is None:
            self._ms_to_idx = self._dataset("ms_to_idx")[()].astype(np.int64)
        return self._ms_to_idx

    def first_index_at(self, t_s: float) -> int:
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
        t = self._field("t")[lo:hi]
        return lo + int(np.searchsorted(t, t_us, side="left"))

    def index_range(self, t0_s: float, t1_s: float) -> tuple[int, int]:
        """Index range of events with ``t0_s ≤ t < t1_s``."""
        return self.first_index_at(t0_s), self.first_index_at(t1_s)

    def check_time_order(self, chunk: int = CHUNK_EVENTS) -> None:
        """Refuse a stream whose timestamps decrease anywhere (windows are found by binary search on ``t``).

        Reads ``/events/t`` ``chunk`` events at a time (memory does not grow with the recording).

        Raises
        ------
        InputError
            Naming ``/events/t`` and the first index where the time goes back.
        """
        previous = None
        for i in range(0, self.n_events, chunk):
            t = self._h5["events/t"][i:i + chunk]
            self._check_order(t, i, previous)
            previous = int(t[-1])

    def _check_order(self, t: np.ndarray, i0: int, previous: int | None) -> None:
        """InputError at the first event of ``t`` (starting at index ``i0``) earlier than the one before it."""
        if t.size == 0:
            return
        back = np.flatnonzero(np.diff(t) < 0)
        if previous is not None and t[0] < previous:
            k, before = 0, previous
        elif back.size:
            k, before = int(back[0]) + 1, int(t[back[0]])
        else:
            return
        raise InputError(f"not sorted (event {i0 + k} at {int(t[k])} µs comes after one at {before} µs)",
                         path=self._path, field="/events/t")

    def by_index(self, i0: int, i1: int) -> dict[str, np.ndarray]:
        """Events ``i0:i1`` as a dict of arrays (``label`` zeros when the recording has none)."""
        out = {k: self._field(k)[i0:i1] for k in _FIELDS}
        label = self._field("label")
        out["label"] = label[i0:i1] if label is not None else np.zeros(i1 - i0, np.uint8)
        return out

    def window(self, t0_s: float, t1_s: float) -> dict[str, np.ndarray]:
        """Events with ``t0_s ≤ t < t1_s``: dict of ``t`` (int64 µs), ``x``, ``y`` (uint16), ``p``, ``label``
        (uint8)."""
        return self.by_index(*self.index_range(t0_s, t1_s))

    def iter_chunks(self, chunk: int = CHUNK_EVENTS, t0_s: float | None = None,
                    t1_s: float | None = None) -> Iterator[dict[str, np.ndarray]]:
        """Yield events in time order, ``chunk`` at a time, optionally restricted to ``[t0_s, t1_s)``."""
        i0 = 0 if t0_s is None else self.first_index_at(t0_s)
        i1 = self.n_events if t1_s is None else self.first_index_at(t1_s)
        previous = None
        for i in range(i0, i1, chunk):
            events = self.by_index(i, min(i + chunk, i1))
            self._check_order(events["t"], i, previous)  # streaming readers see a disorder where it is
            previous = int(events["t"][-1]) if events["t"].size else previous
            yield events

    def windows(self, window_s: float, t0_s: float | None = None, t1_s: float | None = None) -> EventWindows:
        """Fixed-length windows over ``[t0_s, t1_s)`` (default: the recorded span) as a lazy sequence of
        structured arrays with signed polarity (:class:`~simspad.io.recording.samples.EventWindows`)."""
        t0, t1 = self.span_s()
        return EventWindows(self, window_s, t0 if t0_s is None else t0_s, t1 if t1_s is None else t1_s)

    def span_s(self) -> tuple[float, float]:
        """The recorded span ``(t_start_s, t_end_s)`` on the timestamps' time base, s."""
        attrs = self._h5.attrs
        t0 = float(attrs.get("t_start_s", 0.0))
        return t0, float(attrs.get("t_end_s", t0 + float(attrs["duration_s"])))

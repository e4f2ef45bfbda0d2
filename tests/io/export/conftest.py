"""Recordings for the exporter tests: event streams with known content, written with SimSPAD's RecordingWriter.

``source`` arrays are kept beside each file, so every round trip compares what an outside reader returns with
what went in, never with our own reader.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from simspad.io.recording import RecordingWriter

EVENT_ATTRS = dict(threshold_on=0.2, threshold_off=0.2)


@dataclass
class EventSource:
    path: Path
    t: np.ndarray          # int64 µs on the recording's time base
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray          # uint8 1 ON / 0 OFF
    width: int
    height: int
    t_start_s: float
    t_end_s: float


def write_event_recording(path, t_us, x, y, p, *, width, height, t_start_s, t_end_s) -> EventSource:
    """A recording holding only ``/events`` (and the ms index the simulator writes: from t = 0)."""
    t_us = np.asarray(t_us, np.int64)
    root = dict(width=width, height=height, duration_s=t_end_s - t_start_s, lux=1.0, t_start_s=t_start_s,
                t_end_s=t_end_s, created_utc="2026-01-01T00:00:00Z", scene="test")
    n_ms = int(np.ceil(round(t_end_s * 1e3, 6))) + 1
    with RecordingWriter(path, root) as w:
        w.write_dataset("events/t", t_us)
        w.write_dataset("events/x", np.asarray(x, np.uint16))
        w.write_dataset("events/y", np.asarray(y, np.uint16))
        w.write_dataset("events/p", np.asarray(p, np.uint8))
        w.write_dataset("events/ms_to_idx",
                        np.searchsorted(t_us, np.arange(n_ms) * 1000, side="left").astype(np.uint64))
        w.set_attrs("events", **EVENT_ATTRS)
    return EventSource(Path(path), t_us, np.asarray(x, np.uint16), np.asarray(y, np.uint16),
                       np.asarray(p, np.uint8), width, height, t_start_s, t_end_s)


def random_events(rng, n, t0_us, t1_us, width, height):
    """``n`` sorted events in ``[t0_us, t1_us)``: bursts (many events per µs), quiet stretches of several ms."""
    t = np.sort(rng.integers(t0_us, t1_us, n))
    # Empty a few multi-millisecond stretches so windows and ms_to_idx see gaps.
    for start in rng.integers(t0_us, t1_us, 3):
        t = t[(t < start) | (t >= start + 4000)]
    n = t.size
    return t.astype(np.int64), rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n)


@pytest.fixture(scope="module")
def event_source(tmp_path_factory) -> EventSource:
    """≈ 60 000 events over 12.3 ms … 52.3 ms on a 346 × 260 sensor (start not on a whole millisecond)."""
    rng = np.random.default_rng(15)
    t_start_s, t_end_s = 0.0123, 0.0523
    t, x, y, p = random_events(rng, 60_000, 12_300, 52_300, 346, 260)
    path = tmp_path_factory.mktemp("events") / "rec.h5"
    return write_event_recording(path, t, x, y, p, width=346, height=260, t_start_s=t_start_s, t_end_s=t_end_s)

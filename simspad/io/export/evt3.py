"""Prophesee EVT 3.0 ``.raw`` files, encoded here from Prophesee's public description of the format.

An EVT 3.0 file is an ASCII header (lines starting with ``%``, closed by ``% end``) followed by little-endian
16-bit words whose top 4 bits give the word type. The encoder writes, per event, only the words whose value
changed since the previous event, in the order a sensor emits them:

========  =============  ==========================================================
type      name           payload
========  =============  ==========================================================
``0x8``   EVT_TIME_HIGH  bits 23…12 of the timestamp (µs)
``0x6``   EVT_TIME_LOW   bits 11…0 of the timestamp (always after a TIME_HIGH)
``0x0``   EVT_ADDR_Y     y (11 bits)
``0x2``   EVT_ADDR_X     polarity (bit 11: 1 ON, 0 OFF) and x (11 bits): one CD event
========  =============  ==========================================================

Timestamps are 24-bit and wrap every 2²⁴ µs ≈ 16.8 s; a reader counts a wrap when TIME_HIGH goes down, so when
two consecutive events are more than half a wrap apart the encoder inserts TIME_HIGH words every 2¹¹·4096 µs
in between. Timestamps are written relative to the recording's start rounded down to a whole millisecond; the
header line ``% simspad_t_offset_us`` gives that offset (absolute time = t + offset). Addresses are 11-bit, so
sensors up to 2048 × 2048 pixels.

Readers differ on what they decode: OpenEB/Metavision and the ``evt3`` and ``faery`` packages take the timestamp
as TIME_HIGH·4096 + TIME_LOW (the last two ignore the 24-bit wrap, so recordings over 16.8 s come back folded);
``expelliarmus`` (1.1) also counts every decrease of TIME_LOW as a carry into TIME_HIGH, so its timestamps run
ahead by 4096 µs at each TIME_HIGH step that lands on a smaller TIME_LOW (expelliarmus issue #19); its x, y, p
and event order are exact.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.export.common import EXPORT_CHUNK_EVENTS, check_sorted, require_group

EVT_ADDR_Y = 0x0
EVT_ADDR_X = 0x2
EVT_TIME_LOW = 0x6
EVT_TIME_HIGH = 0x8
#: Largest address an 11-bit field holds.
MAX_ADDRESS = (1 << 11) - 1
#: TIME_HIGH steps (of 4096 µs) after which a reader would see the 12-bit field wrap.
_HIGH_WRAP = 1 << 12


def evt3_header(width: int, height: int, t_offset_us: int, date: str = "") -> bytes:
    """The ASCII header of an EVT 3.0 file (``format`` and ``geometry`` lines, as Metavision writes them)."""
    lines = [f"% date {date}"] if date else []
    lines += ["% evt 3.0", f"% format EVT3;height={height};width={width}", f"% geometry {width}x{height}",
              "% integrator_name SimSPAD", f"% simspad_t_offset_us {t_offset_us}", "% end"]
    return ("\n".join(lines) + "\n").encode("ascii")


class Evt3Encoder:
    """Encodes time-sorted event chunks into EVT 3.0 words, carrying the last time, y across chunks."""

    def __init__(self):
        self._high = -1          # last emitted timestamp >> 12 (unwrapped); -1: nothing emitted yet
        self._low = -1
        self._y = -1

    def encode(self, t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Words (uint16, little-endian) for events with timestamps ``t_us`` ≥ 0 (sorted), ``p`` 1 ON / 0 OFF."""
        n = t_us.size
        if n == 0:
            return np.zeros(0, "<u2")
        t_us = t_us.astype(np.int64, copy=False)
        high, low = t_us >> 12, t_us & 0xFFF
        y = y.astype(np.int64)
        prev_high = np.concatenate(([self._high], high[:-1]))
        prev_low = np.concatenate(([self._low], low[:-1]))
        prev_y = np.concatenate(([self._y], y[:-1]))
        need_h = high != prev_high
        need_l = need_h | (low != prev_low)
        need_y = y != prev_y
        # TIME_HIGH words inserted where consecutive events are half a wrap or more apart (never at the start).
        gap = np.where(need_h & (prev_high >= 0), high - prev_high, 0)
        n_fill = np.maximum(0, (gap - 1) // (_HIGH_WRAP // 2))
        counts = n_fill + need_h + need_l + need_y + 1
        pos = np.cumsum(counts) - counts
        words = np.empty(int(counts.sum()), "<u2")
        for i in np.flatnonzero(n_fill):
            steps = prev_high[i] + (_HIGH_WRAP // 2) * np.arange(1, n_fill[i] + 1)
            words[pos[i]:pos[i] + n_fill[i]] = (EVT_TIME_HIGH << 12) | (steps & 0xFFF)
        pos = pos + n_fill
        words[pos[need_h]] = (EVT_TIME_HIGH << 12) | (high[need_h] & 0xFFF)
        pos = pos + need_h
        words[pos[need_l]] = (EVT_TIME_LOW << 12) | low[need_l]
        pos = pos + need_l
        words[pos[need_y]] = (EVT_ADDR_Y << 12) | y[need_y]
        pos = pos + need_y
        words[pos] = (EVT_ADDR_X << 12) | ((np.asarray(p) > 0).astype(np.int64) << 11) | x.astype(np.int64)
        self._high, self._low, self._y = int(high[-1]), int(low[-1]), int(y[-1])
        return words


def export_evt3(rec, out: Path, *, chunk_events: int = EXPORT_CHUNK_EVENTS) -> Path:
    """Write the recording's events as a Prophesee EVT 3.0 ``.raw`` file at ``out``.

    Parameters
    ----------
    rec : Recording
        An open recording with ``/events``, at most 2048 × 2048 pixels.
    out : Path
        The ``.raw`` file to write.
    chunk_events : int
        Events read and encoded per step.
    """
    require_group(rec, "events", "evt3")
    if rec.width > MAX_ADDRESS + 1 or rec.height > MAX_ADDRESS + 1:
        raise InputError(f"EVT 3.0 addresses are 11-bit: {rec.width} × {rec.height} pixels exceed 2048 × 2048",
                         path=rec.path, field="/.width")
    t0_s, _ = rec.events.span_s()
    t_offset_us = int(math.floor(round(t0_s * 1e3, 6))) * 1000
    encoder = Evt3Encoder()
    with atomic_path(out) as tmp, open(tmp, "wb") as f:
        f.write(evt3_header(rec.width, rec.height, t_offset_us, str(rec.attrs.get("created_utc", ""))))
        n, last_us = 0, np.iinfo(np.int64).min
        for ev in rec.events.iter_chunks(chunk_events):
            t_us = ev["t"].astype(np.int64, copy=False)
            check_sorted(t_us, last_us, rec, n)
            if t_us.size and t_us[0] < t_offset_us:
                raise InputError(f"event {n} at {t_us[0]} µs precedes the recording start {t0_s} s",
                                 path=rec.path, field="/events/t")
            f.write(encoder.encode(t_us - t_offset_us, ev["x"], ev["y"], ev["p"]).tobytes())
            n += t_us.size
            last_us = int(t_us[-1]) if t_us.size else last_us
    return out

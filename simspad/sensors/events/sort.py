"""Canonical event order, (µs timestamp, pixel index), from the kernel's per-block output.

The kernel emits events in pixel order (time and a packed pixel/polarity/label code, :mod:`.kernel`), so one
stable counting sort over µs buckets orders a chunk. It runs in parallel on equal slices of that sequence, one
histogram each, with the bucket rows handed out in (bucket, slice) order: the rows a serial pass gives, whatever
the thread count. Sparse events over a long chunk (a µs table would be mostly empty) take a comparison sort
instead. The events held back from the previous chunk (read out after its end, so few) are merged into rows left
free in front of the new ones (:func:`merge_front`), touching only the new events that sort before the last of
them.

Post-processing runs on "parts": the blocks' events read in block (= pixel) order form one virtual sequence (row v
of the sequence lies in segment s with offsets[s] ≤ v < offsets[s+1]), cut into n_parts equal slices, one per
thread (fewer if their histograms would be large). The slices balance the work whatever the blocks' sizes, and the
result does not depend on how the sequence is cut, so it does not depend on the thread count.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from simspad.sensors.events.codes import unpack_codes
from simspad.sensors.events.kernel import EventBuffer

#: Histogram entries (µs buckets × parts) the parallel bucket sort may hold; it uses fewer parts beyond this.
_BUCKET_MAX_ENTRIES = 8 << 20


class EventColumns(NamedTuple):
    """Events as columns, one row per event (sorted by (t_us, pixel) wherever they leave this module)."""

    t_s: np.ndarray
    """float64 readout time, s."""
    t_us: np.ndarray
    """int64 µs timestamp (floor of t_s·10⁶)."""
    pixel: np.ndarray
    """int64 flattened pixel index ``y·W + x``."""
    polarity: np.ndarray
    """uint8, 1 ON, 0 OFF."""
    label: np.ndarray
    """uint8 label code (``LABEL_*``)."""

    @classmethod
    def empty(cls, rows: int) -> EventColumns:
        """``rows`` uninitialised rows."""
        return cls(np.empty(rows), np.empty(rows, np.int64), np.empty(rows, np.int64), np.empty(rows, np.uint8),
                   np.empty(rows, np.uint8))


def sort_events(t_us: np.ndarray, pixel: np.ndarray, n_pix: int) -> np.ndarray:
    """Permutation that orders events by (µs timestamp, pixel index): the file's canonical order."""
    return np.lexsort((np.asarray(pixel), np.asarray(t_us)))


def sort_segments(starts: np.ndarray, ends: np.ndarray, buf: EventBuffer, n_pix: int, lead: int,
                  n_threads: int, t_range_s: tuple[float, float] | None = None) -> EventColumns:
    """The events in buffer rows ``[starts[i], ends[i])`` (segments in pixel order), sorted by (µs, pixel) after
    ``lead`` rows left uninitialised (room for :func:`merge_front`).

    ``t_range_s``: the earliest and latest of their times (s) when the caller knows them (the kernel tracks them
    as it writes), which saves a pass over the events; found here when None."""
    counts = ends - starts
    if counts.sum() == 0:
        return EventColumns.empty(lead)
    if t_range_s is None:
        t_lo, t_hi = _us_range(starts, ends, buf.t_s, n_threads)
    else:  # floor(t·10⁶) is monotone in t: the range's ends are those of the events' µs timestamps
        t_lo, t_hi = (math.floor(t * 1e6) for t in t_range_s)
    span = t_hi - t_lo + 1
    if span <= 4 * int(counts.sum()) + (1 << 20):
        # One histogram of span buckets per part: fewer parts (down to one, a serial pass) when that is large.
        n_parts = max(1, min(n_threads, _BUCKET_MAX_ENTRIES // span))
        return EventColumns(*_bucket_blocks(starts, ends, buf, t_lo, span, n_parts, lead))
    sparse = _gather(starts, ends, buf)  # sparse events over a long chunk: comparison sort
    order = sort_events(sparse[1], sparse[2], n_pix)
    out = EventColumns(*(np.empty(lead + order.size, a.dtype) for a in sparse))
    for a, b in zip(out, sparse):
        a[lead:] = b[order]
    return out


@numba.njit(cache=True)
def _offsets(starts, ends):
    """Exclusive prefix sum of the segments' event counts (``n_seg + 1`` entries, the last = all events)."""
    offsets = np.empty(starts.size + 1, np.int64)
    offsets[0] = 0
    for s in range(starts.size):
        offsets[s + 1] = offsets[s] + ends[s] - starts[s]
    return offsets


@numba.njit(cache=True, inline="always")
def _part(offsets, n_parts, p):
    """Virtual rows ``[v0, v1)`` of part ``p`` and the segment to start reading at (the last one whose first
    row is ≤ ``v0``; segments are read on while they start before ``v1``)."""
    n = offsets[-1]
    v0 = n * p // n_parts
    v1 = n * (p + 1) // n_parts
    return v0, v1, np.searchsorted(offsets, v0, side="right") - 1


@numba.njit(cache=True)
def _part_range(starts, offsets, buf_t, v0, v1, s):
    """(smallest, largest) µs timestamp of virtual rows ``[v0, v1)``, ``s`` as from :func:`_part`."""
    lo = np.iinfo(np.int64).max
    hi = np.iinfo(np.int64).min
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            u = np.int64(math.floor(buf_t[base + v] * 1e6))
            lo = min(lo, u)
            hi = max(hi, u)
        s += 1
    return lo, hi


@numba.njit(cache=True, parallel=True)
def _us_range(starts, ends, buf_t, n_parts):
    """(smallest, largest) µs timestamp of the blocks' events (floor of t·10⁶, as ``timestamps_us``)."""
    offsets = _offsets(starts, ends)
    lo = np.empty(n_parts, np.int64)
    hi = np.empty(n_parts, np.int64)
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        lo[p], hi[p] = _part_range(starts, offsets, buf_t, v0, v1, s)
    return lo.min(), hi.max()


@numba.njit(cache=True)
def _part_histogram(starts, offsets, buf_t, v0, v1, s, t_lo, count):
    """Add the events of virtual rows ``[v0, v1)`` to ``count`` (one entry per µs from ``t_lo``)."""
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            count[np.int64(math.floor(buf_t[base + v] * 1e6)) - t_lo] += 1
        s += 1


@numba.njit(cache=True)
def _part_scatter(starts, offsets, buf, v0, v1, s, t_lo, next_row, out):
    """Move the events of virtual rows ``[v0, v1)`` of ``buf`` to their sorted rows of ``out`` (both
    :class:`~.kernel.EventBuffer`); ``next_row[u]`` is the next free row of µs bucket ``u`` reserved for this part
    (advanced as rows are taken)."""
    buf_t, buf_code = buf.t_s, buf.code
    while s < starts.size and offsets[s] < v1:
        base = starts[s] - offsets[s]
        for v in range(max(v0, offsets[s]), min(v1, offsets[s + 1])):
            i = base + v
            u = np.int64(math.floor(buf_t[i] * 1e6)) - t_lo
            k = next_row[u]
            next_row[u] = k + 1
            out.t_s[k] = buf_t[i]
            out.code[k] = buf_code[i]
        s += 1


@numba.njit(cache=True, parallel=True)
def _bucket_blocks(starts, ends, buf, t_lo, span, n_parts, lead):
    """The blocks' events sorted by (µs timestamp, pixel) with one stable counting sort over µs buckets.

    Blocks cover increasing pixel ranges and each pixel's events are in time order, so reading the blocks in
    order already gives pixel order inside every µs bucket: a stable sort by µs alone suffices. It runs in
    parallel over ``n_parts`` parts of that sequence (one histogram of ``span`` buckets each): the bucket rows are
    handed out in (bucket, part) order, so each part fills its share of a bucket after the earlier parts and in
    its own order, the same rows a serial pass gives. Only the time and the packed code are scattered; the other
    columns are unpacked afterwards in one parallel pass over the sorted rows.

    Returns
    -------
    t_s, t_us, pixel, polarity, label : ndarray
        ``lead`` + number of events rows; the sorted events fill rows ``lead …``, the first ``lead`` rows are
        left uninitialised (room for the held-back events, see :meth:`EventSimulator.advance`).
    """
    offsets = _offsets(starts, ends)
    n = offsets[-1]
    count = np.zeros((n_parts, span), np.int64)
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        _part_histogram(starts, offsets, buf.t_s, v0, v1, s, t_lo, count[p])
    k = lead
    for u in range(span):  # exclusive prefix sum in (bucket, part) order: each part's first row per bucket
        for p in range(n_parts):
            c = count[p, u]
            count[p, u] = k
            k += c
    t_s = np.empty(lead + n, np.float64)
    pix = np.empty(lead + n, np.int64)  # packed codes until unpacked in place
    out = EventBuffer(t_s, pix)
    for p in numba.prange(n_parts):
        v0, v1, s = _part(offsets, n_parts, p)
        _part_scatter(starts, offsets, buf, v0, v1, s, t_lo, count[p], out)
    t_us, pol, lab = unpack_codes(t_s, pix, lead)
    return t_s, t_us, pix, pol, lab


@numba.njit(cache=True)
def merge_front(held, new):
    """Merge the events ``held`` into the front of ``new`` (both :class:`EventColumns`), in place; both sorted by
    (µs, pixel), on a full tie ``held`` (the earlier chunk) comes first.

    The first ``held.t_s.size`` rows of ``new`` are free, the rest hold the new events. Rows are written from the
    front and the write row never passes the next unread new event, so no copy is needed; once ``held`` is used up
    the remaining new events are already in place. Cost: ``held`` plus the new events that sort before its last.
    """
    a_t, a_us, a_pix, a_pol, a_lab = held
    t_s, t_us, pix, pol, lab = new
    na = a_t.size
    n = t_s.size
    i = 0
    j = na
    k = 0
    while i < na:
        if j < n and (t_us[j] < a_us[i] or (t_us[j] == a_us[i] and pix[j] < a_pix[i])):
            t_s[k], t_us[k], pix[k], pol[k], lab[k] = t_s[j], t_us[j], pix[j], pol[j], lab[j]
            j += 1
        else:
            t_s[k], t_us[k], pix[k], pol[k], lab[k] = a_t[i], a_us[i], a_pix[i], a_pol[i], a_lab[i]
            i += 1
        k += 1


@numba.njit(cache=True)
def _gather(starts, ends, buf):
    """Concatenate the blocks' events in block (= pixel) order: ``(t_s, t_us, pixel, polarity, label)``."""
    n = 0
    for b in range(starts.size):
        n += ends[b] - starts[b]
    t = np.empty(n, np.float64)
    pix = np.empty(n, np.int64)
    k = 0
    for b in range(starts.size):
        for i in range(starts[b], ends[b]):
            t[k] = buf.t_s[i]
            pix[k] = buf.code[i]
            k += 1
    t_us, pol, lab = unpack_codes(t, pix, 0)
    return t, t_us, pix, pol, lab

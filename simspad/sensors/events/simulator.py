"""Streaming event simulation: keyframe photocurrent in time chunks, sorted event batches out, ``/events`` written.

Events stream out in time chunks, sorted by (µs timestamp, pixel index) (:mod:`.sort`); the events read out after
a chunk's end are held back and merged with the next chunk, so the order does not depend on chunking; events read
out after the recording's end are dropped. The pixels of a chunk run in parallel blocks (:mod:`.kernel`); a block
whose buffer slice fills up continues from the pixel that did not fit in a larger slice, so no finished work is
redone.

File layout (docs/format.md): ``/events/t`` int64 µs since the timeline's t = 0 (``time_origin_s = 0``; the same
base as ``/gt/t``), ``x``, ``y`` uint16, ``p`` uint8 (1 ON, 0 OFF), ``label`` uint8, and ``ms_to_idx[k]`` = index
of the first event with ``t ≥ 1000·k`` µs, for k = 0 … ceil(t_end_ms) (= ceil(duration_ms) + 1 entries when the
recording starts at 0).
"""

from __future__ import annotations

import json
import math

import numba
import numpy as np
from tqdm import tqdm

from simspad.sensors.events.kernel import (
    Blocks,
    EventBuffer,
    Knots,
    PixelState,
    init_state,
    model_constants,
    simulate_blocks,
)
from simspad.errors import SimSpadError
from simspad.sensors.events.model import (
    LABEL_NAMES,
    PixelMaps,
    draw_pixel_maps,
    mean_shot_noise_ratio,
    noise_field,
    noise_work_problem,
    sensor_current_1lux_e_s,
    sensor_photocurrent_e_s,
)
from simspad.sensors.events.sort import EventColumns, merge_front, sort_segments
from simspad.sensors.presets import EventParams, params_to_attrs

#: Bytes of keyframe photocurrent held per time chunk (bounds memory whatever the sequence length).
CHUNK_BYTES = 64 << 20
#: Keyframe pieces per time chunk at most (keeps each chunk's event buffers small and cache-friendly).
CHUNK_PIECES = 16
#: Events written per HDF5 chunk.
EVENT_CHUNK_ROWS = 1 << 16
#: The ``/events`` columns in write order, with their dtypes.
_EVENT_COLUMNS = (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8), ("label", np.uint8))


def timestamps_us(t_s: np.ndarray) -> np.ndarray:
    """Integer µs timestamps (floor: the µs during which the event was read out)."""
    return np.floor(np.asarray(t_s) * 1e6).astype(np.int64)


class EventSimulator:
    """Streaming event generation: feed photocurrent knots chunk by chunk, get time-sorted event batches.

    Parameters
    ----------
    params : EventParams
    shape : (H, W)
    current0 : ndarray [H·W]
        Photocurrent at ``t0`` (e⁻ s⁻¹); the photoreceptor starts settled there, the reference equal to it and
        each pixel's leak phase drawn from its steady state (uniform over one leak period).
    t0 : float
        Start instant, s.
    current_1lux : float
        ``I₁`` of :func:`~.model.sensor_current_1lux_e_s` (shot-noise normalisation), e⁻ s⁻¹.
    maps : PixelMaps
    """

    def __init__(self, params: EventParams, shape, current0, t0: float, current_1lux: float, maps: PixelMaps):
        self.params = params
        self.shape = (int(shape[0]), int(shape[1]))
        n = self.shape[0] * self.shape[1]
        self.maps = maps
        self.model = model_constants(params, current_1lux)
        self.state = PixelState.empty(maps.rng_state)
        init_state(np.ascontiguousarray(current0, dtype=np.float64).ravel(), float(t0), maps.leak_rate_hz,
                   self.state)
        self._pending = EventColumns.empty(0)
        self._cap = max(1 << 16, 4 * n)  # events expected per chunk (adapts; an overflowing block is rerun)
        self._buf = EventBuffer.empty(0)

    def advance(self, knot_t: np.ndarray, knot_current: np.ndarray) -> EventColumns:
        """Run the pieces between ``knot_t`` (m+1 instants, s) on photocurrents ``[m+1, H·W]`` (e⁻ s⁻¹).

        Returns
        -------
        EventColumns
            Events whose µs timestamp lies before the µs holding ``knot_t[-1]``, sorted by (t_us, pixel);
            later ones are held back and merged with the next chunk, so the order does not depend on chunking.
        """
        pending = self._pending
        knots = Knots(np.ascontiguousarray(knot_t, dtype=np.float64),
                      np.ascontiguousarray(knot_current, dtype=np.float64))
        merged = self._run_chunk(knots, pending.t_s.size)
        # The held-back events are few (read out after the previous chunk's end): they are merged into the rows
        # left free in front of the new ones, touching only the new events that sort before the last of them.
        merge_front(pending, merged)
        cut = int(np.searchsorted(merged.t_us, timestamps_us(knot_t[-1]), side="left"))
        self._pending = EventColumns(*(a[cut:].copy() for a in merged))
        return EventColumns(*(a[:cut] for a in merged))

    def finish(self) -> EventColumns:
        """The events still held back (sorted)."""
        pending = self._pending
        self._pending = EventColumns(*(a[:0] for a in pending))
        return pending

    def _buffers(self, size: int) -> EventBuffer:
        """Event buffers of at least ``size`` rows, kept between chunks (no fresh pages to fault in each time)."""
        if self._buf.t_s.size < size:
            self._buf = EventBuffer.empty(size)
        return self._buf

    def _run_chunk(self, knots: Knots, lead: int = 0) -> EventColumns:
        """All pixels over one chunk, in parallel pixel blocks, sorted by (µs, pixel), after ``lead`` rows left
        uninitialised (room for :func:`~.sort.merge_front`).

        A block that fills its buffer slice stops at the pixel that did not fit (that pixel's state untouched);
        the rest of the block continues in a fresh, larger slice (per-pixel random streams make the result the
        same as one uninterrupted run), so no finished work is redone.
        """
        n_pix = knots.current_e_s.shape[1]
        n_blocks = max(1, min(n_pix, 16 * numba.get_num_threads(), -(-n_pix // 256)))
        bounds = np.arange(n_blocks + 1, dtype=np.int64) * n_pix // n_blocks
        pix_lo, pix_hi = bounds[:-1].copy(), bounds[1:].copy()
        block = np.arange(n_blocks, dtype=np.int64)
        room = max(1024, -(-2 * self._cap // n_blocks))
        starts = np.arange(n_blocks, dtype=np.int64) * room
        used_rows = n_blocks * room
        self._buffers(used_rows)
        seg_pix, seg_start, seg_end, seg_block = [], [], [], []  # finished buffer segments, each a pixel range
        t_min, t_max = math.inf, -math.inf  # readout time range of the events written
        while True:
            ends, p_next, block_t_min, block_t_max = simulate_blocks(Blocks(pix_lo, pix_hi, starts, starts + room),
                                                                     knots, self.maps, self.model, self.state,
                                                                     self._buf)
            t_min, t_max = min(t_min, float(block_t_min.min())), max(t_max, float(block_t_max.max()))
            seg_pix.append(pix_lo)
            seg_start.append(starts)
            seg_end.append(ends)
            seg_block.append(block)
            left = np.flatnonzero(p_next < pix_hi)
            if left.size == 0:
                break
            room *= 4
            pix_lo, pix_hi, block = p_next[left], pix_hi[left], block[left]
            starts = used_rows + np.arange(left.size, dtype=np.int64) * room
            used_rows += left.size * room
            if self._buf.t_s.size < used_rows:  # grow, keeping the segments already written
                old = self._buf
                self._buf = EventBuffer(*(np.empty(used_rows, a.dtype) for a in old))
                for a, b in zip(self._buf, old):
                    a[:b.size] = b
        seg_pix = np.concatenate(seg_pix)
        order = np.argsort(seg_pix, kind="stable")  # pixel order (a segment left empty sorts harmlessly)
        starts = np.concatenate(seg_start)[order]
        ends = np.concatenate(seg_end)[order]
        counts = ends - starts
        per_block = np.bincount(np.concatenate(seg_block)[order], weights=counts, minlength=n_blocks)
        self._cap = max(1024, int(per_block.max()) * n_blocks)
        return sort_segments(starts, ends, self._buf, n_pix, lead, numba.get_num_threads(), (t_min, t_max))


def iter_knot_chunks(flux_tl, t0: float, t1: float, params: EventParams, max_bytes: int = CHUNK_BYTES,
                     max_pieces: int = CHUNK_PIECES):
    """Yield ``(knot_t [m+1], photocurrent [m+1, H·W])`` covering [t0, t1] in chunks of whole keyframe pieces.

    Each chunk is a fresh array (a consumer may keep it), filled knot by knot in place; the last knot of a chunk
    is the first of the next."""
    n_pix = flux_tl.width * flux_tl.height
    per_chunk = max(1, min(max_pieces, max_bytes // (8 * n_pix) - 1))
    times, values = [], None
    for ta, tb, ya, yb in flux_tl.segments(t0, t1):
        if not times:
            times.append(ta)
            values = np.empty((per_chunk + 1, n_pix))
            sensor_photocurrent_e_s(ya, params, out=values[0])
        times.append(tb)
        sensor_photocurrent_e_s(yb, params, out=values[len(times) - 1])
        if len(times) > per_chunk:
            yield np.array(times), values
            last = values[-1]
            times, values = times[-1:], np.empty((per_chunk + 1, n_pix))
            values[0] = last
    if len(times) > 1:
        yield np.array(times), values[:len(times)]


class _EventsWriter:
    """Appends sorted event batches to ``/events`` and counts what ``ms_to_idx`` and the attrs need."""

    def __init__(self, writer, width: int, t1: float):
        self.width = width
        self.t1 = t1
        self.columns = {name: writer.append_dataset(f"events/{name}", (), dtype, chunk_rows=EVENT_CHUNK_ROWS)
                        for name, dtype in _EVENT_COLUMNS}
        n_ms = int(math.ceil(round(t1 * 1e3, 9))) + 1
        self.boundaries_us = np.arange(n_ms, dtype=np.int64) * 1000
        self.ms_to_idx = np.zeros(n_ms, dtype=np.uint64)
        self.counts = np.zeros(len(LABEL_NAMES), dtype=np.int64)

    def write(self, batch: EventColumns) -> None:
        """Append one batch, dropping events read out at or after ``t1``."""
        t_s, t_us, pixel, pol, label = batch
        keep = t_s < self.t1
        if not keep.all():
            t_us, pixel, pol, label = t_us[keep], pixel[keep], pol[keep], label[keep]
        if t_us.size == 0:
            return
        self.ms_to_idx[:] += np.searchsorted(t_us, self.boundaries_us, side="left").astype(np.uint64)
        self.columns["t"].append(t_us)
        self.columns["x"].append((pixel % self.width).astype(np.uint16))
        self.columns["y"].append((pixel // self.width).astype(np.uint16))
        self.columns["p"].append(pol)
        self.columns["label"].append(label)
        self.counts[:] += np.bincount(label, minlength=4)[:4]


def check_noise_work(flux_tl, t0: float, t1: float, params: EventParams, lux: float) -> None:
    """Refuse, before any work, noise rates whose random draws would take hours (:func:`~.model.noise_work_problem`),
    with the shot-noise rate of this scene's pixels at ``t0`` (the same rates :func:`simulate_events` starts
    from)."""
    current = sensor_photocurrent_e_s(flux_tl.sample(t0), params)
    current_1lux = sensor_current_1lux_e_s(float(np.mean(flux_tl.keyframe(0), dtype=np.float64)), lux, params)
    problem = noise_work_problem(params, current.size, t1 - t0, lux,
                                 mean_shot_noise_ratio(current, current_1lux, params))
    if problem:
        raise SimSpadError(problem, field=noise_field(params, lux))


def simulate_events(writer, flux_tl, t0: float, t1: float, params: EventParams, rng: np.random.Generator,
                    lux: float, progress: bool = False, chunk_bytes: int = CHUNK_BYTES) -> dict:
    """Simulate the event camera over [t0, t1] and write ``/events`` (docs/format.md).

    Parameters
    ----------
    writer : RecordingWriter
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Recording interval, s (timeline time base; timestamps are µs since the timeline's t = 0).
    params : EventParams
    rng : numpy.random.Generator
        The sensor's own stream (fixed pattern, then per-pixel stream seeds).
    lux : float
        Scene illuminance of the recording (normalises the shot-noise rate, see :mod:`.model`).
    progress : bool
        Show a progress bar.
    chunk_bytes : int
        Keyframe photocurrent held per time chunk.

    Returns
    -------
    dict
        The attrs written on ``/events``.
    """
    height, width = flux_tl.height, flux_tl.width
    maps = draw_pixel_maps(params, (height, width), rng)
    mean_flux = float(np.mean(flux_tl.keyframe(0), dtype=np.float64))
    current_1lux = sensor_current_1lux_e_s(mean_flux, lux, params)
    sim = EventSimulator(params, (height, width), sensor_photocurrent_e_s(flux_tl.sample(t0), params).ravel(), t0,
                         current_1lux, maps)
    out = _EventsWriter(writer, width, t1)
    chunks = iter_knot_chunks(flux_tl, t0, t1, params, chunk_bytes)
    if progress:
        chunks = tqdm(chunks, desc="events", unit="chunk")
    for knot_t, knot_current in chunks:
        out.write(sim.advance(knot_t, knot_current))
    out.write(sim.finish())
    writer.write_dataset("events/ms_to_idx", out.ms_to_idx)

    counts = out.counts
    attrs = params_to_attrs(params)
    attrs.update(
        time_origin_s=0.0, timestamp_unit="us", t_start_s=float(t0), t_end_s=float(t1),
        ms_to_idx_origin_us=0, lux=float(lux), pixel_area_m2=params.pixel_pitch_m ** 2,
        shot_noise_current_1lux_e_s=current_1lux,
        threshold_on_mean=float(maps.threshold_on.mean()), threshold_on_std=float(maps.threshold_on.std()),
        threshold_off_mean=float(maps.threshold_off.mean()), threshold_off_std=float(maps.threshold_off.std()),
        n_hot_pixels=int(np.count_nonzero(maps.hot_rate_hz)), n_events=int(counts.sum()),
        n_events_by_label=json.dumps({LABEL_NAMES[i]: int(c) for i, c in enumerate(counts)}),
        labels=json.dumps({str(k): v for k, v in LABEL_NAMES.items()}), polarity="1 ON, 0 OFF",
        model="log photocurrent, low-pass f_c=f_max*I/(I+I_ref), per-crossing interpolated timestamps; "
              "shot-noise rate r1*(I1/I)^exponent; leak drift leak_rate*threshold_on; refractory after readout")
    writer.set_attrs("events", **attrs)
    return attrs

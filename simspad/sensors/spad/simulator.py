"""SPAD simulation driver: stream packed binary frames chunk by chunk into a recording (docs/format.md ``/spad``).

The bins of the interval are generated in chunks of about :data:`CHUNK_BYTES` of packed bits, so memory is
bounded whatever the duration. For each chunk the timeline's linear pieces are laid out as runs of bins
(:class:`~simspad.sensors.spad.kernel.ChunkLayout`) and the numba kernel samples them with a seed drawn from the
SPAD's own random stream; secondary detections that fall past a chunk's last bin are carried into the next.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from tqdm import tqdm

from simspad.io.compression import SPAD_COMPRESSIONS
from simspad.sensors.presets import SpadParams
from simspad.sensors.spad.kernel import (
    DENSE_MIN_BYTES,
    DENSE_MIN_CANDIDATES,
    PixelResponse,
    apply_events,
    spad_chunk,
)
from simspad.sensors.spad.layout import KeyframeRing, chunk_layout
from simspad.sensors.spad.model import dcr_map, n_bins, resolve_gate, spad_attrs

#: Target size of one streamed chunk of packed bits (bytes); bounds memory whatever the duration.
CHUNK_BYTES = 16 << 20
MIN_CHUNK_BINS = 64
MAX_CHUNK_BINS = 8192
#: Smallest capacity of the secondary-detection buffer of a kernel call (grown when a call finds more).
EVENTS_CAPACITY = 4096
#: Keyframes one kernel call may span (bounds the images held per call whatever the keyframe rate).
MAX_KEYFRAMES_PER_CALL = 16


class SpadChunker:
    """Generate packed binary frames chunk by chunk from a photon-flux timeline.

    Parameters
    ----------
    flux_tl : Timeline
        Sensor-plane photon irradiance (photons s⁻¹ m⁻²).
    t0 : float
        Start of the first bin, s.
    n_total : int
        Number of bins.
    params : SpadParams
        With ``gate_s`` already resolved to seconds.
    dcr_cps : ndarray [H, W]
        Dark count map.
    rng : numpy.random.Generator
        Seeds of the per-run kernel streams are drawn from it.
    """

    def __init__(self, flux_tl, t0: float, n_total: int, params: SpadParams, dcr_cps: np.ndarray,
                 rng: np.random.Generator):
        self.tl = flux_tl
        self.t0 = float(t0)
        self.n_total = int(n_total)
        self.bin_s = float(params.bin_s)
        self.gate_s = float(params.gate_s)
        self.q_gate = params.detection_area_m2 * self.gate_s
        self.dcr = np.ascontiguousarray(dcr_cps, dtype=np.float32)
        self.rng = rng
        ap, ct = float(params.afterpulsing_probability), float(params.crosstalk_probability)
        self.log1m_ap = math.log1p(-ap) if 0 < ap < 1 else (0.0 if ap <= 0 else -np.inf)
        self.log1m_ct = math.log1p(-ct) if 0 < ct < 1 else (0.0 if ct <= 0 else -np.inf)
        self.response = PixelResponse(dcr_cps=self.dcr, q_gate_m2_s=self.q_gate, gate_s=self.gate_s,
                                      dense_min_candidates=DENSE_MIN_CANDIDATES,
                                      dense_min_bytes=DENSE_MIN_BYTES,
                                      log1m_afterpulse=self.log1m_ap, log1m_crosstalk=self.log1m_ct)
        self._carry = np.empty((0, 3), np.int64)
        self._secondary_per_primary = min(ap, 1.0) + 4 * min(ct, 1.0)
        self._events = np.empty((EVENTS_CAPACITY, 3), np.int64)
        # a call touches at most MAX_KEYFRAMES_PER_CALL + 1 keyframes (the one before its first bin included)
        self._ring = KeyframeRing(flux_tl, MAX_KEYFRAMES_PER_CALL + 1)

    def chunk(self, k0: int, m: int, out: np.ndarray | None = None) -> np.ndarray:
        """Packed bits of bins ``k0 … k0+m−1`` as ``[m, H, ceil(W/8)]`` uint8. Call with consecutive ``k0``.

        ``out``, when given with that frame shape and at least ``m`` rows, has its first ``m`` rows overwritten and
        returned (a view): one buffer serves every chunk, the shorter last one included.
        """
        H, W = self.tl.height, self.tl.width
        shape = (m, H, (W + 7) // 8)
        if out is None or out.shape[1:] != shape[1:] or out.shape[0] < m:
            out = np.empty(shape, np.uint8)  # the kernel writes every byte
        out = out[:m]
        found = []
        for j0, n in self._sub_chunks(k0, m):
            starts = self.t0 + (k0 + j0 + np.arange(n)) * self.bin_s
            layout = chunk_layout(self._ring, starts, self.gate_s, self.bin_s, self.q_gate)
            seed = int(self.rng.integers(0, 2**63))
            self._reserve_events(n * H * W)
            n_events = spad_chunk(out[j0 : j0 + n], self._events, layout, self.response, seed)
            if n_events > len(self._events):  # the buffer was short: grow it and draw the same bits again
                self._events = np.empty((2 * n_events, 3), np.int64)
                n_events = spad_chunk(out[j0 : j0 + n], self._events, layout, self.response, seed)
            events = self._events[:n_events].copy()
            events[:, 0] += j0
            found.append(events)
        events = np.concatenate(found)
        carry, self._carry = self._carry, None
        if len(carry):
            apply_events(out, carry, 0)
        rest = apply_events(out, events, m)
        # afterpulses of the very last bin fall outside the recording
        self._carry = rest if k0 + m < self.n_total else np.empty((0, 3), np.int64)
        return out

    def _reserve_events(self, max_primaries: int) -> None:
        """Size the secondary-detection buffer for a call of ``max_primaries`` pixel-bins up front.

        Even if every pixel-bin detected, the secondaries exceed their mean + 6 σ with probability ~1e-9, so the
        kernel practically never runs twice (a short buffer means drawing the whole call again). The buffer is
        allocated, not written: only the pages the kernel fills are touched.
        """
        mean = self._secondary_per_primary * max_primaries
        need = max(EVENTS_CAPACITY, int(mean + 6.0 * math.sqrt(mean) + 64))
        if len(self._events) < need:
            self._events = np.empty((need, 3), np.int64)

    def _sub_chunks(self, k0: int, m: int):
        """Split bins so that no kernel call spans more than :data:`MAX_KEYFRAMES_PER_CALL` keyframes.

        The kernel holds the keyframes of a call in a ring of slots; dense keyframes (fast motion) would otherwise
        make that grow with the keyframe rate.
        """
        times = self.tl.times_s
        j0 = 0
        while j0 < m:
            t_a = self.t0 + (k0 + j0) * self.bin_s
            i = int(np.searchsorted(times, t_a, side="right"))
            t_limit = times[min(i + MAX_KEYFRAMES_PER_CALL - 1, len(times) - 1)]
            if i + MAX_KEYFRAMES_PER_CALL - 1 >= len(times):
                n = m - j0
            else:
                n = int(np.clip(math.floor((t_limit - self.gate_s - t_a) / self.bin_s) + 1, 1, m - j0))
            yield j0, n
            j0 += n


def h5_chunk_bins(height: int, width: int) -> int:
    """Bins per HDF5 chunk of ``/spad/bits`` (~1 MiB: readers can fetch short windows of bins cheaply)."""
    return int(np.clip((1 << 20) // max(height * ((width + 7) // 8), 1), 1, MAX_CHUNK_BINS))


def chunk_bins(height: int, width: int) -> int:
    """Bins per streamed chunk: about :data:`CHUNK_BYTES` of packed bits."""
    per_bin = height * ((width + 7) // 8)
    return int(np.clip(CHUNK_BYTES // max(per_bin, 1), MIN_CHUNK_BINS, MAX_CHUNK_BINS))


def simulate_spad(writer, flux_tl, t0: float, t1: float, params: SpadParams, rng: np.random.Generator,
                  progress: bool = False) -> dict:
    """Simulate the SPAD on ``[t0, t1]`` and stream it into ``writer`` (docs/format.md ``/spad``).

    Parameters
    ----------
    writer : simspad.io.recording.RecordingWriter
        Open writer; ``/spad/bits``, ``/spad/t_start``, ``/spad/dcr_cps`` and the group attrs are written.
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Interval in seconds; bins whose gate lies inside it are simulated.
    params : SpadParams
        ``gate_s`` may be ``"auto"``: resolved from the flux at ``t0`` (:func:`~simspad.sensors.spad.auto_gate`).
    rng : numpy.random.Generator
        The SPAD's own stream (DCR map first, then the kernel seeds).
    progress : bool
        Show a tqdm bar.

    Returns
    -------
    dict
        The attrs written on ``/spad`` (with the resolved gate).
    """
    H, W = flux_tl.height, flux_tl.width
    dcr = dcr_map((H, W), params, rng)
    q = params.detection_area_m2
    rate0 = None
    if params.gate_s == "auto":
        rate0 = flux_tl.sample(t0).astype(np.float64) * q + dcr
    gate = resolve_gate(params, rate0)
    resolved = dataclasses.replace(params, gate_s=gate)
    n = n_bins(t1 - t0, params.bin_s, gate)
    attrs = spad_attrs(params, gate, n, t0)
    m = chunk_bins(H, W)
    writer.set_attrs("spad", **attrs)
    writer.write_dataset("spad/dcr_cps", dcr, attrs={"units": "counts s-1"})
    bits = writer.append_dataset("spad/bits", (H, (W + 7) // 8), np.uint8,
                                 chunk_rows=min(h5_chunk_bins(H, W), max(n, 1)),
                                 attrs={"bit_order": "little", "axis_packed": "width"}, n_rows=n,
                                 storage=SPAD_COMPRESSIONS[params.compression])
    t_start = writer.append_dataset("spad/t_start", (), np.float64, chunk_rows=max(1, min(m, n)))
    chunker = SpadChunker(flux_tl, t0, n, resolved, dcr, rng)
    bar = tqdm(total=n, unit="bin", desc="spad", leave=False) if progress else None
    buffer = None
    for k0 in range(0, n, m):
        mm = min(m, n - k0)
        # one buffer for every chunk (the appender copies the rows it keeps): no fresh pages to fault in
        buffer = chunker.chunk(k0, mm, out=buffer)
        bits.append(buffer)
        t_start.append(t0 + (k0 + np.arange(mm)) * params.bin_s)
        if bar is not None:
            bar.update(mm)
    if bar is not None:
        bar.close()
    return attrs

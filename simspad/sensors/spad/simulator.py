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

from simspad.sensors.presets import SpadParams
from simspad.sensors.spad.kernel import (
    SPARSE_MAX_PROBABILITY,
    ChunkLayout,
    PixelResponse,
    apply_events,
    spad_chunk,
)
from simspad.sensors.spad.model import dcr_map, n_bins, resolve_gate, spad_attrs, validate_params

#: Target size of one streamed chunk of packed bits (bytes); bounds memory whatever the duration.
CHUNK_BYTES = 16 << 20
MIN_CHUNK_BINS = 64
MAX_CHUNK_BINS = 8192
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
                                      sparse_max_probability=SPARSE_MAX_PROBABILITY,
                                      log1m_afterpulse=self.log1m_ap, log1m_crosstalk=self.log1m_ct)
        self._carry = np.empty((0, 3), np.int64)
        self._rows = None
        self.n_detections_secondary = 0

    def chunk(self, k0: int, m: int, out: np.ndarray | None = None) -> np.ndarray:
        """Packed bits of bins ``k0 … k0+m−1`` as ``[m, H, ceil(W/8)]`` uint8. Call with consecutive ``k0``."""
        H, W = self.tl.height, self.tl.width
        shape = (m, H, (W + 7) // 8)
        if out is None or out.shape != shape:
            out = np.empty(shape, np.uint8)  # every bin is overwritten by its sub-chunk's transpose
        found = []
        for j0, n in self._sub_chunks(k0, m):
            layout = self._layout(k0 + j0, n)
            seed = int(self.rng.integers(0, 2**63))
            rows = self._scratch((H, n, shape[2]))
            events = spad_chunk(rows, layout, self.response, seed)
            out[j0 : j0 + n] = rows.transpose(1, 0, 2)
            events[:, 0] += j0
            found.append(events)
        events = np.concatenate(found)
        carry, self._carry = self._carry, None
        if len(carry):
            apply_events(out, carry, 0)
        rest = apply_events(out, events, m)
        self.n_detections_secondary += len(events)
        # afterpulses of the very last bin fall outside the recording
        self._carry = rest if k0 + m < self.n_total else np.empty((0, 3), np.int64)
        return out

    def _scratch(self, shape: tuple) -> np.ndarray:
        """A zeroed row-major buffer [H, n, ceil(W/8)] for the kernel, reused between calls of the same shape."""
        if self._rows is None or self._rows.shape != shape:
            self._rows = np.zeros(shape, np.uint8)
        else:
            self._rows.fill(0)
        return self._rows

    def _sub_chunks(self, k0: int, m: int):
        """Split bins so that no kernel call spans more than :data:`MAX_KEYFRAMES_PER_CALL` keyframes.

        The kernel holds two images per linear piece; dense keyframes (fast motion) would otherwise make that
        grow with the keyframe rate.
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

    def _layout(self, k0: int, m: int) -> ChunkLayout:
        """Arrays of one kernel call: images [I,H,W], run_ia, run_ib, run_dw [R], bin_run, bin_w [m].

        Consecutive pieces share their end images (the same array objects), so each is stacked once. Every gate
        mean lies between the images of its run (a straddling gate's exact mean is an image of its own), so the
        images bound the flux of the call.
        """
        runs = list(self._runs(k0, m))
        images, index = [], {}

        def image_index(a):
            key = id(a)
            if key not in index:
                index[key] = len(images)
                images.append(a)
            return index[key]

        run_ia = np.empty(len(runs), np.int64)
        run_ib = np.empty(len(runs), np.int64)
        run_dw = np.empty(len(runs), np.float64)
        bin_run = np.empty(m, np.int64)
        bin_w = np.empty(m, np.float64)
        for i, (j0, n, ya, yb, w0, dw, _) in enumerate(runs):
            run_ia[i] = image_index(ya)
            run_ib[i] = image_index(yb)
            run_dw[i] = dw
            bin_run[j0 : j0 + n] = i
            bin_w[j0 : j0 + n] = w0 + dw * np.arange(n)
        stacked = np.stack(images).astype(np.float32, copy=False)
        return ChunkLayout(images=stacked, run_ia=run_ia, run_ib=run_ib, run_dw=run_dw, bin_run=bin_run,
                           bin_w=bin_w)

    def _runs(self, k0: int, m: int):
        """Yield (j0, n, ya, yb, w0, dw, is_piece): runs of bins whose gates lie in one linear piece, or one
        straddling bin (``is_piece`` False, ya = yb = its exact gate mean)."""
        bin_s, gate = self.bin_s, self.gate_s
        t_first = self.t0 + k0 * bin_s
        t_last_end = self.t0 + (k0 + m - 1) * bin_s + gate
        pieces = list(self.tl.segments(t_first, t_last_end))
        if not pieces:  # a single keyframe: constant in time
            y = self.tl.sample(t_first)
            yield 0, m, y, y, 0.0, 0.0, True
            return
        tol = 1e-6 * gate
        starts = self.t0 + (k0 + np.arange(m)) * bin_s
        ta = np.array([p[0] for p in pieces])
        tb = np.array([p[1] for p in pieces])
        idx = np.clip(np.searchsorted(ta, starts + tol, side="right") - 1, 0, len(pieces) - 1)
        inside = starts + gate <= tb[idx] + tol
        j = 0
        while j < m:
            i = idx[j]
            if not inside[j]:
                y = _gate_mean(pieces, float(starts[j]), gate)
                yield j, 1, y, y, 0.0, 0.0, False
                j += 1
                continue
            e = j + 1
            while e < m and inside[e] and idx[e] == i:
                e += 1
            a, b, ya, yb = pieces[i]
            span = b - a
            w0 = (starts[j] + 0.5 * gate - a) / span
            dw = bin_s / span
            yield j, e - j, ya, yb, float(w0), float(dw), True
            j = e


def _gate_mean(pieces, t: float, gate: float) -> np.ndarray:
    """Exact mean over the gate ``[t, t + gate]`` of the piecewise-linear flux given by ``pieces``.

    Each piece ``(a, b, ya, yb)`` it overlaps on ``[lo, hi]`` contributes ``(hi − lo)`` times its value at the
    overlap's midpoint (exact for a linear function), as a weighted sum of the piece's end images: a few
    multiply-adds per pixel, where a general ``Timeline.integrate`` interpolates and converts whole images.
    """
    total = None
    for a, b, ya, yb in pieces:
        lo, hi = max(t, a), min(t + gate, b)
        if hi <= lo:
            continue
        w = (0.5 * (lo + hi) - a) / (b - a)
        term = ya * np.float32((hi - lo) * (1.0 - w) / gate) + yb * np.float32((hi - lo) * w / gate)
        total = term if total is None else total + term
    return total


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
    validate_params(params)
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
                                 attrs={"bit_order": "little", "axis_packed": "width"})
    t_start = writer.append_dataset("spad/t_start", (), np.float64, chunk_rows=max(1, min(m, n)))
    chunker = SpadChunker(flux_tl, t0, n, resolved, dcr, rng)
    bar = tqdm(total=n, unit="bin", desc="spad", leave=False) if progress else None
    for k0 in range(0, n, m):
        mm = min(m, n - k0)
        # a fresh array per chunk: the appender may keep a view of the rows short of a whole HDF5 chunk until
        # the next append, so a reused buffer would overwrite them (m need not be a multiple of its chunk rows)
        bits.append(chunker.chunk(k0, mm))
        t_start.append(t0 + (k0 + np.arange(mm)) * params.bin_s)
        if bar is not None:
            bar.update(mm)
    if bar is not None:
        bar.close()
    return attrs

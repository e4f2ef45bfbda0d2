"""SPAD sensor (DESIGN §4, preset ``swissspad2``): gated binary frames with calibrated noise.

Model
-----
Binary frame ``k`` starts at ``t_k = t0 + k·bin_s``; its gate is ``[t_k, t_k + gate_s]`` (gate at the start of
the bin). A pixel's bit is 1 when at least one photon or dark detection falls inside the gate:

    Λ_k = q·∫_gate Φ(t) dt + r_dark·gate_s,      P(bit = 1) = 1 − exp(−Λ_k),

with ``Φ`` the sensor-plane photon irradiance (photons s⁻¹ m⁻²), ``q = pixel_pitch_m²·fill_factor·qe`` (m², the
detection area) and ``r_dark`` the pixel's dark count rate (a fixed log-normal map with a fraction of hot pixels).
The timeline is piecewise linear in time, so the integral is exact: inside one linear piece Λ_k is an affine
function of ``k``; a gate that straddles a keyframe is integrated piece by piece.

Secondary effects, drawn from each *primary* detection (second-order cascades, ∝ p², are neglected):

- afterpulsing: the detection triggers a spurious detection in the same pixel's next bin with probability
  ``afterpulsing_probability``;
- crosstalk: the detection triggers each of the 4 neighbours in the same bin with probability
  ``crosstalk_probability`` (a trial towards a neighbour outside the array is lost).

Dead time (``dead_time_s``, ≈ 100 ns) does not change the bit in gated 1-bit mode: the first detection in a
gate sets the bit, and detections the dead time hides would only have set it again. The one residual effect —
a detection in the last ``dead_time_s`` of gate k blinding the start of gate k+1 when ``bin_s − gate_s`` is
shorter than the dead time — removes at most ``dead_time_s/gate_s`` of that gate (≤ 1 % for the 10 µs gates
where it can happen) and is neglected. The value is recorded in the attrs for free-running analyses.

Efficiency
----------
Drawing one uniform number per pixel per bin costs the same whatever the light level. Here the bins of a chunk
are simulated per output byte (8 pixels) by whichever sampler is cheaper (both are exact):

- *sparse* (byte's largest probability bound below :data:`SPARSE_MAX_PROBABILITY`): for each pixel, with
  ``Λ_max`` the largest Λ over the chunk (the flux is piecewise linear, so its maximum sits on a keyframe),
  draw geometric skips between candidate bins (``⌊E/Λ_max⌋`` with E exponential: one draw per candidate) and
  keep a candidate with probability ``p_k/p_max`` (thinning, with a squeeze on the lower bound). Work is
  proportional to detections, so dark scenes cost almost nothing;
- *dense*: bin by bin, one uniform per pixel compared with ``z_k = exp(−Λ_k)``, which is advanced by one
  multiplication per bin inside a linear piece (Λ is affine in k there); the byte is assembled in a register.

The random stream is a SplitMix64 generator inside the numba kernel, seeded per kernel call from the caller's
``numpy.random.Generator``: one sequential stream, so outputs are bit-identical for the same seed and chunking
(the chunk size is a function of the frame size only).
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from simspad.errors import SimSpadError
from simspad.sensors.presets import SpadParams, params_to_attrs

#: Per-pixel choice between the sparse (skip) and dense (uniform per bin) samplers: sparse below this p_max.
SPARSE_MAX_PROBABILITY = 0.08
#: Target size of one streamed chunk of packed bits (bytes); bounds memory whatever the duration.
CHUNK_BYTES = 16 << 20
MIN_CHUNK_BINS = 64
MAX_CHUNK_BINS = 8192
#: Keyframes one kernel call may span (bounds the images held per call whatever the keyframe rate).
MAX_KEYFRAMES_PER_CALL = 16
_FIELD = "sensors.spad"


# ---------------------------------------------------------------------------------------------- pure functions
def detection_area_m2(params: SpadParams) -> float:
    """Detection area ``q = pixel_pitch_m²·fill_factor·qe`` (m²): detections s⁻¹ per photon s⁻¹ m⁻²."""
    return float(params.pixel_pitch_m) ** 2 * float(params.fill_factor) * float(params.qe)


def dcr_map(shape: tuple[int, int], params: SpadParams, rng: np.random.Generator) -> np.ndarray:
    """Dark count rate of every pixel, counts s⁻¹, float32 ``[H, W]``.

    Ordinary pixels are log-normal around ``dcr_median_cps`` (σ of ln DCR = ``dcr_log_sigma``); a fraction
    ``hot_pixel_fraction`` of pixels, chosen at random, are hot: log-normal around ``hot_pixel_dcr_cps`` with
    the same σ.
    """
    hot = rng.random(shape) < params.hot_pixel_fraction
    median = np.where(hot, params.hot_pixel_dcr_cps, params.dcr_median_cps)
    dcr = median * np.exp(params.dcr_log_sigma * rng.standard_normal(shape))
    return dcr.astype(np.float32)


def auto_gate(rate_cps, bin_s: float, min_gate_s: float, max_probability: float = 0.9,
              percentile: float = 99.0) -> float:
    """Longest gate in ``[min_gate_s, bin_s]`` keeping the ``percentile`` detection probability ≤ ``max_probability``.

    P(1) = 1 − exp(−rate·gate) is monotone in rate, so the percentile of P is P at the rate's percentile and the
    gate solves ``rate_p·gate = −ln(1 − max_probability)``.

    Parameters
    ----------
    rate_cps : ndarray
        Detection rate per pixel (photon + dark), counts s⁻¹, from the first keyframe.
    bin_s, min_gate_s : float
        Bin period and shortest gate the sensor supports, s.
    """
    rate_p = float(np.percentile(np.asarray(rate_cps, dtype=np.float64), percentile))
    if rate_p <= 0:
        return float(bin_s)
    gate = -math.log1p(-max_probability) / rate_p
    return float(min(max(gate, min_gate_s), bin_s))


def validate_params(params: SpadParams) -> None:
    """Raise :class:`SimSpadError` naming the field for values the model cannot use."""
    checks = [
        ("pixel_pitch_m", params.pixel_pitch_m > 0, "must be > 0"),
        ("fill_factor", 0 < params.fill_factor <= 1, "must be in (0, 1]"),
        ("qe", 0 < params.qe <= 1, "must be in (0, 1]"),
        ("bin_s", params.bin_s > 0, "must be > 0"),
        ("min_gate_s", 0 < params.min_gate_s <= params.bin_s, "must be in (0, bin_s]"),
        ("auto_max_probability", 0 < params.auto_max_probability < 1, "must be in (0, 1)"),
        ("auto_percentile", 0 <= params.auto_percentile <= 100, "must be in [0, 100]"),
        ("hot_pixel_fraction", 0 <= params.hot_pixel_fraction <= 1, "must be in [0, 1]"),
        ("afterpulsing_probability", 0 <= params.afterpulsing_probability < 1, "must be in [0, 1)"),
        ("crosstalk_probability", 0 <= params.crosstalk_probability < 1, "must be in [0, 1)"),
    ]
    for name, ok, message in checks:
        if not ok:
            raise SimSpadError(f"{message}, got {getattr(params, name)!r}", field=f"{_FIELD}.{name}")
    if params.gate_s != "auto":
        resolve_gate(params)


def resolve_gate(params: SpadParams, rate_cps=None) -> float:
    """The gate in seconds: ``params.gate_s`` checked against its range, or :func:`auto_gate` for ``"auto"``."""
    if params.gate_s == "auto":
        if rate_cps is None:
            raise ValueError("auto gate needs the detection rate of the first keyframe")
        return auto_gate(rate_cps, params.bin_s, params.min_gate_s, params.auto_max_probability,
                         params.auto_percentile)
    gate = float(params.gate_s)
    if not (params.min_gate_s * (1 - 1e-9) <= gate <= params.bin_s * (1 + 1e-9)):
        raise SimSpadError(f"gate {gate:g} s must lie in [min_gate_s = {params.min_gate_s:g}, "
                           f"bin_s = {params.bin_s:g}] s (or be 'auto')", field=f"{_FIELD}.gate_s")
    return min(gate, float(params.bin_s))


def n_bins(duration_s: float, bin_s: float, gate_s: float) -> int:
    """Number of whole binary frames whose gate lies inside an interval of ``duration_s``."""
    if duration_s < gate_s:
        return 0
    return int(math.floor((duration_s - gate_s) / bin_s * (1 + 1e-12) + 1e-9)) + 1


def pack_bits(bits: np.ndarray) -> np.ndarray:
    """Pack ``[..., W]`` 0/1 into ``[..., ceil(W/8)]`` uint8, little bit order along W (DESIGN §5)."""
    return np.packbits(np.asarray(bits, dtype=np.uint8), axis=-1, bitorder="little")


def unpack_bits(packed: np.ndarray, width: int) -> np.ndarray:
    """Inverse of :func:`pack_bits`."""
    return np.unpackbits(packed, axis=-1, count=width, bitorder="little")


# ---------------------------------------------------------------------------------------------- numba kernels
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_S32 = np.uint64(32)
_M32 = np.uint64(0xFFFFFFFF)
_INV32 = 1.0 / 4294967296.0
_POPCOUNT8 = np.array([bin(i).count("1") for i in range(256)], np.int64)
_DENSE_BLOCK = 128


@numba.njit(inline="always")
def _next_u64(state):
    """SplitMix64 step: (new state, 64 random bits)."""
    state = state + _GOLDEN
    z = state
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return state, z ^ (z >> _S31)


@numba.njit(inline="always")
def _next_uniform(state):
    """(new state, uniform in [0, 1) with 53-bit resolution)."""
    state, z = _next_u64(state)
    return state, float(z >> _S11) * _INV53


@numba.njit(inline="always")
def _geometric(state, log1m_p):
    """Failures before the next success of Bernoulli trials with log(1 − p) = ``log1m_p`` (< 0)."""
    state, u = _next_uniform(state)
    g = math.log(1.0 - u) / log1m_p  # 1 − u is exact and > 0; log is ~3× cheaper than log1p
    if g > 4.0e18:
        g = 4.0e18
    return state, np.int64(g)


@numba.njit(inline="always")
def _push(events, n_events, k, y, x):
    if n_events == events.shape[0]:
        grown = np.empty((2 * events.shape[0], 3), np.int64)
        grown[:n_events] = events[:n_events]
        events = grown
    events[n_events, 0] = k
    events[n_events, 1] = y
    events[n_events, 2] = x
    return events, n_events + 1


@numba.njit(inline="always")
def _secondaries(state, events, n_events, ap_left, ct_left, k, y, x, H, W, log1m_ap, log1m_ct):
    """Afterpulse and crosstalk trials of one primary detection, as running geometric countdowns.

    A countdown holds the failures before the next success of a stream of Bernoulli trials (1 afterpulse trial
    and 4 crosstalk trials per detection), so the cost is a subtraction per detection, not 5 uniforms.
    """
    if log1m_ap < 0.0:
        if ap_left == 0:
            events, n_events = _push(events, n_events, k + 1, y, x)
            state, ap_left = _geometric(state, log1m_ap)
        else:
            ap_left -= 1
    if log1m_ct < 0.0:
        remaining = np.int64(4)
        nb = np.int64(0)
        while ct_left < remaining:
            nb += ct_left
            yy = y
            xx = x
            if nb == 0:
                yy = y - 1
            elif nb == 1:
                yy = y + 1
            elif nb == 2:
                xx = x - 1
            else:
                xx = x + 1
            if 0 <= yy < H and 0 <= xx < W:
                events, n_events = _push(events, n_events, k, yy, xx)
            remaining -= ct_left + 1
            nb += 1
            state, ct_left = _geometric(state, log1m_ct)
        ct_left -= remaining
    return state, events, n_events, ap_left, ct_left


@numba.njit(inline="always")
def _lam(images, run_ia, run_ib, bin_run, bin_w, k, y, x, q_gate, dark):
    """Λ of bin k at pixel (y, x): the gate's mean flux is affine in w within the bin's run."""
    r = bin_run[k]
    a = float(images[run_ia[r], y, x])
    lam = q_gate * (a + (float(images[run_ib[r], y, x]) - a) * bin_w[k]) + dark
    return lam if lam > 0.0 else 0.0


@numba.njit(cache=True)
def _spad_chunk(out, images, run_ia, run_ib, run_dw, bin_run, bin_w, dcr, q_gate, gate_s, seed,
                sparse_max_p, log1m_ap, log1m_ct, events, n_events):
    """Primary bits of one chunk of ``m`` bins, OR-ed into ``out`` [m, H, ceil(W/8)].

    Bin k belongs to run r = bin_run[k]; its gate-mean flux is ``A_r + (B_r − A_r)·bin_w[k]`` (A_r =
    images[run_ia[r]], B_r = images[run_ib[r]]; w advances by run_dw[r] per bin), so Λ_k = q_gate·mean +
    dcr·gate_s exactly (a gate that straddles a keyframe is a run of its own with A = B = its exact mean), so
    the images bound every gate mean of the call. Secondary detections (afterpulses in bin k+1, crosstalk to
    neighbours in bin k) are appended to ``events`` as (bin, row, col).

    The sampler is chosen per output byte (8 pixels) from the byte's largest probability bound: sparse pixels
    one by one (geometric skips + thinning); dense bytes bin by bin, assembled in a register, with
    z = exp(−Λ) advanced by one multiplication per bin inside a run.
    """
    m = out.shape[0]
    H, W = images.shape[1], images.shape[2]
    Wb = (W + 7) // 8
    state = np.uint64(seed)
    ap_left = np.int64(1) << 62  # never reaches zero when the effect is off
    ct_left = np.int64(1) << 62
    if log1m_ap < 0.0:
        state, ap_left = _geometric(state, log1m_ap)
    if log1m_ct < 0.0:
        state, ct_left = _geometric(state, log1m_ct)
    lam_dense = -math.log1p(-sparse_max_p)
    lam_hi = np.empty(8, np.float64)
    lam_lo = np.empty(8, np.float64)
    dense_y = np.empty(H * Wb, np.int64)
    dense_b = np.empty(H * Wb, np.int64)
    n_dense = 0
    for y in range(H):
        for xb in range(Wb):
            x_end = min(8, W - 8 * xb)
            hi_byte = 0.0
            for bit in range(x_end):
                x = 8 * xb + bit
                hi = 0.0
                lo = np.inf
                for i in range(images.shape[0]):
                    v = float(images[i, y, x])
                    hi = max(hi, v)
                    lo = min(lo, v)
                dark = float(dcr[y, x]) * gate_s
                lam_hi[bit] = q_gate * hi + dark
                lam_lo[bit] = max(q_gate * lo + dark, 0.0)
                hi_byte = max(hi_byte, lam_hi[bit])
            if hi_byte >= lam_dense:
                dense_y[n_dense] = y
                dense_b[n_dense] = xb
                n_dense += 1
                continue
            for bit in range(x_end):
                lam_max = lam_hi[bit]
                if lam_max <= 0.0:
                    continue
                x = 8 * xb + bit
                dark = float(dcr[y, x]) * gate_s
                varying = lam_lo[bit] < lam_max
                p_max = -math.expm1(-lam_max) if varying else 1.0
                p_min = -math.expm1(-lam_lo[bit]) if varying else 1.0
                mask = np.uint8(1 << bit)
                inv_lam = 1.0 / lam_max
                k = np.int64(-1)
                while True:
                    state, u = _next_uniform(state)
                    skip = -math.log(1.0 - u) * inv_lam
                    if skip >= m - 1 - k:
                        break
                    k += 1 + np.int64(skip)
                    if varying:  # thinning: keep with p_k / p_max (squeeze on the lower bound first)
                        state, u = _next_uniform(state)
                        up = u * p_max
                        if up >= p_min:
                            lam = _lam(images, run_ia, run_ib, bin_run, bin_w, k, y, x, q_gate, dark)
                            if up >= -math.expm1(-lam):
                                continue
                    out[k, y, xb] |= mask
                    state, events, n_events, ap_left, ct_left = _secondaries(
                        state, events, n_events, ap_left, ct_left, k, y, x, H, W, log1m_ap, log1m_ct)
    # blocks of dense bytes run through all bins while their state stays in L1 cache
    z = np.ones((_DENSE_BLOCK, 8), np.float64)  # z = 1: never a detection (pixels past the right edge)
    ratio = np.ones((_DENSE_BLOCK, 8), np.float64)
    for b0 in range(0, n_dense, _DENSE_BLOCK):
        b1 = min(b0 + _DENSE_BLOCK, n_dense)
        for k in range(m):
            r = bin_run[k]
            if k == 0 or r != bin_run[k - 1]:  # a new run: exact Λ and its per-bin ratio
                for i in range(b0, b1):
                    y = dense_y[i]
                    for bit in range(min(8, W - 8 * dense_b[i])):
                        x = 8 * dense_b[i] + bit
                        dark = float(dcr[y, x]) * gate_s
                        z[i - b0, bit] = math.exp(-_lam(images, run_ia, run_ib, bin_run, bin_w, k, y, x, q_gate,
                                                        dark))
                        slope = q_gate * (float(images[run_ib[r], y, x]) - float(images[run_ia[r], y, x])) * run_dw[r]
                        ratio[i - b0, bit] = math.exp(-slope) if slope != 0.0 else 1.0
            for i in range(b0, b1):
                ii = i - b0
                value = np.int64(0)
                for bit in range(0, 8, 2):
                    # two 32-bit uniforms per draw: p ≥ SPARSE_MAX_PROBABILITY here, so 2⁻³² resolution is ample
                    state, w = _next_u64(state)
                    u0 = float(w & _M32) * _INV32
                    u1 = float(w >> _S32) * _INV32
                    z0 = z[ii, bit]
                    z1 = z[ii, bit + 1]
                    z[ii, bit] = z0 * ratio[ii, bit]
                    z[ii, bit + 1] = z1 * ratio[ii, bit + 1]
                    # branch-free: at p ~ 0.5 a data-dependent branch mispredicts every other pixel
                    value |= (np.int64(u0 >= z0) << bit) | (np.int64(u1 >= z1) << (bit + 1))
                out[k, dense_y[i], dense_b[i]] |= np.uint8(value)
                count = np.int64(_POPCOUNT8[value])
                if ap_left < count or ct_left < 4 * count:  # a secondary is due: resolve pixel by pixel
                    for bit in range(8):
                        if (value >> bit) & 1:
                            state, events, n_events, ap_left, ct_left = _secondaries(
                                state, events, n_events, ap_left, ct_left, k, dense_y[i], 8 * dense_b[i] + bit,
                                H, W, log1m_ap, log1m_ct)
                else:
                    ap_left -= count
                    ct_left -= 4 * count
        z[:] = 1.0
        ratio[:] = 1.0
    return events, n_events


@numba.njit(cache=True)
def _apply_events(out, events, n_events, k_offset):
    """OR secondary detections into ``out``; return those past its last bin (shifted by ``k_offset``)."""
    m = out.shape[0]
    rest = np.empty((n_events, 3), np.int64)
    n_rest = 0
    for i in range(n_events):
        k = events[i, 0]
        y = events[i, 1]
        x = events[i, 2]
        if k < m:
            out[k, y, x >> 3] |= np.uint8(1 << (x & 7))
        else:
            rest[n_rest, 0] = k - k_offset
            rest[n_rest, 1] = y
            rest[n_rest, 2] = x
            n_rest += 1
    return rest[:n_rest]


# ---------------------------------------------------------------------------------------------- chunked driver
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
        self.q_gate = detection_area_m2(params) * self.gate_s
        self.dcr = np.ascontiguousarray(dcr_cps, dtype=np.float32)
        self.rng = rng
        ap, ct = float(params.afterpulsing_probability), float(params.crosstalk_probability)
        self.log1m_ap = math.log1p(-ap) if 0 < ap < 1 else (0.0 if ap <= 0 else -np.inf)
        self.log1m_ct = math.log1p(-ct) if 0 < ct < 1 else (0.0 if ct <= 0 else -np.inf)
        self._carry = np.empty((0, 3), np.int64)
        self.n_detections_secondary = 0

    def chunk(self, k0: int, m: int, out: np.ndarray | None = None) -> np.ndarray:
        """Packed bits of bins ``k0 … k0+m−1`` as ``[m, H, ceil(W/8)]`` uint8. Call with consecutive ``k0``."""
        H, W = self.tl.height, self.tl.width
        shape = (m, H, (W + 7) // 8)
        if out is None or out.shape != shape:
            out = np.zeros(shape, np.uint8)
        else:
            out.fill(0)
        found = []
        for j0, n in self._sub_chunks(k0, m):
            images, run_ia, run_ib, run_dw, bin_run, bin_w = self._layout(k0 + j0, n)
            seed = int(self.rng.integers(0, 2**63))
            events, n_events = _spad_chunk(out[j0 : j0 + n], images, run_ia, run_ib, run_dw, bin_run, bin_w,
                                           self.dcr, self.q_gate, self.gate_s, seed,
                                           SPARSE_MAX_PROBABILITY, self.log1m_ap, self.log1m_ct,
                                           np.empty((1024, 3), np.int64), 0)
            events = events[:n_events]
            events[:, 0] += j0
            found.append(events)
        events = np.concatenate(found)
        n_events = len(events)
        carry, self._carry = self._carry, None
        if len(carry):
            _apply_events(out, carry, len(carry), 0)
        rest = _apply_events(out, events, n_events, m)
        self.n_detections_secondary += n_events
        # afterpulses of the very last bin fall outside the recording
        self._carry = rest if k0 + m < self.n_total else np.empty((0, 3), np.int64)
        return out

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

    def _layout(self, k0: int, m: int):
        """Arrays of one kernel call: (images [I,H,W], run_ia, run_ib, run_dw [R], bin_run, bin_w [m]).

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
        return stacked, run_ia, run_ib, run_dw, bin_run, bin_w

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
                t_k = starts[j]
                y = self.tl.integrate(t_k, t_k + gate) / np.float32(gate)
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


def h5_chunk_bins(height: int, width: int) -> int:
    """Bins per HDF5 chunk of ``/spad/bits`` (~1 MiB: readers can fetch short windows of bins cheaply)."""
    return int(np.clip((1 << 20) // max(height * ((width + 7) // 8), 1), 1, MAX_CHUNK_BINS))


def chunk_bins(height: int, width: int) -> int:
    """Bins per streamed chunk: about :data:`CHUNK_BYTES` of packed bits."""
    per_bin = height * ((width + 7) // 8)
    return int(np.clip(CHUNK_BYTES // max(per_bin, 1), MIN_CHUNK_BINS, MAX_CHUNK_BINS))


def spad_attrs(params: SpadParams, gate_s: float, n: int, t0: float) -> dict:
    """Group attrs: every parameter with the gate resolved, plus what inverting the data needs."""
    attrs = params_to_attrs(dataclasses.replace(params, gate_s=gate_s))
    area = float(params.pixel_pitch_m) ** 2
    attrs.update(gate_auto=params.gate_s == "auto", pixel_area_m2=area, detection_area_m2=detection_area_m2(params),
                 frame_rate_hz=1.0 / params.bin_s, n_bins=int(n), t0=float(t0), gate_position="start",
                 bit_order="little", dead_time_model="none in gated 1-bit mode (first detection sets the bit)",
                 secondary_model="afterpulse: next bin same pixel; crosstalk: 4-neighbours same bin; "
                                 "from primary detections only")
    return attrs


def simulate_spad(writer, flux_tl, t0: float, t1: float, params: SpadParams, rng: np.random.Generator,
                  progress: bool = False) -> dict:
    """Simulate the SPAD on ``[t0, t1]`` and stream it into ``writer`` (DESIGN §5 ``/spad``).

    Parameters
    ----------
    writer : simspad.io.recording.RecordingWriter
        Open writer; ``/spad/bits``, ``/spad/t_start``, ``/spad/dcr_cps`` and the group attrs are written.
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Interval in seconds; bins whose gate lies inside it are simulated.
    params : SpadParams
        ``gate_s`` may be ``"auto"``: resolved from the flux at ``t0`` (:func:`auto_gate`).
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
    q = detection_area_m2(params)
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
    bar = _progress(progress, n)
    buf = None
    for k0 in range(0, n, m):
        mm = min(m, n - k0)
        buf = chunker.chunk(k0, mm, buf if buf is not None and buf.shape[0] == mm else None)
        bits.append(buf)
        t_start.append(t0 + (k0 + np.arange(mm)) * params.bin_s)
        if bar is not None:
            bar.update(mm)
    if bar is not None:
        bar.close()
    return attrs


def _progress(enabled: bool, total: int):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="bin", desc="spad", leave=False)

"""SPAD sampling kernel (numba): the primary bits of a chunk of bins and their secondary detections.

Samplers
--------
Drawing one uniform number per pixel per bin costs the same whatever the light level. Here the bins of a chunk
are simulated per output byte (8 pixels) by whichever of two exact samplers is expected to be cheaper, from the
byte's rate bounds (the flux is piecewise linear, so its bounds sit on keyframes): the sparse one while its
expected candidates per bin stay below :data:`DENSE_MIN_CANDIDATES` (or its row has too few such bytes to pay
for the dense loop, :data:`DENSE_MIN_BYTES`), else the dense one.

- *sparse*: the byte's 8 pixels × m bins form one sequence of candidate slots; geometric skips between
  candidates at the byte's largest rate Λ_max (``⌊E/Λ_max⌋``, one ziggurat exponential per candidate,
  :mod:`simspad.physics.ziggurat`) and thinning by ``p_k/p_max`` (a pixel-wise rejection on the upper bound Λ
  and a squeeze on the lower bound before the exact ``p_k``; in rows with many candidates and calls whose runs
  are long, the exact Λ_k comes from a per-row table of each run's ``a + b·dk`` instead of the keyframes,
  :data:`_TABLE_MIN_RUN_BINS`). Work is proportional to detections, plus one
  terminating draw per byte: dark scenes cost almost nothing. A byte whose pixels differ so much (a hot pixel
  among dark ones) that the joint candidates would outnumber per-pixel draws is skipped pixel by pixel, so a hot
  pixel does not make its byte dense;
- *dense*: bin by bin, each pixel's bit compares a 16-bit slice of a random word with ``⌊z_k·2¹⁶⌋``,
  ``z_k = exp(−Λ_k)`` (advanced by one multiplication per bin inside a linear piece, where Λ is affine in k);
  only a tie (probability 2⁻¹⁶) draws the uniform's further bits, so the bit is exactly Bernoulli(1 − z_k) with
  four pixels per 64-bit draw. A row's dense bytes are drawn in one vectorised loop (SplitMix64 draws addressed
  by counter), and the start of each linear piece sets z for the whole row with an inlined exponential
  (:mod:`simspad.physics.vector_exp`). A run of a single bin (a gate straddling a keyframe) computes no per-bin
  factor. That set-up works in the sampler's own [bit, byte] layout, on the dense bytes only: each row's dark term
  and keyframe values are transposed into it once.

Both samplers write a block of rows of every bin into a small L2-resident buffer that is then stored bin by bin
(in place, a byte's bins lie H·ceil(W/8) bytes apart and alias to the same cache sets).

The random stream is a SplitMix64 generator (:mod:`simspad.physics.rng`) inside the numba kernel, seeded per
kernel call from the caller's ``numpy.random.Generator``: one sequential stream, so outputs are bit-identical for
the same seed and chunking (the chunk size is a function of the frame size only).

Where the kernel's time goes, and the alternatives measured against it: docs/performance.md (section "The SPAD
sampling kernel"). The model (Λ_k, secondary effects) is described in :mod:`simspad.sensors.spad.model`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from simspad.physics.rng import GOLDEN_GAMMA, geometric, mix64, uniform
from simspad.physics.vector_exp import exp_fast
from simspad.physics.ziggurat import exponential_zig
from simspad.sensors.spad.dense_bits import M16, dense_bits

#: Per-byte choice of sampler: a byte whose expected sparse candidates per bin reach this uses the dense sampler
#: (whose cost does not depend on the rates), in rows that have :data:`DENSE_MIN_BYTES` such bytes. Measured with
#: the kernel alone on the scene of benchmarks/bench_spad.py (CPU ms per 512 bins of 512×512, median of 4,
#: thresholds 0.6 / 0.4 / 0.3 / 0.2 with 16 bytes, an AMD EPYC with AVX-512): 10.0 / 10.3 / 10.1 / 10.2 at mean
#: P(1) = 0.001, 32.1 / 32.1 / 32.5 / 31.7 at 0.01, 97.5 / 87.7 / 79.4 / 78.9 at 0.05, 105 / 98 / 92 / 89 at 0.1,
#: 165 / 163 / 155 / 154 at 0.9 (8 or 32 bytes instead of 16: no better; the same ranking with numba compiling
#: for AVX2, ``NUMBA_CPU_NAME=haswell``: 95.8 / 85.8 / 80.2 / 78.1 at 0.05). The dense sampler alone costs ≈ 75 ms
#: whatever the rates. An earlier kernel, whose dense loop was not vectorised, measured 0.6 best. The choice
#: fixes which random numbers make which bits, so it is a constant, never tuned at run time: the same spec
#: gives the same bits on every machine.
DENSE_MIN_CANDIDATES = 0.3
#: Dense bytes a row needs before any of its bytes uses the dense sampler (or all of the row's bytes, if fewer):
#: the dense loop costs per bin of the row whatever its number of bytes, and a sparse sampler per candidate.
DENSE_MIN_BYTES = 16
_TWO16 = 65536.0
#: Mean bins per run from which the sparse sampler may tabulate each run's Λ per row: Λ_k = a + b·(k − k_r),
#: one multiply-add from a row-local table instead of a weighted sum of keyframes read from the ring. A row is
#: tabulated when its expected sparse candidates outnumber its run × pixel entries. Kernel alone at mean
#: P(1) = 0.05 on the scene of benchmarks/bench_spad.py: 179 → 175 ms per 512 bins (min of 10, interleaved);
#: unchanged at 0.001 and 0.01, where rows are not tabulated.
_TABLE_MIN_RUN_BINS = 8
#: Bytes of the sampling buffer (all bins of a block of rows), well inside L2.
_BLOCK_BYTES = 512 << 10
_POPCOUNT8 = np.array([bin(i).count("1") for i in range(256)], np.int64)


class ChunkLayout(NamedTuple):
    """Time structure of one kernel call (:func:`simspad.sensors.spad.layout.chunk_layout`): bins grouped in runs
    over which the gate-mean flux is affine in the bin index.

    Bin k belongs to run ``r = bin_run[k]``; its Λ without dark counts is
    ``Σ_t (term_c[t] + (k − run_k0[r])·term_dc[t])·images[term_img[t]]`` over ``t`` in
    ``term_ptr[r] … term_ptr[r+1]−1`` (coefficients in m² s: detection area × gate × weight).
    """

    images: np.ndarray
    """[S, H, W] float32: sensor-plane photon irradiance of keyframes, photons s⁻¹ m⁻² (a ring of slots)."""
    slots: np.ndarray
    """[I] int64: the slots of ``images`` this call uses; they bound every gate mean of the call."""
    run_k0: np.ndarray
    """[R] int64: first bin of each run."""
    term_ptr: np.ndarray
    """[R+1] int64: each run's terms are ``term_ptr[r] … term_ptr[r+1]−1``."""
    term_img: np.ndarray
    """[T] int64: slot of each term's keyframe."""
    term_c: np.ndarray
    """[T] float64: coefficient of each term at its run's first bin, m² s."""
    term_dc: np.ndarray
    """[T] float64: increase of each term's coefficient per bin, m² s."""
    bin_run: np.ndarray
    """[m] int64: run of each bin."""


class PixelResponse(NamedTuple):
    """Per-pixel response of the sensor for one kernel call (named fields: no two floats can swap places)."""

    dcr_cps: np.ndarray
    """[H, W] float32: dark count rate, counts s⁻¹."""
    q_gate_m2_s: float
    """Detection area × gate, m² s: Λ per unit photon irradiance."""
    gate_s: float
    """Gate, s."""
    dense_min_candidates: float
    """Bytes whose expected sparse candidates per bin reach this use the dense sampler."""
    dense_min_bytes: int
    """... but only in rows with at least this many such bytes (the dense loop's cost per bin of a row is not
    worth paying for a few bytes)."""
    log1m_afterpulse: float
    """ln(1 − afterpulsing probability); 0 when the effect is off."""
    log1m_crosstalk: float
    """ln(1 − crosstalk probability) per neighbour; 0 when the effect is off."""


@numba.njit(inline="always")
def _push(events, n_events, k, y, x):
    """Store a secondary detection if the buffer has room; count it either way (the caller then re-runs)."""
    if n_events < events.shape[0]:
        events[n_events, 0] = k
        events[n_events, 1] = y
        events[n_events, 2] = x
    return n_events + 1


@numba.njit(inline="always")
def _secondaries(state, events, n_events, countdown, k, y, x, shape, response):
    """Afterpulse and crosstalk trials of the primary detection at bin k, pixel (y, x).

    ``events`` [capacity, 3] int64 (bin, row, col) is the secondary-detection buffer holding ``n_events``;
    ``countdown`` holds ``(ap_left, ct_left)``: running geometric countdowns, the failures before the next
    success of a stream of Bernoulli trials (1 afterpulse trial and 4 crosstalk trials per detection), so the
    cost is a subtraction per detection, not 5 uniforms. Returns the updated ``(state, n_events, countdown)``.
    """
    ap_left, ct_left = countdown
    H, W = shape
    log1m_ap = response.log1m_afterpulse
    log1m_ct = response.log1m_crosstalk
    if log1m_ap < 0.0:
        if ap_left == 0:
            n_events = _push(events, n_events, k + 1, y, x)
            state, ap_left = geometric(state, log1m_ap)
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
                n_events = _push(events, n_events, k, yy, xx)
            remaining -= ct_left + 1
            nb += 1
            state, ct_left = geometric(state, log1m_ct)
        ct_left -= remaining
    return state, n_events, (ap_left, ct_left)


@numba.njit(inline="always")
def _one_minus_exp_neg(x):
    """1 − e^(−x) for x ≥ 0 to double precision: below 2⁻⁷ its Taylor series to x⁶ (the first term left out is
    < 5·10⁻¹⁷ of the value), ~10× cheaper than ``expm1``, which the sparse sampler called once per byte (≈ 1 ms
    of a 10 ms, 512 × 512 recording at P(1) = 0.001)."""
    if x < 0.0078125:
        return x * (1.0 - x * 0.5 * (1.0 - x * (1.0 / 3.0) * (1.0 - x * 0.25 * (1.0 - x * 0.2
                                                                                  * (1.0 - x * (1.0 / 6.0))))))
    return -math.expm1(-x)


@numba.njit(inline="always")
def _lam(layout, k, y, x, dark):
    """Λ of bin k at pixel (y, x): the weighted sum of its run's keyframes, plus the dark term."""
    r = layout.bin_run[k]
    dk = float(k - layout.run_k0[r])
    lam = dark
    for t in range(layout.term_ptr[r], layout.term_ptr[r + 1]):
        lam += (layout.term_c[t] + dk * layout.term_dc[t]) * float(layout.images[layout.term_img[t], y, x])
    return lam if lam > 0.0 else 0.0


# One kernel (not split further): the sparse and dense samplers share the random stream and the secondary
# countdowns, and separate calls would cost the register-resident state that makes the dense path fast.
@numba.njit(cache=True)
def spad_chunk(out, events, layout, response, seed):
    """Primary bits of one chunk of ``m`` bins into ``out`` [m, H, ceil(W/8)] (every byte written).

    Λ_k = q_gate·mean + dcr·gate_s exactly, with the gate-mean flux of :class:`ChunkLayout` (a weighted sum of
    keyframes; a gate that straddles a keyframe is a run of its own), so the keyframes of the call bound every
    gate mean.

    The sampler is chosen per output byte (8 pixels) by its expected cost: sparse (geometric skips over the
    byte's pixel × bin slots + thinning) while the byte's expected candidates per bin stay below
    ``response.dense_min_candidates`` or its row has fewer than ``response.dense_min_bytes`` bytes that reach it
    (unless those are all of the row's bytes), else dense (bin by bin, with z = exp(−Λ) advanced by one
    multiplication per bin inside a run). The random stream is consumed in that order: row by row, the row's
    sparse bytes in raster order, then its dense bytes.

    Parameters
    ----------
    out : ndarray [m, H, ceil(W/8)] uint8
        Packed bits in the recording's order. The samplers write a block of rows of all bins at a time into a
        zeroed L2-resident buffer (the sparse sampler sets only the bits of its detections, the dense sampler
        writes whole bytes), which is then stored bin by bin.
    events : ndarray [capacity, 3] int64
        Receives the secondary detections (afterpulses in bin k+1, crosstalk to neighbours in bin k) as
        (bin, row, col). A fixed buffer (no array is carried through the loops, which would cost reference
        counting per detection); when it is too small the caller grows it and calls again with the same seed.
    layout : ChunkLayout
    response : PixelResponse
    seed : int
        Seed of this call's SplitMix64 stream.

    Returns
    -------
    int
        Number of secondary detections (those past ``capacity`` were not stored).
    """
    images = layout.images
    dcr = response.dcr_cps
    q_gate = response.q_gate_m2_s
    gate_s = response.gate_s
    log1m_ap = response.log1m_afterpulse
    log1m_ct = response.log1m_crosstalk
    m = out.shape[0]
    slots = layout.slots
    H, W = images.shape[1], images.shape[2]
    shape = (H, W)
    Wb = (W + 7) // 8
    # rows are sampled in blocks into a contiguous [m, rows, Wb] buffer that stays in L2, then stored bin by bin
    # (rows·Wb contiguous bytes each). Written in place, a byte's bins lie H·Wb bytes apart, a multiple of
    # 4 KiB at common widths: they map to the same few cache sets and every detection would miss.
    block_rows = max(1, min(H, _BLOCK_BYTES // max(m * Wb, 1)))
    block = np.empty((m, block_rows, Wb), np.uint8)
    state = np.uint64(seed)
    ap_left = np.int64(1) << 62  # never reaches zero when the effect is off
    ct_left = np.int64(1) << 62
    if log1m_ap < 0.0:
        state, ap_left = geometric(state, log1m_ap)
    if log1m_ct < 0.0:
        state, ct_left = geometric(state, log1m_ct)
    countdown = (ap_left, ct_left)
    n_events = np.int64(0)
    dense_min = response.dense_min_candidates
    dense_min_bytes = response.dense_min_bytes
    lam_hi = np.empty(8, np.float64)
    lam_lo = np.empty(8, np.float64)
    lo_bound = np.empty(8, np.float64)
    dense_b = np.empty(Wb, np.int64)
    byte_candidates = np.empty(Wb, np.float64)  # per byte of the row: expected sparse candidates per bin
    row_hi = np.empty(W, np.float32)
    row_lo = np.empty(W, np.float32)
    # the dense bytes' pixels transposed to [bit, i] (bit b of the row's i-th dense byte), once per row: the dark
    # term and each keyframe slot the call uses (0 past the right edge: z = 1 there, never a detection nor a tie)
    dark_t = np.empty((8, Wb), np.float64)
    img_t = np.empty((images.shape[0], 8, Wb), np.float64)
    bin_run = layout.bin_run
    # the sparse sampler's exact Λ (thinning) from a per-row table of each run's a + b·dk, when the call has few
    # runs (keyframes far apart); with a run every few bins the table would cost more than it saves
    n_runs = len(layout.run_k0)
    tabulated = n_runs * _TABLE_MIN_RUN_BINS <= m
    run_a = np.empty((n_runs if tabulated else 0, W), np.float64)
    run_b = np.empty((n_runs if tabulated else 0, W), np.float64)
    # dense bytes: z·2¹⁶ and its per-bin factor for bit b of the row's i-th dense byte, the byte of each bin
    t16 = np.empty((8, Wb), np.float64)
    f16 = np.empty((8, Wb), np.float64)
    hits = np.empty(Wb, np.uint8)
    words0 = np.empty(Wb, np.uint64)
    words1 = np.empty(Wb, np.uint64)
    for i in range(Wb):
        words0[i] = np.uint64(2 * i + 1) * GOLDEN_GAMMA
        words1[i] = np.uint64(2 * i + 2) * GOLDEN_GAMMA
    for y in range(H):
        row_in_block = y % block_rows
        if row_in_block == 0:
            block[:] = 0
        n_dense = 0
        # the row's flux bounds over the call's keyframes, keyframe by keyframe (contiguous: the loops vectorise)
        first = slots[0]
        for x in range(W):
            v = images[first, y, x]
            row_hi[x] = v if v > 0.0 else np.float32(0.0)
            row_lo[x] = v
        for j in range(1, len(slots)):
            i = slots[j]
            for x in range(W):
                v = images[i, y, x]
                row_hi[x] = v if v > row_hi[x] else row_hi[x]
                row_lo[x] = v if v < row_lo[x] else row_lo[x]
        # expected candidates per bin of each byte: jointly at the byte's largest rate, or pixel by pixel (a hot
        # pixel among dark ones); the row's bytes that reach dense_min go dense only if there are enough of them
        # to pay for the dense loop
        n_qualify = 0
        for xb in range(Wb):
            hi_byte = 0.0
            sum_hi = 0.0
            for x in range(8 * xb, min(8 * xb + 8, W)):
                lam = q_gate * float(row_hi[x]) + float(dcr[y, x]) * gate_s
                hi_byte = max(hi_byte, lam)
                sum_hi += lam
            byte_candidates[xb] = min(8.0 * hi_byte, sum_hi)
            if byte_candidates[xb] >= dense_min:
                n_qualify += 1
        row_dense_min = dense_min if n_qualify >= min(dense_min_bytes, Wb) else math.inf
        # the table costs a few operations per run and pixel: worth it when the row's sparse candidates (about
        # as many exact Λ) outnumber them
        row_candidates = 0.0
        for xb in range(Wb):
            if byte_candidates[xb] < row_dense_min:
                row_candidates += byte_candidates[xb]
        row_tabulated = tabulated and m * row_candidates >= n_runs * W
        if row_tabulated:  # Λ = a + b·dk of each run, all pixels at once (vectorised)
            for r in range(n_runs):
                for x in range(W):
                    run_a[r, x] = float(dcr[y, x]) * gate_s
                    run_b[r, x] = 0.0
                for term in range(layout.term_ptr[r], layout.term_ptr[r + 1]):
                    c = layout.term_c[term]
                    dc = layout.term_dc[term]
                    img = layout.term_img[term]
                    for x in range(W):
                        v = float(images[img, y, x])
                        run_a[r, x] += c * v
                        run_b[r, x] += dc * v
        for xb in range(Wb):
            # the dense sampler costs the same whatever the rates
            if byte_candidates[xb] >= row_dense_min:
                dense_b[n_dense] = xb
                n_dense += 1
                continue
            x_end = min(8, W - 8 * xb)
            hi_byte = 0.0
            sum_hi = 0.0
            for bit in range(8):
                lam_hi[bit] = 0.0  # pixels past the right edge: never a detection
                lam_lo[bit] = 0.0
            for bit in range(x_end):
                x = 8 * xb + bit
                hi = float(row_hi[x])
                lo = float(row_lo[x])
                dark = float(dcr[y, x]) * gate_s
                lam_hi[bit] = q_gate * hi + dark
                lam_lo[bit] = max(q_gate * lo + dark, 0.0)
                hi_byte = max(hi_byte, lam_hi[bit])
                sum_hi += lam_hi[bit]
            joint = 8.0 * m * hi_byte <= m * sum_hi + 7.0
            if hi_byte <= 0.0:
                continue
            # sparse: candidate slots over the byte's 8 pixels × m bins (s = 8·k + bit) at the byte's largest rate,
            # or pixel by pixel (s = k)
            for bit in range(8):
                lo = lam_lo[bit]
                lo_bound[bit] = lo * (1.0 - 0.5 * lo)  # 1 − e^(−Λ) ≥ Λ − Λ²/2: a lower bound of every p_k
            for g in range(1 if joint else x_end):
                rate = hi_byte if joint else lam_hi[g]
                if rate <= 0.0:
                    continue
                p_max = _one_minus_exp_neg(rate)
                inv_lam = 1.0 / rate
                n_slots = 8 * m if joint else m
                s = np.int64(-1)
                while True:
                    state, e = exponential_zig(state)  # no logarithm in ~99 % of draws
                    skip = e * inv_lam
                    if skip >= n_slots - 1 - s:
                        break
                    s += 1 + np.int64(skip)
                    k = s >> 3 if joint else s
                    bit = s & 7 if joint else g
                    # thinning: keep with p_k / p_max. The squeeze (below a lower bound of every p_k) accepts
                    # most candidates without evaluating p_k, so it is tested first: one well-predicted branch
                    # for them (same decisions as rejecting first; kernel alone at P(1) = 0.001: −8 to −14 %);
                    # above it, p_k ≤ Λ_k ≤ lam_hi rejects most of a dim pixel's candidates
                    state, u = uniform(state)
                    up = u * p_max
                    x = 8 * xb + bit
                    if up >= lo_bound[bit]:
                        if up >= lam_hi[bit]:
                            continue
                        if row_tabulated:
                            r = bin_run[k]
                            lam = max(run_a[r, x] + float(k - layout.run_k0[r]) * run_b[r, x], 0.0)
                        else:
                            lam = _lam(layout, k, y, x, float(dcr[y, x]) * gate_s)
                        # p_k = 1 − e^(−Λ) lies in [Λ − Λ²/2, Λ]: the exponential only inside that band
                        if up >= lam or (up >= lam * (1.0 - 0.5 * lam) and up >= -math.expm1(-lam)):
                            continue
                    block[k, row_in_block, xb] |= np.uint8(1 << bit)
                    ap_left, ct_left = countdown
                    if ap_left < 1 or ct_left < 4:  # a secondary is due (the buffer is touched only then)
                        state, n_events, countdown = _secondaries(state, events, n_events, countdown, k, y, x,
                                                                  shape, response)
                    else:
                        countdown = (ap_left - 1, ct_left - 4)
        # the dense bytes, bin by bin: 4 pixels per 64-bit draw, the draws of a bin addressed by counter
        # (state + j·γ), so the loop over bytes vectorises
        if n_dense > 0:
            for bit in range(8):
                for i in range(n_dense):
                    x = 8 * dense_b[i] + bit
                    dark_t[bit, i] = float(dcr[y, x]) * gate_s if x < W else 0.0
            for j in range(len(slots)):
                slot = slots[j]
                for bit in range(8):
                    for i in range(n_dense):
                        x = 8 * dense_b[i] + bit
                        img_t[slot, bit, i] = float(images[slot, y, x]) if x < W else 0.0
        for k in range(m if n_dense > 0 else 0):
            r = bin_run[k]
            if k == 0 or r != bin_run[k - 1]:  # a new run: exact Λ and its per-bin ratio
                # Λ and its slope for the dense pixels, term by term in the transposed layout (vectorised); the
                # same operations in the same order per pixel as a pixel-order loop, so the same values
                dk = float(k - layout.run_k0[r])
                for bit in range(8):
                    for i in range(n_dense):
                        t16[bit, i] = dark_t[bit, i]
                        f16[bit, i] = 0.0
                for term in range(layout.term_ptr[r], layout.term_ptr[r + 1]):
                    c = layout.term_c[term] + dk * layout.term_dc[term]
                    dc = layout.term_dc[term]
                    img = layout.term_img[term]
                    for bit in range(8):
                        for i in range(n_dense):
                            v = img_t[img, bit, i]
                            t16[bit, i] += c * v
                            f16[bit, i] += dc * v
                # z·2¹⁶ and the per-bin factor (an inlined exponential: the loop vectorises); a run of one bin (a
                # gate straddling a keyframe: about every other run when keyframes are 1 ms apart) needs no
                # factor, and its exponentials are half the set-up
                one_bin = (layout.run_k0[r + 1] if r + 1 < n_runs else m) == k + 1
                for bit in range(8):
                    for i in range(n_dense):
                        t16[bit, i] = _TWO16 * exp_fast(-max(t16[bit, i], 0.0))
                if one_bin:
                    for bit in range(8):
                        for i in range(n_dense):
                            f16[bit, i] = 1.0
                else:
                    for bit in range(8):
                        for i in range(n_dense):
                            f16[bit, i] = exp_fast(-f16[bit, i])
            total, ties = dense_bits(words0, words1, t16, hits, n_dense, state)
            state_bin = state
            state += np.uint64(2 * n_dense) * GOLDEN_GAMMA
            if ties > 0:  # a 16-bit slice equal to ⌊z·2¹⁶⌋: the uniform's further bits decide (u ≥ z)
                for i in range(n_dense):
                    for bit in range(8):
                        w = mix64(state_bin + (words0[i] if bit < 4 else words1[i]))
                        u16 = float((w >> np.uint64(16 * (bit & 3))) & M16)
                        t = t16[bit, i]
                        if u16 == math.floor(t):
                            state, rest = uniform(state)
                            if rest >= t - u16:  # exact: t − ⌊t⌋ is representable
                                hits[i] |= np.uint8(1 << bit)
                                total += 1
            for bit in range(8):
                for i in range(n_dense):
                    t16[bit, i] *= f16[bit, i]
            for i in range(n_dense):
                block[k, row_in_block, dense_b[i]] = hits[i]
            ap_left, ct_left = countdown
            if ap_left >= total and ct_left >= 4 * total:  # no secondary due in this row of this bin
                countdown = (ap_left - total, ct_left - 4 * total)
                continue
            for i in range(n_dense):
                value = np.int64(hits[i])
                count = np.int64(_POPCOUNT8[value])
                ap_left, ct_left = countdown
                if ap_left < count or ct_left < 4 * count:  # a secondary is due: resolve pixel by pixel
                    for bit in range(8):
                        if (value >> bit) & 1:
                            state, n_events, countdown = _secondaries(state, events, n_events, countdown, k,
                                                                      y, 8 * dense_b[i] + bit, shape,
                                                                      response)
                else:
                    countdown = (ap_left - count, ct_left - 4 * count)
        if row_in_block == block_rows - 1 or y == H - 1:  # the block is complete: store its rows of every bin
            y0 = y - row_in_block
            for k in range(m):
                for j in range(row_in_block + 1):
                    for xb in range(Wb):
                        out[k, y0 + j, xb] = block[k, j, xb]
    return n_events


@numba.njit(cache=True)
def apply_events(out, events, k_offset):
    """OR secondary detections ``events`` [n, 3] (bin, row, col) into ``out``; return those past its last bin
    (bins shifted by ``-k_offset``)."""
    m = out.shape[0]
    n_events = events.shape[0]
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

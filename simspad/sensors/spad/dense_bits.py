"""The SPAD dense sampler's bits for one bin of a row: 8 exact Bernoulli bits per byte from two 64-bit draws.

Each 64-bit SplitMix64 draw (addressed by counter, so the loop over bytes vectorises) gives four 16-bit slices.
A pixel's bit is 1 when the uniform its slice starts, u = (slice + rest)/2¹⁶, is ≥ z = exp(−Λ): a slice above
⌊z·2¹⁶⌋ decides 1 and one below decides 0 whatever the rest; only a tie (probability 2⁻¹⁶) needs the uniform's
further bits, which the kernel (:mod:`simspad.sensors.spad.kernel`) draws. Four pixels per draw and integer
compares, against two pixels per draw and float conversions for 32-bit uniforms.
"""

from __future__ import annotations

import numba
import numpy as np

from simspad.physics.rng import mix64

_S0 = np.uint64(0)
_S16 = np.uint64(16)
_S32 = np.uint64(32)
_S48 = np.uint64(48)
#: One 16-bit slice of a draw.
M16 = np.uint64(0xFFFF)


@numba.njit(inline="always")
def _lane_hit(word, shift, t16):
    """(hit, tie) of the 16-bit slice at ``shift`` against ``t16 = z·2¹⁶``: hit = 1 when the slice alone decides
    u ≥ z, tie = 1 when it equals ⌊z·2¹⁶⌋ (then the uniform's further bits decide)."""
    u = np.int64((word >> shift) & M16)
    threshold = np.int64(t16)  # ⌊z·2¹⁶⌋ (t16 ≥ 0)
    return np.int64(u > threshold), np.int64(u == threshold)


@numba.njit(inline="always")
def dense_bits(words0, words1, t16, hits, n_dense, state):
    """One bin of a row's dense bytes: 8 Bernoulli bits per byte from two counter-addressed 64-bit draws.

    Bit ``b`` of dense byte ``i`` compares the ``b mod 4``-th 16-bit slice of draw ``2i + b // 4`` with
    ``t16[b, i] = z·2¹⁶`` (z = exp(−Λ)): the bit is 1 when the uniform it starts, u = (slice + rest)/2¹⁶, is
    ≥ z. A slice above ⌊z·2¹⁶⌋ decides 1 and one below decides 0 whatever the rest; only a tie (probability
    2⁻¹⁶) needs more bits, drawn by the caller. Returns (ones decided, ties).
    """
    total = np.int64(0)
    ties = np.int64(0)
    for i in range(n_dense):
        w0 = mix64(state + words0[i])
        w1 = mix64(state + words1[i])
        h0, e0 = _lane_hit(w0, _S0, t16[0, i])
        h1, e1 = _lane_hit(w0, _S16, t16[1, i])
        h2, e2 = _lane_hit(w0, _S32, t16[2, i])
        h3, e3 = _lane_hit(w0, _S48, t16[3, i])
        h4, e4 = _lane_hit(w1, _S0, t16[4, i])
        h5, e5 = _lane_hit(w1, _S16, t16[5, i])
        h6, e6 = _lane_hit(w1, _S32, t16[6, i])
        h7, e7 = _lane_hit(w1, _S48, t16[7, i])
        hits[i] = np.uint8(h0 | (h1 << 1) | (h2 << 2) | (h3 << 3) | (h4 << 4) | (h5 << 5) | (h6 << 6) | (h7 << 7))
        total += h0 + h1 + h2 + h3 + h4 + h5 + h6 + h7
        ties += e0 + e1 + e2 + e3 + e4 + e5 + e6 + e7
    return total, ties

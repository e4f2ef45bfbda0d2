"""Per-knot quantities of a tile of pixels, computed ahead of the event kernel's sequential per-pixel loop.

The kernel (:mod:`.kernel`) advances each pixel through its keyframe pieces one after the other: every value it
computes feeds the next, so a ``log`` or a division inside that loop sits on its dependency chain and costs its full
latency. What depends only on the knots — ln I and the shot-noise factor ``I^(−γ/2)`` at each knot, the slope of the
photocurrent and its inverse over each piece — is computed here for a tile of pixels first, in loops whose
iterations are independent (the CPU overlaps them), with the very same expressions, so the kernel's results are
bit-identical to computing them in place.
"""

from __future__ import annotations

import math

import numba

from simspad.physics.photoreceptor import MIN_CURRENT_E_S

#: Pixels per tile: the tile's tables (4 × knots × tile float64) stay in the L1/L2 cache for a chunk's knots.
TILE_PIXELS = 32


@numba.njit(cache=True, error_model="numpy")
def fill_knot_table(knot_t, knot_current, p_lo, p_hi, shot_exp, current_i, log_i, g_i, slope, inv_abs_slope):
    """Fill rows ``0 … p_hi − p_lo − 1`` of the tables for pixels ``p_lo … p_hi − 1``.

    The photocurrent comes knot-major, as the timeline gives it (no transposed copy of a chunk is made): a tile
    reads a short contiguous run of each knot's row, and from then on the kernel reads only the tile's tables.

    Parameters
    ----------
    knot_t : ndarray [m+1]
        Knot instants, s.
    knot_current : ndarray [m+1, H·W]
        Photocurrent at the knots, e⁻ s⁻¹.
    shot_exp : float
        ``γ``, the shot-noise exponent.
    current_i, log_i, g_i : ndarray [tile, m+1]
        Out: the photocurrent clamped to ``MIN_CURRENT_E_S`` (e⁻ s⁻¹), ``ln I`` and ``I^(−γ/2) = exp(−γ/2 · ln I)``
        at each knot.
    slope, inv_abs_slope : ndarray [tile, m]
        Out: ``dI/dt`` over each piece (e⁻ s⁻²; 0 for an empty piece) and ``1/|dI/dt|`` (0 where the slope is 0).
    """
    n_knots = knot_t.size
    n = p_hi - p_lo
    # knot by knot, the tile's pixels inner: each knot's row is read as one contiguous run (rows a multiple of 4 KiB
    # apart, read pixel by pixel, would all fall in the same L1 cache set)
    for j in range(n_knots):
        row = knot_current[j, p_lo:p_hi]
        for q in range(n):
            ib = max(row[q], MIN_CURRENT_E_S)
            current_i[q, j] = ib
            lg = math.log(ib)
            log_i[q, j] = lg
            g_i[q, j] = math.exp(-0.5 * shot_exp * lg)
    for j in range(n_knots - 1):
        seg = knot_t[j + 1] - knot_t[j]
        for q in range(n):
            s = (current_i[q, j + 1] - current_i[q, j]) / seg if seg > 0.0 else 0.0
            slope[q, j] = s
            inv_abs_slope[q, j] = 1.0 / abs(s) if s != 0.0 else 0.0

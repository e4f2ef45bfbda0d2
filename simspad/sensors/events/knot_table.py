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
def fill_knot_table(knot_t, knot_current, p_lo, p_hi, shot_exp, log_i, g_i, slope, inv_abs_slope):
    """Fill rows ``0 … p_hi − p_lo − 1`` of the tables for pixels ``p_lo … p_hi − 1``.

    Parameters
    ----------
    knot_t : ndarray [m+1]
        Knot instants, s.
    knot_current : ndarray [H·W, m+1]
        Photocurrent at the knots, e⁻ s⁻¹ (clamped to ``MIN_CURRENT_E_S`` here, as in the kernel).
    shot_exp : float
        ``γ``, the shot-noise exponent.
    log_i, g_i : ndarray [tile, m+1]
        Out: ``ln I`` and ``I^(−γ/2) = exp(−γ/2 · ln I)`` at each knot.
    slope, inv_abs_slope : ndarray [tile, m]
        Out: ``dI/dt`` over each piece (e⁻ s⁻²; 0 for an empty piece) and ``1/|dI/dt|`` (0 where the slope is 0).
    """
    n_knots = knot_t.size
    for q in range(p_hi - p_lo):
        p = p_lo + q
        ia = max(knot_current[p, 0], MIN_CURRENT_E_S)
        lg = math.log(ia)
        log_i[q, 0] = lg
        g_i[q, 0] = math.exp(-0.5 * shot_exp * lg)
        for j in range(n_knots - 1):
            ib = max(knot_current[p, j + 1], MIN_CURRENT_E_S)
            lg = math.log(ib)
            log_i[q, j + 1] = lg
            g_i[q, j + 1] = math.exp(-0.5 * shot_exp * lg)
            seg = knot_t[j + 1] - knot_t[j]
            s = (ib - ia) / seg if seg > 0.0 else 0.0
            slope[q, j] = s
            inv_abs_slope[q, j] = 1.0 / abs(s) if s != 0.0 else 0.0
            ia = ib

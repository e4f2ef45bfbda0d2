"""Threshold crossings of the change detector inside one internal step, solved to 1 ns.

Inside a step of length ``h`` the photoreceptor output follows its exact path for an input whose log is linear in
time, so with ``x = s − t`` the detector is

    D(x) = A + B·x + c·exp(−x/τ)        (a :class:`Detector`)

with at most one stationary point (``D' = B − (c/τ)·exp(−x/τ)`` is monotone). Each crossing — several per step
included — is solved on its monotone piece: closed form once the transient has decayed, Halley iterations (one
exp gives D, D' and D'') otherwise, so a crossing costs about two exp.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

ROOT_TOL_S = 1e-9  # s: crossing instants are solved to this (timestamps are whole µs) ...
ROOT_TOL_LOG = 1e-9  # ... or until the detector is this close to the threshold (log units)


class Detector(NamedTuple):
    """The change detector over one step, ``D(x) = offset + slope·x + transient·exp(−x/tau_s)``, x in s."""

    offset: float
    """``A``, log units."""
    slope: float
    """``B``, log units s⁻¹."""
    transient: float
    """``c``, the photoreceptor transient at the step's start, log units."""
    tau_s: float
    """Photoreceptor time constant over the step, s."""


@numba.njit(cache=True, error_model="numpy")
def solve_monotone(det, lo, hi, f_lo, f_hi, level, tr_lo):
    """Root of D(x) = level on [lo, hi] where D (a :class:`Detector`) is monotone.

    ``f_lo``, ``f_hi`` are D − level at the ends (opposite signs, or zero); ``tr_lo`` = c·exp(−lo/τ), the
    photoreceptor transient at ``lo`` (the caller has it already). Once the transient has decayed below the
    tolerance D is linear and the root is closed-form; otherwise Halley steps from the secant point, kept inside
    the shrinking bracket (bisection when a step leaves it). One exp gives D, D' and D'' (cubic convergence);
    a step is taken without a further evaluation when it, or its predicted error K·step³ (×10 margin), is
    below the tolerance.
    """
    a_off, b_slope, c, tau = det.offset, det.slope, det.transient, det.tau_s
    if f_lo == 0.0:
        return lo
    if f_hi == 0.0:
        return hi
    if abs(tr_lo) <= ROOT_TOL_LOG:
        return min(max(lo - f_lo / b_slope, lo), hi)
    inv_tau = 1.0 / tau
    x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
    for _ in range(100):
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        e = c * math.exp(-x * inv_tau)
        f_x = a_off + b_slope * x + e - level
        if abs(f_x) <= ROOT_TOL_LOG or hi - lo < ROOT_TOL_S:
            return x
        if (f_x > 0.0) == (f_lo > 0.0):
            lo, f_lo = x, f_x
        else:
            hi = x
        d1 = b_slope - e * inv_tau
        if d1 == 0.0:
            x = 0.5 * (lo + hi)
            continue
        d2 = e * inv_tau * inv_tau
        if abs(f_x * d2) <= d1 * d1:  # near the root: Halley, error after the step ≈ K·step³
            step = 2.0 * f_x * d1 / (2.0 * d1 * d1 - f_x * d2)
            r2 = d2 / d1  # K = (D2/D1)²/4 − D3/(6·D1), and D3 = −D2/τ here
            err = (0.25 * r2 * r2 + abs(r2 * inv_tau) / 6.0) * abs(step) ** 3
        else:  # far out on the flat tail Halley creeps by ~2τ a step; Newton overshoots into a bisection
            step = f_x / d1
            err = np.inf
        x = x - step
        if (abs(step) <= ROOT_TOL_S or 10.0 * err <= ROOT_TOL_S) and lo <= x <= hi:
            return x
    return x


@numba.njit(cache=True, error_model="numpy")
def first_crossing(det, x0, h, d0, dh, theta_on, theta_off, tr0, trh):
    """First x in (x0, h] where D(x) (a :class:`Detector`) reaches θ_on or −θ_off.

    D has at most one stationary point (D' = b_slope − (c/τ)·exp(−x/τ) is monotone), so [x0, h] splits into at
    most two monotone pieces; the first piece whose far end is beyond a threshold holds the crossing.
    ``d0``, ``dh`` are D at x0 and h; ``tr0``, ``trh`` the transient c·exp(−x/τ) there: D' has a root inside only
    if its end values differ in sign, so the log that locates it is taken only then.
    Returns ``(x, polarity)`` or ``(-1, 0)``; requires −θ_off < D(x0) < θ_on.
    """
    a_off, b_slope, c, tau = det.offset, det.slope, det.transient, det.tau_s
    xs = -1.0
    if c != 0.0 and b_slope != 0.0 and (b_slope - tr0 / tau > 0.0) != (b_slope - trh / tau > 0.0):
        r = b_slope * tau / c
        if r > 0.0:
            x_stat = -tau * math.log(r)
            if x0 < x_stat < h:
                xs = x_stat
    lo, f_lo, tr_lo = x0, d0, tr0
    for piece in range(2):
        if piece == 0 and xs > 0.0:
            hi = xs
            f_hi = a_off + b_slope * xs + b_slope * tau  # c·exp(−xs/τ) = b_slope·τ there
        elif piece == 0 or xs > 0.0:  # the only piece, or the one after the stationary point
            hi, f_hi = h, dh
        else:
            break
        if f_hi >= theta_on:
            return solve_monotone(det, lo, hi, f_lo - theta_on, f_hi - theta_on, theta_on, tr_lo), 1
        if f_hi <= -theta_off:
            return solve_monotone(det, lo, hi, f_lo + theta_off, f_hi + theta_off, -theta_off, tr_lo), 0
        lo, f_lo, tr_lo = hi, f_hi, b_slope * tau
    return -1.0, 0

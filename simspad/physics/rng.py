"""Counter-based random numbers for numba kernels: SplitMix64 and the draws the sensor kernels take from it.

Each pixel (or block) of a kernel carries its own 64-bit state, seeded from the recording's keyed stream
(:mod:`simspad.physics.seeding`), so results do not depend on thread count or scheduling. The functions are
``inline="always"``: they compile into each kernel with no call overhead. Each returns ``(new_state, value)``.

SplitMix64: Steele, Lea & Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014 (the
finaliser of Java's ``SplittableRandom``). Normal quantile: P. J. Acklam's rational approximation (relative
error < 1.2e-9).
"""

from __future__ import annotations

import math

import numba
import numpy as np

GOLDEN_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
#: 2⁻⁵³: one unit in the last place of a uniform with 53-bit resolution.
INV_2_53 = 1.0 / 9007199254740992.0


@numba.njit(cache=True, inline="always")
def next_u64(state):
    """SplitMix64 step: (new state, 64 random bits)."""
    state = state + GOLDEN_GAMMA
    z = state
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return state, z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def mix64(z):
    """SplitMix64's output function: the j-th draw after state s is ``mix64(s + j·GOLDEN_GAMMA)``.

    Draws so addressed do not depend on each other, so a loop over them vectorises (same values as
    :func:`next_u64` called j times).
    """
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def uniform(state):
    """(new state, u) with u uniform in [0, 1), 53-bit resolution."""
    state, z = next_u64(state)
    return state, float(z >> _S11) * INV_2_53


@numba.njit(cache=True, inline="always")
def uniform_positive(state):
    """(new state, u) with u uniform in (0, 1], 53-bit resolution: safe under a logarithm."""
    state, z = next_u64(state)
    return state, ((z >> _S11) + np.uint64(1)) * INV_2_53


@numba.njit(cache=True, inline="always")
def exponential(state):
    """(new state, x) with x exponential of unit mean."""
    state, u = uniform_positive(state)
    return state, -math.log(u)


@numba.njit(cache=True, inline="always")
def geometric(state, log1m_p):
    """(new state, failures before the next success) of Bernoulli trials with log(1 − p) = ``log1m_p`` (< 0).

    Capped at 4·10¹⁸ so the result fits an int64.
    """
    state, u = uniform(state)
    g = math.log(1.0 - u) / log1m_p  # 1 − u is exact and > 0; log is ~3× cheaper than log1p
    if g > 4.0e18:
        g = 4.0e18
    return state, np.int64(g)


# Acklam's coefficients. One uniform per draw and no transcendental call in the central 95 %, where Box-Muller
# needs a log, a sqrt and a cos for every draw.
_ACK_A = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02, 1.383577518672690e+02,
          -3.066479806614716e+01, 2.506628277459239e+00)
_ACK_B = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02, 6.680131188771972e+01,
          -1.328068155288572e+01)
_ACK_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00, -2.549732539343734e+00,
          4.374664141464968e+00, 2.938163982698783e+00)
_ACK_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00)
_ACK_LOW = 0.02425


@numba.njit(cache=True, inline="always")
def normal_quantile(u):
    """Standard normal quantile of u in (0, 1) (Acklam)."""
    a, b, c, d = _ACK_A, _ACK_B, _ACK_C, _ACK_D
    if u < _ACK_LOW or u > 1.0 - _ACK_LOW:
        q = math.sqrt(-2.0 * math.log(min(u, 1.0 - u)))
        z = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
        return z if u < _ACK_LOW else -z
    q = u - 0.5
    r = q * q
    return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q / \
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)


@numba.njit(cache=True, inline="always")
def normal(state):
    """(new state, z) with z standard normal, from one uniform in the open interval (0, 1)."""
    state, z = next_u64(state)
    return state, normal_quantile(((z >> _S11) + 0.5) * INV_2_53)

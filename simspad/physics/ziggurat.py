"""Exponential random numbers by the ziggurat method, for numba kernels (one 64-bit draw and one multiply in
~99 % of cases; no logarithm).

Marsaglia & Tsang, "The ziggurat method for generating random variables", J. Stat. Softw. 5(8), 2000: the
density e^(−x) is covered by 256 strips of equal area; a draw picks a strip with 8 random bits and a point in it
with the other 56; points inside the strip's inner rectangle (the common case) are accepted at once, the rest are
resolved exactly against e^(−x) (wedges) or by the tail's own exponential. The sampler is exact: the strips only
decide how often the slow path runs. Resolution: 56 bits within a strip (−log of a 53-bit uniform, its
alternative, also caps the tail at 36.7).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from simspad.physics.rng import INV_2_53, next_u64

_R = 7.69711747013104972  # right edge of the base strip
_V = 3.949659822581572e-3  # area of each strip
_SCALE = 2.0**56
_S8 = np.uint64(8)
_M8 = np.uint64(0xFF)
_S11 = np.uint64(11)


def _tables():
    k = np.zeros(256, np.uint64)  # acceptance bounds (56-bit) of the inner rectangles
    w = np.zeros(256, np.float64)  # x per unit of the 56-bit draw in each strip
    f = np.zeros(256, np.float64)  # e^(−x) at each strip's edge
    de = _R
    te = de
    q = _V / math.exp(-de)
    k[0] = np.uint64(int((de / q) * _SCALE))
    k[1] = 0
    w[0] = q / _SCALE
    w[255] = de / _SCALE
    f[0] = 1.0
    f[255] = math.exp(-de)
    for i in range(254, 0, -1):
        de = -math.log(_V / de + math.exp(-de))
        k[i + 1] = np.uint64(int((de / te) * _SCALE))
        te = de
        f[i] = math.exp(-de)
        w[i] = de / _SCALE
    return k, w, f


_K, _W, _F = _tables()


@numba.njit(cache=True, inline="always")
def exponential_zig(state):
    """(new state, x) with x exponential of unit mean (SplitMix64 draws; usually exactly one)."""
    while True:
        state, z = next_u64(state)
        i = z & _M8
        j = z >> _S8  # 56 bits
        if j < _K[i]:
            return state, float(j) * _W[i]
        if i == 0:  # the tail beyond the base strip's edge: exponential again, shifted (memorylessness)
            state, z = next_u64(state)
            u = (float(z >> _S11) + 1.0) * INV_2_53  # in (0, 1]
            return state, _R - math.log(u)
        x = float(j) * _W[i]
        state, z = next_u64(state)
        u = float(z >> _S11) * INV_2_53
        if _F[i] + u * (_F[i - 1] - _F[i]) < math.exp(-x):  # under the density within the wedge
            return state, x

"""NumPy's pairwise summation, for numba kernels that must add in NumPy's order.

A kernel replacing ``a.sum()`` or ``a.mean()`` by a plain loop changes the result in the last bits; these
functions add ``a[lo:lo + n]`` (1-D, contiguous) exactly as NumPy's reduction inner loop does, so a kernel can
reproduce an array expression to the last bit. NumPy reduces a contiguous run pairwise (blocks of at most 128
values, eight partial sums in each); a sum over a 2-D array whose rows are not contiguous adds row sums one after
the other. Checked against NumPy in ``tests/physics/test_pairwise_sum.py``.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def pairwise_block(a, lo, n):
    """NumPy's sum of ``a[lo:lo + n]`` for n ≤ 128: sequential below 8 values, else eight interleaved partial
    sums added as ((0 + 1) + (2 + 3)) + ((4 + 5) + (6 + 7)), then the remainder."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i + 8 <= n:
        j = lo + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True, inline="always")
def pairwise_sum(a, lo, n):
    """NumPy's pairwise sum of ``a[lo:lo + n]`` (what ``sum`` does along a contiguous axis): blocks of at most 128
    values, longer runs split in halves (the first a multiple of 8) and the halves' sums added.

    Inlined into its callers, so that a kernel summing many short runs (QBP's tile rows of 16 values) pays no
    call for them: that call was a fifth of QBP's Lucas–Kanade kernel. Longer runs go to :func:`_pairwise_halves`.
    """
    if n <= 128:
        return pairwise_block(a, lo, n)
    return _pairwise_halves(a, lo, n)


@numba.njit(cache=True)
def _pairwise_halves(a, lo, n):
    """:func:`pairwise_sum` of a run longer than 128 values. The halving runs on an explicit stack: numba functions
    that call themselves crash when loaded from numba's cache."""
    depth = 64
    los = np.empty(depth, np.int64)
    ns = np.empty(depth, np.int64)
    left = np.empty(depth)
    stage = np.zeros(depth, np.int64)  # 0: left half pending, 1: right half pending
    top = 0
    los[0], ns[0], stage[0] = lo, n, 0
    val = 0.0
    while True:
        m = ns[top]
        if m <= 128:
            val = pairwise_block(a, los[top], m)
            top -= 1
            # hand the value to the parents until one still has its right half to do
            while top >= 0 and stage[top] == 1:
                val = left[top] + val
                top -= 1
            if top < 0:
                return val
            left[top] = val
            stage[top] = 1
            half = ns[top] // 2
            half -= half % 8
            los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, ns[top] - half, 0
            top += 1
        else:
            half = m // 2
            half -= half % 8
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1

"""Packed event code: an event's pixel, polarity and label in one int64, ``pixel·8 + polarity·4 + label``.

The code travels from the kernel (:mod:`.kernel`) through the bucket sort (:mod:`.sort`): two scattered stores per
event instead of four. It is unpacked once, in parallel, over the sorted rows.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def pack_code(pixel, polarity, label):
    """``pixel·8 + polarity·4 + label`` as one int64."""
    return (np.int64(pixel) << 3) | (np.int64(polarity) << 2) | np.int64(label)


@numba.njit(cache=True, parallel=True)
def unpack_codes(t_s, pix, lo):
    """Unpack rows ``lo …`` of events given as time (s) and packed code, in parallel; ``pix`` holds the codes on
    entry and the pixel indices on return (no separate code array to allocate and fault in).

    Returns
    -------
    t_us, pol, lab : ndarray
        µs timestamps (floor of t·10⁶, as :func:`~.simulator.timestamps_us`), polarity and label. Rows before
        ``lo`` are left uninitialised: they are the room :meth:`EventSimulator.advance` merges the held-back events
        into.
    """
    n = pix.size
    t_us = np.empty(n, np.int64)
    pol = np.empty(n, np.uint8)
    lab = np.empty(n, np.uint8)
    for j in numba.prange(n - lo):
        k = lo + j
        t_us[k] = np.int64(math.floor(t_s[k] * 1e6))
        c = pix[k]
        pix[k] = c >> 3
        pol[k] = np.uint8((c >> 2) & 1)
        lab[k] = np.uint8(c & 3)
    return t_us, pol, lab

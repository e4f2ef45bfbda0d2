"""The SPAD stream of a recording (``/spad``): packed binary frames, their start times, the dark count map."""

from __future__ import annotations

from collections import OrderedDict
from typing import Iterator

import numpy as np

from simspad.io.recording.group import GroupView
from simspad.io.recording.samples import SpadBlocks

#: Binary frames read per chunk by default (bounded memory whatever the recording length).
CHUNK_BINS = 1024
#: Most bytes of photon counts :meth:`SpadView.counts` keeps for the next caller asking for the same frames.
COUNTS_CACHE_BYTES = 32 * 2**20


class SpadView(GroupView):
    """``/spad``: binary frames stored 8 pixels a byte along x (little bit order), read in chunks."""

    def __init__(self, h5, path, width: int, height: int):
        super().__init__(h5, path, "spad")
        self._width = width
        self._height = height
        # counts by (start, stop), oldest first: methods scored on one open recording aggregate the same frames
        self._counts: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()

    @property
    def t_start(self) -> np.ndarray:
        """Start time of every binary frame, s."""
        return self._dataset("t_start")[()]

    @property
    def n_bins(self) -> int:
        """Number of binary frames."""
        return int(self._dataset("bits").shape[0])

    @property
    def dcr_cps(self) -> np.ndarray:
        """Dark count rate map, counts s⁻¹."""
        return self._dataset("dcr_cps")[()]

    def bits(self, start: int, stop: int) -> np.ndarray:
        """Binary frames ``start:stop`` unpacked to ``[n,H,W]`` uint8 (0/1)."""
        packed = self._dataset("bits")[start:stop]
        return np.unpackbits(packed, axis=2, count=self._width, bitorder="little")

    def iter_bits(self, start: int = 0, stop: int | None = None,
                  chunk: int = CHUNK_BINS) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_index, bits[n,H,W])`` over ``start:stop`` in chunks of ``chunk`` frames."""
        stop = self.n_bins if stop is None else min(stop, self.n_bins)
        for i in range(start, stop, chunk):
            yield i, self.bits(i, min(i + chunk, stop))

    def counts(self, start: int, stop: int, chunk: int = CHUNK_BINS) -> np.ndarray:
        """Number of ones per pixel over binary frames ``start:stop`` (``[H,W]`` int32), read in chunks.

        The last results (up to ``COUNTS_CACHE_BYTES``) are kept: another method asking for the same frames of this
        open recording gets a copy without decoding the bits again.
        """
        key = (int(start), int(stop))
        hit = self._counts.get(key)
        if hit is not None:
            self._counts.move_to_end(key)
            return hit.copy()
        total = np.zeros((self._height, self._width), np.int32)
        for _, bits in self.iter_bits(start, stop, chunk):
            total += bits.sum(axis=0, dtype=np.int32)
        if total.nbytes <= COUNTS_CACHE_BYTES:
            self._counts[key] = total.copy()
            while len(self._counts) * total.nbytes > COUNTS_CACHE_BYTES:
                self._counts.popitem(last=False)
        return total

    def blocks(self, n_bins: int) -> SpadBlocks:
        """Consecutive blocks of ``n_bins`` binary frames as a lazy sequence of ``(t_start_s, bits[n,H,W])``."""
        return SpadBlocks(self, n_bins)

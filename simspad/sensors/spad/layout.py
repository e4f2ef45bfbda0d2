"""Time layout of one SPAD kernel call: every bin's gate-mean flux as a weighted sum of keyframes.

The flux is piecewise linear between keyframes, so the mean over a gate ``[t, t + gate]`` is exactly a weighted
sum of the keyframes it touches (a convex combination). Consecutive bins whose gates lie inside one linear piece
form a *run*: their weights are affine in the bin index. A gate that straddles a keyframe is a run of its own,
with the exact weights of every piece it overlaps. Nothing here computes an image: the kernel evaluates the weighted
sums only where it needs Λ (the sparse sampler's thinning, the start of a dense run), and the keyframes
themselves, which bound every gate mean of the call, bound Λ.

Keyframes live once each, scaled, in a :class:`KeyframeRing` that consecutive calls share.
"""

from __future__ import annotations

import numpy as np

from simspad.sensors.spad.kernel import ChunkLayout

#: Gate ends this close past a keyframe (relative to the gate) still count as inside its piece (round-off of
#: t0 + k·bin_s).
_INSIDE_TOLERANCE = 1e-6


class KeyframeRing:
    """Scaled keyframes of a timeline in a fixed ring of slots (keyframe ``i`` in slot ``i mod S``).

    A kernel call reads a contiguous range of keyframes and calls move forward in time, so each keyframe is
    read (and decoded) once and kept while later calls still need it; memory is ``S`` images whatever the length.
    """

    def __init__(self, flux_tl, n_slots: int):
        self.tl = flux_tl
        self._alloc(max(1, min(int(n_slots), flux_tl.n_keyframes)))

    def _alloc(self, n_slots: int) -> None:
        self.images = np.empty((n_slots, self.tl.height, self.tl.width), np.float32)
        self._held = np.full(n_slots, -1, np.int64)

    def slots(self, i0: int, i1: int) -> np.ndarray:
        """Slots holding keyframes ``i0 … i1`` (loaded if needed), as an int64 array indexed by ``i − i0``."""
        count = i1 - i0 + 1
        if count > self.images.shape[0]:  # more keyframes in one call than slots: grow (keyframes reloaded)
            self._alloc(count)
        n_slots = self.images.shape[0]
        slots = np.arange(i0, i1 + 1, dtype=np.int64) % n_slots
        for i, s in zip(range(i0, i1 + 1), slots):
            if self._held[s] != i:
                self.tl.keyframe(i, out=self.images[s])
                self._held[s] = i
        return slots


def chunk_layout(ring: KeyframeRing, t_starts: np.ndarray, gate_s: float, bin_s: float,
                 q_gate: float) -> ChunkLayout:
    """:class:`ChunkLayout` of the bins starting at ``t_starts`` (s, evenly spaced by ``bin_s``).

    Λ_k = Σ_t (c_t + (k − k_r)·dc_t)·image_t + dark over the terms t of bin k's run r (coefficients include the
    detection area × gate ``q_gate``, m² s).
    """
    tl = ring.tl
    times = np.asarray(tl.times_s, np.float64)
    m = len(t_starts)
    t_lo, t_hi = float(times[0]), float(times[-1])
    starts = np.clip(t_starts, t_lo, t_hi)
    ends = np.clip(t_starts + gate_s, t_lo, t_hi)
    bin_run = np.empty(m, np.int64)
    run_k0, term_ptr, term_img, term_c, term_dc = [], [0], [], [], []
    if len(times) == 1:  # one keyframe: constant in time
        slots = ring.slots(0, 0)
        bin_run[:] = 0
        return ChunkLayout(images=ring.images, slots=slots, run_k0=np.zeros(1, np.int64),
                           term_ptr=np.array([0, 1], np.int64), term_img=slots.copy(),
                           term_c=np.array([q_gate]), term_dc=np.zeros(1), bin_run=bin_run)
    last_piece = len(times) - 2
    tol = _INSIDE_TOLERANCE * gate_s
    idx = np.clip(np.searchsorted(times, starts + tol, side="right") - 1, 0, last_piece)
    last = np.clip(np.searchsorted(times, ends - tol, side="left") - 1, 0, last_piece)
    inside = ends <= times[idx + 1] + tol
    i0, i1 = int(idx[0]), int(max(last[-1], idx[-1])) + 1
    slots = ring.slots(i0, i1)
    j = 0
    while j < m:
        i = int(idx[j])
        run_k0.append(j)
        if inside[j]:
            e = j + 1
            while e < m and inside[e] and idx[e] == i:
                e += 1
            span = times[i + 1] - times[i]
            w0 = (starts[j] + 0.5 * gate_s - times[i]) / span
            dw = bin_s / span
            term_img += [slots[i - i0], slots[i + 1 - i0]]
            term_c += [q_gate * (1.0 - w0), q_gate * w0]
            term_dc += [-q_gate * dw, q_gate * dw]
        else:  # a straddling gate: the exact mean, each overlapped piece weighted by its share of the gate
            e = j + 1
            lo, hi = float(starts[j]), float(ends[j])
            coef: dict[int, float] = {}
            for p in range(i, int(last[j]) + 1):
                a, b = max(lo, times[p]), min(hi, times[p + 1])
                if b <= a:
                    continue
                share = q_gate * (b - a) / gate_s
                w = (0.5 * (a + b) - times[p]) / (times[p + 1] - times[p])
                coef[p] = coef.get(p, 0.0) + share * (1.0 - w)
                coef[p + 1] = coef.get(p + 1, 0.0) + share * w
            for p, c in coef.items():
                term_img.append(slots[p - i0])
                term_c.append(c)
                term_dc.append(0.0)
        bin_run[j:e] = len(run_k0) - 1
        term_ptr.append(len(term_img))
        j = e
    return ChunkLayout(images=ring.images, slots=slots, run_k0=np.array(run_k0, np.int64),
                       term_ptr=np.array(term_ptr, np.int64), term_img=np.array(term_img, np.int64),
                       term_c=np.array(term_c, np.float64), term_dc=np.array(term_dc, np.float64),
                       bin_run=bin_run)

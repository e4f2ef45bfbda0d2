"""NEDI throughput: the vectorised numba solver versus a naive per-pixel scipy ``brentq`` reference, same process.

Run: ``python benchmarks/bench_nedi.py [side]``. One aggregate of 244 bins (0.4 kHz at 97.7 kHz) on a side×side
array, x = qΦτ between 0.05 and 3 (the nonlinear regime), 0–6 events per pixel inside the window; both solvers
must agree before timing counts.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np
from scipy.optimize import brentq

from simspad.methods.event_batches import EventBatch
from simspad.methods.nedi import nedi_deblur

Q_M2 = 0.45 * 0.105 * (16.38e-6) ** 2
BIN_S = 10.24e-6
N_BINS = 244


def make_problem(side: int, rng):
    n_pix = side * side
    x_ref = rng.uniform(0.05, 3.0, n_pix)
    n_ev = rng.integers(0, 7, n_pix)
    pix = np.repeat(np.arange(n_pix), n_ev)
    t = rng.uniform(0, N_BINS * BIN_S, pix.size)
    dl = np.where(rng.random(pix.size) < 0.5, 0.3, -0.3)
    order = np.argsort(t, kind="stable")
    batch = EventBatch(t[order], pix[order].astype(np.int64), dl[order], 0.0, N_BINS * BIN_S)
    bin_t = (np.arange(N_BINS) + 0.5) * BIN_S
    counts = rng.binomial(N_BINS, -np.expm1(-x_ref)).reshape(side, side)
    return counts, bin_t, batch


def brentq_reference(counts, bin_t, batch, t_ref, pixels):
    """Per pixel: build a_k bin by bin in Python and solve E[S](Φ) = S with scipy's brentq."""
    out = np.empty(len(pixels))
    flat = counts.reshape(-1)
    for j, p in enumerate(pixels):
        sel = batch.pix == p
        et, edl = batch.t_s[sel], batch.dl[sel]
        lev = np.array([edl[et <= tk].sum() for tk in bin_t])
        lref = edl[et <= t_ref].sum()
        a = np.exp(lev - lref)
        s = min(float(flat[p]), N_BINS - 1.0)
        if s <= 0:
            out[j] = 0.0
            continue

        def f(phi):
            return np.sum(-np.expm1(-Q_M2 * phi * a * BIN_S)) - s

        hi = 1.0 / (Q_M2 * BIN_S)
        while f(hi) < 0:
            hi *= 2
        out[j] = brentq(f, 0.0, hi, xtol=1e-6, rtol=1e-12)
    return out


def main(side: int = 512) -> None:
    rng = np.random.default_rng(0)
    counts, bin_t, batch = make_problem(side, rng)
    t_ref = 0.5 * N_BINS * BIN_S
    nedi_deblur(counts[:4, :4], N_BINS, bin_t, None, t_ref, Q_M2, BIN_S, 0.0)  # compile / load cache
    t0, c0 = time.perf_counter(), time.process_time()
    phi, _, _ = nedi_deblur(counts, N_BINS, bin_t, batch, t_ref, Q_M2, BIN_S, 0.0)
    t_fast, c_fast = time.perf_counter() - t0, time.process_time() - c0
    pixels = rng.choice(side * side, 300, replace=False)
    t0, c0 = time.perf_counter(), time.process_time()
    ref = brentq_reference(counts, bin_t, batch, t_ref, pixels)
    t_ref_s, c_ref = time.perf_counter() - t0, time.process_time() - c0
    got = phi.reshape(-1)[pixels]
    assert np.allclose(got, ref, rtol=1e-6, atol=1.0), "NEDI and the brentq reference disagree"
    n_pix = side * side
    print(f"NEDI, one aggregate of {N_BINS} bins, {len(batch) / n_pix:.1f} events/pixel, one core (wall clock; "
          f"CPU time in brackets, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"  numba solver  : {n_pix:>8,d} px in {t_fast:7.3f} s = {n_pix / t_fast / 1e6:8.3f} M px/s"
          f"  [{n_pix / c_fast / 1e6:7.3f}]")
    print(f"  scipy brentq  : {len(pixels):>8,d} px in {t_ref_s:7.3f} s = {len(pixels) / t_ref_s / 1e6:8.5f} M px/s"
          f"  [{len(pixels) / c_ref / 1e6:8.5f}]")
    print(f"  speed-up      : {(n_pix / t_fast) / (len(pixels) / t_ref_s):8.0f}x")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 512)

"""NEDI throughput: the numba solver versus the independent vectorised SciPy reference, same process, same pixels.

Run: ``python benchmarks/bench_nedi.py [side]``. One aggregate of 244 bins (0.4 kHz at 97.7 kHz) on a side×side
array, x = qΦτ between 0.05 and 3 (the nonlinear regime), 0–6 events per pixel inside the window. The reference
(``tests/helpers/references.py``: the per-bin event levels of a block of pixels as one array, E[S](Φ) = S solved
for the whole block by ``scipy.optimize.elementwise.find_root``) must agree with the solver to 10⁻⁹ relative before
timing counts.
"""

from __future__ import annotations

import os
import sys
import time

from pathlib import Path

import numpy as np

from simspad.methods.event_batches import EventBatch
from simspad.methods.nedi import nedi_deblur
from simspad.processes import available_cores

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the tests' references
from tests.helpers.references import nedi_reference  # noqa: E402

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


def main(side: int = 512) -> None:
    rng = np.random.default_rng(0)
    counts, bin_t, batch = make_problem(side, rng)
    t_ref = 0.5 * N_BINS * BIN_S
    nedi_deblur(counts[:4, :4], N_BINS, bin_t, None, t_ref, Q_M2, BIN_S, 0.0)  # compile / load cache
    t0, c0 = time.perf_counter(), time.process_time()
    phi, _, _ = nedi_deblur(counts, N_BINS, bin_t, batch, t_ref, Q_M2, BIN_S, 0.0)
    t_fast, c_fast = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    ref = nedi_reference(counts, N_BINS, bin_t, batch, t_ref, Q_M2, BIN_S, 0.0)
    t_ref_s, c_ref = time.perf_counter() - t0, time.process_time() - c0
    live = counts > 0
    assert np.allclose(phi[live], ref[live], rtol=1e-9, atol=0), "NEDI and the vectorised reference disagree"
    n_pix = side * side
    print(f"NEDI, one aggregate of {N_BINS} bins, {len(batch) / n_pix:.1f} events/pixel, one core (wall clock; "
          f"CPU time in brackets, load average {os.getloadavg()[0]:.1f} on {available_cores()} cores)")
    print(f"  numba solver     : {n_pix:>8,d} px in {t_fast:7.3f} s = {n_pix / t_fast / 1e6:8.3f} M px/s"
          f"  [{n_pix / c_fast / 1e6:7.3f}]")
    print(f"  SciPy vectorised : {n_pix:>8,d} px in {t_ref_s:7.3f} s = {n_pix / t_ref_s / 1e6:8.3f} M px/s"
          f"  [{n_pix / c_ref / 1e6:7.3f}]  (same pixels; agree to 1e-9)")
    print(f"  speed-up         : {t_ref_s / t_fast:8.1f}x wall, {c_ref / c_fast:.1f}x CPU time")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 512)

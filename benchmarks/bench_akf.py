"""AKF event throughput: the numba per-event kernel versus the independent vectorised NumPy reference, same
process, same stream.

Run: ``python benchmarks/bench_akf.py [n_events]``. Synthetic stream: random pixels of a 346×260 array (worst case
for caches), sorted random times over 1 s, ±0.2 log steps, every noise term on (threshold, isolation, refractory,
photoreceptor bandwidth). The reference (``tests/helpers/references.py``: each event's noise from sorts and
searches over the whole stream, the state recursion over the k-th events of every pixel at once) must agree with
the kernel to 10⁻¹² before timing counts. A second, spatially coherent stream (a sweeping edge) shows the
cache-friendly case. One core: the per-event recursion is sequential per pixel.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from simspad.methods.akf import AkfParams, AkfState, EventUpdateParams
from simspad.processes import available_cores

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the tests' references
from tests.helpers.references import akf_events_reference  # noqa: E402


def update_params(st: AkfState, p: AkfParams) -> EventUpdateParams:
    return EventUpdateParams(st.width, st.height, p.sigma_p, p.sigma_iso, p.sigma_ref, p.refractory_window_s,
                             p.q_threshold, p.pr_cutoff_hz_max > 0.0)


def arrays(st: AkfState):
    return (st.L, st.P, st.LF, st.Rinv, st.t_upd, st.t_last_ev, st.tau_pr)


# Event-camera description as in the recording attrs (Prophesee Gen4 preset), so every noise term is on.
PARAMS = AkfParams(pr_area_m2=0.5 * 0.77 * 4.86e-6 ** 2, pr_dark_e_s=30.0, pr_cutoff_hz_max=3000.0,
                   pr_cutoff_ref_e_s=1e6)


def make_state(H, W):
    st = AkfState(H, W, 0.0)
    rng = np.random.default_rng(0)
    st.L[:] = rng.normal(34.0, 1.0, H * W)  # ln Φ, Φ ≈ 6e14 ph s⁻¹ m⁻² (≈ 10 lx)
    st.LF[:] = st.L + rng.normal(0, 0.1, H * W)
    st.P[:] = 0.05
    st.Rinv[:] = 1.0 / (0.02 * 2.5e-3)
    st.update_photoreceptor(PARAMS)
    return st


def main(n_events: int = 5_000_000) -> None:
    H, W = 260, 346
    rng = np.random.default_rng(1)
    ev_t = np.sort(rng.random(n_events))
    ev_pix = rng.integers(0, H * W, n_events).astype(np.int64)
    ev_dl = np.where(rng.random(n_events) < 0.5, 0.2, -0.2)
    p = PARAMS

    warm = make_state(H, W)
    warm.events(ev_t[:1000], ev_pix[:1000], ev_dl[:1000], p)  # compile / load the cache outside the timing

    fast = make_state(H, W)
    t0, c0 = time.perf_counter(), time.process_time()
    fast.events(ev_t, ev_pix, ev_dl, p)
    t_fast, c_fast = time.perf_counter() - t0, time.process_time() - c0

    ref = make_state(H, W)
    t0, c0 = time.perf_counter(), time.process_time()
    akf_events_reference(arrays(ref), ev_t, ev_pix, ev_dl, update_params(ref, p))
    t_ref, c_ref = time.perf_counter() - t0, time.process_time() - c0
    for name, a, b in zip(("L", "P", "LF", "Rinv", "t_upd", "t_last_ev", "tau_pr"), arrays(fast), arrays(ref)):
        assert np.allclose(a, b, rtol=1e-12, atol=0), f"kernel and reference disagree on {name}"

    # A spatially coherent stream (a vertical edge sweeping the array) as real scenes produce: cache-friendly.
    sweep_x = (ev_t * 20 * W).astype(np.int64) % W
    coh_pix = rng.integers(0, H, n_events).astype(np.int64) * W + sweep_x
    coh = make_state(H, W)
    t0, c0 = time.perf_counter(), time.process_time()
    coh.events(ev_t, coh_pix, ev_dl, p)
    t_coh, c_coh = time.perf_counter() - t0, time.process_time() - c0

    fast_rate = n_events / t_fast
    ref_rate = n_events / t_ref
    print(f"AKF per-event update, {H}x{W} px, every noise term on, one core (wall clock; CPU time of this process "
          f"in brackets, load average {os.getloadavg()[0]:.1f} on {available_cores()} cores)")
    print(f"  numba kernel     : {n_events:>10,d} events in {t_fast:7.3f} s = {fast_rate / 1e6:8.2f} M events/s"
          f"  [{n_events / c_fast / 1e6:6.2f}]  (random pixels)")
    print(f"  numba, sweep     : {n_events:>10,d} events in {t_coh:7.3f} s = {n_events / t_coh / 1e6:8.2f} M events/s"
          f"  [{n_events / c_coh / 1e6:6.2f}]  (spatially coherent stream)")
    print(f"  NumPy vectorised : {n_events:>10,d} events in {t_ref:7.3f} s = {ref_rate / 1e6:8.2f} M events/s"
          f"  [{n_events / c_ref / 1e6:6.2f}]  (same stream; states agree to 1e-12)")
    cpu_rate = n_events / c_fast
    print(f"  speed-up         : {fast_rate / ref_rate:8.1f}x wall, {cpu_rate / (n_events / c_ref):.1f}x CPU time")
    print(f"  goal >= 10 M events/s (random pixels): wall {'met' if fast_rate >= 10e6 else 'NOT met'}, "
          f"CPU time {'met' if cpu_rate >= 10e6 else 'NOT met'} (wall clock counts other users' load)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5_000_000)

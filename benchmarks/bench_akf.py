"""AKF event throughput: the numba per-event kernel versus a plain-Python per-event reference, same process.

Run: ``python benchmarks/bench_akf.py [n_events]``. Synthetic stream: random pixels of a 346×260 array (worst case
for caches), sorted random times over 1 s, ±0.2 log steps; both implementations must agree to rounding before
timing counts. A second, spatially coherent stream (a sweeping edge) shows the cache-friendly case. One core:
the per-event recursion is sequential per pixel; the other core is left to the rest of the pipeline.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from simspad.methods.akf import AkfParams, AkfState


def python_reference(st: AkfState, ev_t, ev_pix, ev_dl, p: AkfParams) -> None:
    """The same update as ``akf_events``, one Python statement at a time."""
    W, H = st.width, st.height
    for t, i, dl in zip(ev_t.tolist(), ev_pix.tolist(), ev_dl.tolist()):
        dt = t - st.t_upd[i]
        if dt > 0.0:
            p0 = st.P[i]
            pn = 1.0 / (1.0 / p0 + st.Rinv[i] * dt)
            st.L[i] = st.LF[i] + (pn / p0) * (st.L[i] - st.LF[i])
            st.P[i] = pn + p.sigma_p * dt
            st.t_upd[i] = t
        st.L[i] += dl
        st.LF[i] += dl
        y, x = divmod(i, W)
        t_nb = -1e300
        for yy in range(max(y - 1, 0), min(y + 2, H)):
            for xx in range(max(x - 1, 0), min(x + 2, W)):
                if (yy, xx) != (y, x):
                    t_nb = max(t_nb, st.t_last_ev[yy * W + xx])
        q = p.q_threshold + p.sigma_iso * (t - t_nb)
        dtp = t - st.t_last_ev[i]
        if dtp < p.refractory_window_s:
            q += p.sigma_ref * dtp
        if p.pr_cutoff_hz_max > 0.0:
            tau = st.tau_pr[i]
            q += (dl * tau / (tau + dtp)) ** 2
        st.P[i] += q
        st.t_last_ev[i] = t


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


def main(n_events: int = 5_000_000, n_ref: int = 50_000) -> None:
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

    a, b = make_state(H, W), make_state(H, W)
    a.events(ev_t[:n_ref], ev_pix[:n_ref], ev_dl[:n_ref], p)
    t0, c0 = time.perf_counter(), time.process_time()
    python_reference(b, ev_t[:n_ref], ev_pix[:n_ref], ev_dl[:n_ref], p)
    t_ref, c_ref = time.perf_counter() - t0, time.process_time() - c0
    assert np.allclose(a.L, b.L, rtol=0, atol=1e-12) and np.allclose(a.P, b.P, rtol=1e-12, atol=0), "mismatch"

    # A spatially coherent stream (a vertical edge sweeping the array) as real scenes produce: cache-friendly.
    sweep_x = (ev_t * 20 * W).astype(np.int64) % W
    coh_pix = rng.integers(0, H, n_events).astype(np.int64) * W + sweep_x
    coh = make_state(H, W)
    t0, c0 = time.perf_counter(), time.process_time()
    coh.events(ev_t, coh_pix, ev_dl, p)
    t_coh, c_coh = time.perf_counter() - t0, time.process_time() - c0

    fast_rate = n_events / t_fast
    ref_rate = n_ref / t_ref
    print(f"AKF per-event update, {H}x{W} px, one core (wall clock; CPU time of this process in brackets, "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"  numba kernel : {n_events:>10,d} events in {t_fast:7.3f} s = {fast_rate / 1e6:8.2f} M events/s"
          f"  [{n_events / c_fast / 1e6:6.2f}]  (random pixels)")
    print(f"  numba, sweep : {n_events:>10,d} events in {t_coh:7.3f} s = {n_events / t_coh / 1e6:8.2f} M events/s"
          f"  [{n_events / c_coh / 1e6:6.2f}]  (spatially coherent stream)")
    print(f"  plain Python : {n_ref:>10,d} events in {t_ref:7.3f} s = {ref_rate / 1e6:8.4f} M events/s"
          f"  [{n_ref / c_ref / 1e6:6.4f}]")
    cpu_rate = n_events / c_fast
    print(f"  speed-up     : {fast_rate / ref_rate:8.1f}x wall, {cpu_rate / (n_ref / c_ref):.1f}x CPU time")
    print(f"  goal >= 10 M events/s (random pixels): wall {'met' if fast_rate >= 10e6 else 'NOT met'}, "
          f"CPU time {'met' if cpu_rate >= 10e6 else 'NOT met'} (wall clock counts other users' load)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5_000_000)

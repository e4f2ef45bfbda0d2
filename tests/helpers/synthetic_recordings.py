"""Synthetic recordings for the method tests, written with SimSPAD's RecordingWriter in the docs/format.md layout.

The scene is an analytic flux function ``flux(t) -> [H, W]`` (ph s⁻¹ m⁻²); SPAD bits follow the exact Bernoulli
model at each gate centre, events are ideal log-threshold crossings with interpolated timestamps on a fine
grid, frames follow the EMVA model with Poisson shot noise and Gaussian read noise. Independent of simspad's
simulator on purpose: the method tests must not depend on it.
"""

from __future__ import annotations

import numpy as np

from simspad.io.recording import RecordingWriter

SPAD_ATTRS = dict(bin_s=10.24e-6, gate_s=10.24e-6, pixel_pitch_m=16.38e-6, fill_factor=0.105, qe=0.45,
                  dead_time_s=100e-9)
FRAME_ATTRS = dict(gain_dn_per_e=0.39, black_level_dn=40.0, read_noise_e=2.8, full_well_e=10500.0, bit_depth=12,
                   qe=0.65, fill_factor=1.0, pixel_pitch_m=3.45e-6)
EVENT_ATTRS = dict(threshold_on=0.2, threshold_off=0.2, threshold_sigma=0.0, refractory_s=0.0,
                   pixel_pitch_m=4.86e-6, fill_factor=0.77, qe=0.5)


def spad_q(attrs=SPAD_ATTRS) -> float:
    return attrs["qe"] * attrs["fill_factor"] * attrs["pixel_pitch_m"] ** 2


def ideal_events(flux_fn, t0, t1, dt, shape, c_on, c_off):
    """Ideal events of ln flux crossing ±c from a per-pixel reference, times interpolated on a grid ``dt``."""
    H, W = shape
    ts = np.arange(t0, t1 + 0.5 * dt, dt)
    prev = np.log(flux_fn(ts[0])).reshape(-1)
    ref = prev.copy()
    out_t, out_pix, out_p = [], [], []
    for k in range(1, ts.size):
        cur = np.log(flux_fn(ts[k])).reshape(-1)
        while True:
            up = cur >= ref + c_on
            dn = cur <= ref - c_off
            if not (up.any() or dn.any()):
                break
            for mask, sign, c in ((up, 1, c_on), (dn, -1, c_off)):
                idx = np.nonzero(mask)[0]
                if idx.size == 0:
                    continue
                level = ref[idx] + sign * c
                frac = (level - prev[idx]) / (cur[idx] - prev[idx])
                out_t.append(ts[k - 1] + np.clip(frac, 0, 1) * dt)
                out_pix.append(idx)
                out_p.append(np.full(idx.size, 1 if sign > 0 else 0, np.uint8))
                ref[idx] = level
        prev = cur
    if not out_t:
        return np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.uint8)
    t = np.concatenate(out_t)
    pix = np.concatenate(out_pix)
    p = np.concatenate(out_p)
    order = np.argsort(t, kind="stable")
    return t[order], pix[order], p[order]


def write_recording(path, flux_fn, *, shape=(12, 16), duration_s=0.02, seed=0, spad=True, frames=True,
                    events=True, frame_rate_hz=500.0, exposure_s=1e-3, gt_rate_hz=1000.0, dcr_cps=0.0,
                    event_attrs=None, spad_attrs=None, event_dt_s=5e-6):
    """Write a synthetic recording; returns the event arrays written (t_s, pix, p) for reference."""
    rng = np.random.default_rng(seed)
    H, W = shape
    sa = dict(SPAD_ATTRS, **(spad_attrs or {}))
    ea = dict(EVENT_ATTRS, **(event_attrs or {}))
    root = dict(scene="synthetic", trajectory="none", lux=1.0, seed=seed, width=W, height=H, duration_s=duration_s,
                spec="{}", created_utc="2026-01-01T00:00:00Z", simspad_version="test", sequence="synthetic")
    ev_out = None
    with RecordingWriter(path, root) as w:
        gt_t = np.arange(0.0, duration_s - 1e-12, 1.0 / gt_rate_hz)
        w.write_dataset("gt/t", gt_t)
        w.write_dataset("gt/flux", np.stack([flux_fn(t) for t in gt_t]).astype(np.float32))
        if spad:
            M = int(duration_s / sa["bin_s"])
            t_start = np.arange(M) * sa["bin_s"]
            dcr = np.full((H, W), float(dcr_cps), np.float32) if np.isscalar(dcr_cps) else dcr_cps.astype(np.float32)
            q = spad_q(sa)
            app = w.append_dataset("spad/bits", (H, (W + 7) // 8), np.uint8, chunk_rows=256)
            for k0 in range(0, M, 256):
                k1 = min(k0 + 256, M)
                lam = np.stack([q * flux_fn(t + sa["gate_s"] / 2) + dcr for t in t_start[k0:k1]])
                bits = (rng.random(lam.shape) < -np.expm1(-lam * sa["gate_s"])).astype(np.uint8)
                app.append(np.packbits(bits, axis=2, bitorder="little"))
            w.write_dataset("spad/t_start", t_start)
            w.write_dataset("spad/dcr_cps", dcr)
            w.set_attrs("spad", **sa)
        if frames:
            fa = dict(FRAME_ATTRS)
            period = 1.0 / frame_rate_hz
            ts = np.arange(0.0, duration_s - exposure_s + 1e-12, period)
            te = ts + exposure_s
            area = fa["qe"] * fa["fill_factor"] * fa["pixel_pitch_m"] ** 2
            dns = []
            for a, b in zip(ts, te):
                sub = np.linspace(a, b, 21)
                mean_flux = np.mean([flux_fn(s) for s in sub], axis=0)
                e = rng.poisson(mean_flux * area * exposure_s) + rng.normal(0, fa["read_noise_e"], (H, W))
                e = np.minimum(e, fa["full_well_e"])
                dn = np.clip(np.rint(fa["gain_dn_per_e"] * e + fa["black_level_dn"]), 0, 2 ** fa["bit_depth"] - 1)
                dns.append(dn.astype(np.uint16))
            w.write_dataset("frames/dn", np.stack(dns))
            w.write_dataset("frames/t_start", ts)
            w.write_dataset("frames/t_end", te)
            w.set_attrs("frames", exposure_s=exposure_s, frame_rate_hz=frame_rate_hz, **fa)
        if events:
            t, pix, p = ideal_events(flux_fn, 0.0, duration_s, event_dt_s, shape, ea["threshold_on"],
                                     ea["threshold_off"])
            t_us = np.rint(t * 1e6).astype(np.int64)
            order = np.argsort(t_us, kind="stable")
            t_us, pix, p = t_us[order], pix[order], p[order]
            w.write_dataset("events/t", t_us)
            w.write_dataset("events/x", (pix % W).astype(np.uint16))
            w.write_dataset("events/y", (pix // W).astype(np.uint16))
            w.write_dataset("events/p", p)
            w.write_dataset("events/label", np.zeros(t_us.size, np.uint8))
            n_ms = int(np.ceil(duration_s * 1000))
            w.write_dataset("events/ms_to_idx", np.searchsorted(t_us, np.arange(n_ms + 1) * 1000).astype(np.uint64))
            w.set_attrs("events", **ea)
            ev_out = (t_us * 1e-6, pix, p)
    return ev_out

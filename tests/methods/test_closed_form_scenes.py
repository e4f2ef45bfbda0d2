"""Methods end to end (``get_method(name).reconstruct``) on scenes whose output is known in closed form (issue 36,
goal 6): what each method must return is computed here from the recording's own data (events, DN, SPAD bits)
by the documented equations, independently of the method's code, with stated bounds.

Scene ``ramp``: Φ(x, y, t) = Φ₀(x, y)·e^{r·t}, a texture brightening uniformly. Every pixel then crosses the
event threshold c at the same instants t_k = k·c/r (ideal events), chosen to fall between the evaluation and
exposure instants (never on one).
"""

import numpy as np
import pytest

from simspad.io.recording import open_recording
from simspad.methods import get_method
from simspad.methods.nedi import aggregate_bins
from tests.helpers.synthetic_recordings import EVENT_ATTRS, FRAME_ATTRS, SPAD_ATTRS, spad_q, write_recording

SHAPE = (8, 12)
C = EVENT_ATTRS["threshold_on"]  # 0.2
RATE = C / 2.3e-3  # one event per pixel every 2.3 ms: at 2.3, 4.6, ... ms, never on a ms or a frame centre
FLOAT32 = 2e-7  # the methods output float32 images: relative rounding


def _texture(level):
    yy, xx = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    return level * np.exp(0.8 * np.sin(xx / 2.0) * np.cos(yy / 3.0))


def _ramp(level):
    base = _texture(level)
    return lambda t: base * np.exp(RATE * t)


@pytest.fixture(scope="module")
def ramp_recording(tmp_path_factory):
    """Frames (500 Hz, 1 ms exposures) and events of the ramp scene over 20 ms: 700 e⁻ per exposure at the
    texture's mean at t = 0, 315–1560 e⁻ over the texture, rising ×5.2 by the last frame, below the full well."""
    path = tmp_path_factory.mktemp("closed_form") / "ramp.h5"
    area = FRAME_ATTRS["qe"] * FRAME_ATTRS["fill_factor"] * FRAME_ATTRS["pixel_pitch_m"] ** 2
    level = 700.0 / (area * 1e-3)
    ev_t, ev_pix, ev_p = write_recording(path, _ramp(level), shape=SHAPE, duration_s=0.02, spad=False,
                                         frame_rate_hz=500.0, exposure_s=1e-3)
    return path, (ev_t, ev_pix, np.where(ev_p > 0, C, -C))


def _levels(events, instants):
    """ℓ per pixel [K, n_pix] at each instant: the sum of the pixel's steps at or before it."""
    ev_t, ev_pix, ev_dl = events
    n_pix = SHAPE[0] * SHAPE[1]
    return np.stack([np.bincount(ev_pix[ev_t <= t], weights=ev_dl[ev_t <= t], minlength=n_pix) for t in instants])


def _mean_exp_level(events, pixel, t0, t1, f):
    """(1/T)∫_{t0}^{t1} exp(ℓ(t) − ℓ(f)) dt of one pixel, ℓ piecewise constant between its events: exact."""
    ev_t, ev_pix, ev_dl = events
    mine = ev_pix == pixel
    t, dl = ev_t[mine], ev_dl[mine]
    cuts = np.concatenate([[t0], t[(t > t0) & (t < t1)], [t1]])
    lev = np.array([dl[t <= s].sum() for s in cuts[:-1]])
    return float(np.sum(np.diff(cuts) * np.exp(lev - dl[t <= f].sum())) / (t1 - t0))


def test_the_ramp_has_the_events_it_claims(ramp_recording):
    _, (ev_t, ev_pix, ev_dl) = ramp_recording
    per_pixel = np.bincount(ev_pix, minlength=SHAPE[0] * SHAPE[1])
    assert np.all(per_pixel == 8) and np.all(ev_dl == C)  # 20 ms / 2.3 ms
    k = np.arange(1, 9)
    for p in (0, 37, 95):
        np.testing.assert_allclose(np.sort(ev_t[ev_pix == p]), k * C / RATE, atol=1e-6)


def test_cf_is_the_leaky_sum_of_the_events(ramp_recording):
    """CF: L(t) = Σ_{t_k ≤ t} ±c·exp(−α(t − t_k)) (the complementary filter with no frame, L(0) = 0, solved
    exactly), output exp(L); and L stays within c of the true log change r·t (event quantisation), the leak
    (α = 2π·0.1 Hz) costing < 10⁻³ over 20 ms."""
    path, (ev_t, ev_pix, ev_dl) = ramp_recording
    alpha = 2 * np.pi * 0.1
    with open_recording(path) as rec:
        times = rec.gt.t
        out = np.stack(list(get_method("cf").reconstruct(rec, times))).astype(np.float64)
    n_pix = SHAPE[0] * SHAPE[1]
    for t, img in zip(times, out):
        past = ev_t <= t
        expected = np.bincount(ev_pix[past], weights=ev_dl[past] * np.exp(-alpha * (t - ev_t[past])),
                               minlength=n_pix)
        np.testing.assert_allclose(np.log(img.reshape(-1)), expected, rtol=0, atol=3 * FLOAT32 * (1 + expected.max()))
        assert np.all(np.abs(expected - RATE * t) < C + 1e-3)


def dn_saturated(path):
    with open_recording(path) as rec:
        dn = rec.frames.dn(slice(None)).astype(np.float64)
    return (dn - FRAME_ATTRS["black_level_dn"]) / FRAME_ATTRS["gain_dn_per_e"] >= 0.99 * FRAME_ATTRS["full_well_e"]


def _edi_estimates(path, events):
    """Per frame k: (a_k, b_k, f_k, Φ̂_k(f)) with Φ̂ = B/M: B the DN inverted by the EMVA model, M the exact mean of
    exp(ℓ − ℓ(f)) over the exposure; windows split at the mid-points between exposure centres."""
    fa = FRAME_ATTRS
    area = fa["qe"] * fa["fill_factor"] * fa["pixel_pitch_m"] ** 2
    with open_recording(path) as rec:
        ts, te = np.asarray(rec.frames.t_start), np.asarray(rec.frames.t_end)
        dn = rec.frames.dn(slice(None)).astype(np.float64)
    centres = (ts + te) / 2
    mids = np.concatenate([[-np.inf], (centres[1:] + centres[:-1]) / 2, [np.inf]])
    n_pix = SHAPE[0] * SHAPE[1]
    out = []
    for k in range(ts.size):
        blur = np.maximum(dn[k].reshape(-1) - fa["black_level_dn"], 0) / fa["gain_dn_per_e"] / (area * (te[k] - ts[k]))
        m = np.array([_mean_exp_level(events, p, ts[k], te[k], centres[k]) for p in range(n_pix)])
        out.append((mids[k], mids[k + 1], centres[k], blur / m))
    return out


def test_edi_is_the_frame_divided_by_the_mean_event_exponential_then_advanced_by_events(ramp_recording):
    """EDI: the instant t takes the frame k of nearest exposure centre f_k, Φ(t) = Φ̂_k(f_k)·e^{ℓ(t) − ℓ(f_k)}; and
    against the truth, within the events' quantisation c and 5 standard deviations of the frame's shot noise (at
    ≥ 315 e⁻, 5.6 % per pixel)."""
    path, events = ramp_recording
    frames = _edi_estimates(path, events)
    with open_recording(path) as rec:
        times, gt = rec.gt.t, rec.gt.flux().astype(np.float64)
        out = np.stack(list(get_method("edi").reconstruct(rec, times))).astype(np.float64)
    lev_t = _levels(events, times)
    for j, t in enumerate(times):
        a, b, f, phi_f = next(x for x in frames if x[0] <= t < x[1])
        expected = phi_f * np.exp(lev_t[j] - _levels(events, [f])[0])
        np.testing.assert_allclose(out[j].reshape(-1), expected, rtol=5 * FLOAT32)
    err = np.log(out / gt)
    assert not np.any(dn_saturated(path))
    assert abs(err.mean()) < C / 2 and np.abs(err).max() < C + 5 * 0.056


def test_akf_fe_stays_within_the_event_advanced_frames_it_has_seen(ramp_recording):
    """AKF (F+E): between frames the state relaxes towards the latest frame and events add the same ±c to state
    and frame, so L(t) − ℓ(t) is a convex combination of the frames' ln Φ̂_k(f_k) − ℓ(f_k) seen so far (EDI's
    estimates, computed above from the DN): per pixel it lies between their minimum and maximum."""
    path, events = ramp_recording
    frames = _edi_estimates(path, events)
    with open_recording(path) as rec:
        times = rec.gt.t
        out = np.stack(list(get_method("akf_fe").reconstruct(rec, times))).astype(np.float64)
    lev_t = _levels(events, times)
    anchored = np.stack([np.log(phi) - _levels(events, [f])[0] for _, _, f, phi in frames])  # [K, n_pix]
    inside = 0
    for j, t in enumerate(times):
        seen = anchored[[k for k, x in enumerate(frames) if x[0] <= t]]
        got = np.log(out[j].reshape(-1)) - lev_t[j]
        assert np.all(got >= seen.min(axis=0) - 1e-6) and np.all(got <= seen.max(axis=0) + 1e-6), t
        inside += int(np.sum(np.ptp(seen, axis=0) > 1e-3))
    assert inside > 100  # the hull is not a single point: the frames disagree and the check has teeth


@pytest.fixture(scope="module")
def static_spad_recording(tmp_path_factory):
    """A static texture seen by the SPAD only (no motion, hence no event): 40 ms at x = qΦ·gate ≈ 0.2–1.0."""
    path = tmp_path_factory.mktemp("closed_form") / "static.h5"
    level = 0.45 / (spad_q() * SPAD_ATTRS["gate_s"])
    write_recording(path, lambda t: _texture(level), shape=SHAPE, duration_s=0.04,
                    frames=False, dcr_cps=25.0)
    return path


def test_adaptive_nedi_akf_stays_within_the_aggregates_naive_estimates(static_spad_recording):
    """Adaptive NEDI+AKF on a static scene: with no events, every aggregate read is NI's estimate
    Φ̂ = (−ln(1 − S/n)/gate − r_dark)/q (docs/methods.md) and the filter's state is a convex combination of the
    reads (in ln Φ), so per pixel ln(output) lies between the smallest and largest ln Φ̂ of the windows of n bins
    up to that instant. Counts stay ≥ 10 (the low-count update is not used)."""
    path = static_spad_recording
    with open_recording(path) as rec:
        times = rec.gt.t
        n = aggregate_bins(rec)
        n_win = rec.spad.t_start.size // n
        counts = np.stack([rec.spad.counts(j * n, (j + 1) * n).astype(np.float64).reshape(-1) for j in range(n_win)])
        t_start = np.asarray(rec.spad.t_start)
        gt = rec.gt.flux().astype(np.float64)
        method = get_method("adaptive_nedi_akf", tile_px=4)
        out = np.stack(list(method.reconstruct(rec, times))).astype(np.float64)
    assert counts.min() >= 10
    q, gate = spad_q(), SPAD_ATTRS["gate_s"]
    ni = np.log((-np.log1p(-counts / n) / gate - 25.0) / q)  # [window, pixel]
    win_start = t_start[np.arange(n_win) * n]
    for j, t in enumerate(times):
        seen = ni[: max(1, int(np.sum(win_start <= t)))]
        got = np.log(out[j].reshape(-1))
        assert np.all(got >= seen.min(axis=0) - 1e-6) and np.all(got <= seen.max(axis=0) + 1e-6), t
    # and the truth: the last output within 4 standard errors of one aggregate (binomial) of the true flux
    x = q * gt[-1].reshape(-1) * gate
    sd_log = np.sqrt(np.expm1(x) / n) / x  # Cramér–Rao of ln Φ̂ from n gates (no dark counts)
    assert np.all(np.abs(np.log(out[-1].reshape(-1)) - np.log(gt[-1].reshape(-1))) < 4 * sd_log)
    assert method.last_policy.readout_fraction < 1.0  # it did skip reads: the adaptive path was exercised

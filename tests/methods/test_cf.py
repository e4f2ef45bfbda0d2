"""CF (E): the events-only complementary filter tracks a known log signal from ideal events."""

import numpy as np

from simspad.methods.cf import cf_decay, cf_events
from tests.helpers.synthetic_recordings import ideal_events


def _high_pass(signal, t, alpha):
    """Exact first-order high-pass (L̇ = ṡ − αL, L(0) = 0) of a sampled signal, by the trapezoid rule."""
    out = np.zeros_like(signal)
    for k in range(1, t.size):
        dt = t[k] - t[k - 1]
        out[k] = np.exp(-alpha * dt) * out[k - 1] + (signal[k] - signal[k - 1]) * np.exp(-alpha * dt / 2)
    return out


def test_cf_tracks_known_log_signal_from_ideal_events():
    c = 0.05
    shape = (4, 5)
    phase = np.linspace(0, 2 * np.pi, 20, endpoint=False).reshape(shape)
    amp = np.linspace(0.5, 2.0, 20).reshape(shape)

    def log_signal(t):
        return amp * np.sin(2 * np.pi * 15.0 * t + phase)

    def flux(t):
        return np.exp(log_signal(t))

    ev_t, ev_pix, ev_p = ideal_events(flux, 0.0, 0.2, 5e-5, shape, c, c)
    dl = np.where(ev_p > 0, c, -c)
    alpha = 2 * np.pi * 2.0  # a strong leak, so that the test sees it
    out_t = np.linspace(0.01, 0.2, 39)
    L = np.zeros(20)
    t_upd = np.zeros(20)
    got = []
    i = 0
    for t in out_t:
        j = np.searchsorted(ev_t, t, side="right")
        cf_events(L, t_upd, ev_t[i:j], ev_pix[i:j], dl[i:j], alpha)
        i = j
        cf_decay(L, t_upd, t, alpha)
        got.append(L.copy())
    got = np.array(got)
    grid = np.linspace(0, 0.2, 4001)
    s = np.array([log_signal(t).reshape(-1) for t in grid])
    hp = np.array([_high_pass(s[:, p], grid, alpha) for p in range(20)]).T
    ref = hp[np.searchsorted(grid, out_t)]
    err = got - ref
    # Event quantisation bounds the error by c (plus its own high-passed copy ≤ c); typically ≈ c/2.
    assert np.abs(err).max() < 2 * c
    assert np.abs(err).mean() < 0.6 * c
    # The leak matters: integrating without it would be far off.
    no_leak = s[np.searchsorted(grid, out_t)] - s[0]
    assert np.abs(no_leak - ref).mean() > 3 * np.abs(err).mean()

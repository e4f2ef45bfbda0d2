"""AKF: covariance and state follow the closed-form equations; convergence to a step; event noise terms, by hand
and against the independent vectorised reference (tests/helpers/references.py)."""

import numpy as np
import pytest

from simspad.methods.akf import (
    AkfParams,
    AkfState,
    EventArrays,
    EventUpdateParams,
    FilterArrays,
    akf_events,
    akf_frames,
)
from simspad.methods.event_batches import EventBatch
from simspad.methods.windows import Measurement
from tests.helpers.references import akf_events_reference, event_noise_reference


def test_relaxation_matches_closed_form_and_composes():
    st = AkfState(1, 3, 0.0)
    P0 = np.array([0.5, 0.09, 0.01])
    st.P[:] = P0
    st.L[:] = 0.0
    st.LF[:] = 1.0
    st.Rinv[:] = np.array([100.0, 10.0, 0.0])
    for t in np.linspace(0.001, 0.05, 17):  # many small steps, no process noise
        st.advance(t, sigma_p=0.0)
    T = 0.05
    P_exp = 1.0 / (1.0 / P0 + st.Rinv * T)
    assert np.allclose(st.P, P_exp, rtol=1e-12)
    assert np.allclose(st.L - 1.0, (P_exp / P0) * (0.0 - 1.0), rtol=1e-12)
    assert st.L[2] == 0.0  # no measurement (R⁻¹ = 0): the state does not move
    # one step with process noise: P = (P0⁻¹ + R⁻¹Δt)⁻¹ + σ_p Δt
    st2 = AkfState(1, 1, 0.0)
    st2.P[:] = 0.2
    st2.Rinv[:] = 50.0
    st2.advance(0.01, sigma_p=0.005)
    assert np.isclose(st2.P[0], 1.0 / (1 / 0.2 + 50.0 * 0.01) + 0.005 * 0.01, rtol=1e-12)


def test_converges_to_a_step_with_the_predicted_time_constant():
    """Frames at ln Φ = 0 then a step to ln Φ = 1: the error decays as P(t)/P(T) (no process noise)."""
    shape = (2, 3)
    n = 6
    T = 2.5e-3
    var = 0.04

    def meas(j, level):
        return Measurement(j * T, (j + 1) * T, (j + 0.5) * T, np.full(n, np.exp(level)), 1e-30, np.full(n, var),
                           np.zeros(n), None, 8.0, T)

    times = np.linspace(0.0, 4 * T - 1e-9, 81)
    params = AkfParams(sigma_p=0.0, innovation_window_px=0)  # the bare equations
    out = np.stack(list(akf_frames(iter([meas(0, 0.0), meas(1, 0.0), meas(2, 1.0), meas(3, 1.0)]), times, shape,
                                   params, None)))
    L = np.log(out[:, 0, 0].astype(np.float64))
    # Closed form: P starts at var, information grows by t/(var T) per unit time (prior counted at t=0).
    P_step = 1.0 / (1.0 / var + 2 * T / (var * T))
    after = times >= 2 * T
    predicted = 1.0 - (1.0 / (1.0 / P_step + (times[after] - 2 * T) / (var * T))) / P_step
    assert np.allclose(L[after], predicted, atol=2e-6)  # float32 output
    assert np.allclose(L[~after], 0.0, atol=1e-6)
    # Time constant: the error halves when the information gathered equals the prior's (t − 2T = P_step⁻¹·var·T).
    t_half = P_step ** -1 * var * T
    k = np.argmin(np.abs(times - (2 * T + t_half)))
    assert abs((1.0 - L[k]) - 1.0 / (1.0 + (times[k] - 2 * T) / t_half)) < 1e-5
    # After two windows at the new level the error is prior/(prior + gained) = 3/5 of the step, decreasing.
    assert abs((1.0 - L[-1]) - 0.6) < 1e-3 and np.all(np.diff(L[after]) > 0)
    # Covariance matching: the innovation (1) is far beyond √(P + R), so P is scaled up at the step and the state
    # follows the new frames at once; ratio = ν²/(P + R) exactly (uniform images).
    out2 = np.stack(list(akf_frames(iter([meas(0, 0.0), meas(1, 0.0), meas(2, 1.0), meas(3, 1.0)]), times, shape,
                                    AkfParams(sigma_p=0.0), None)))
    L2 = np.log(out2[:, 0, 0].astype(np.float64))
    P_infl = P_step * 1.0 / (P_step + var)
    k_end = np.searchsorted(times, 3 * T) - 1
    expected = 1.0 - (1.0 / (1.0 / P_infl + (times[k_end] - 2 * T) / (var * T))) / P_infl
    assert abs(L2[k_end] - expected) < 1e-5 and 1.0 - L2[k_end] < 0.25


def test_event_update_adds_threshold_isolation_and_refractory_noise():
    W, H = 3, 3
    n = W * H
    L = np.zeros(n)
    P = np.full(n, 0.1)
    LF = np.zeros(n)
    Rinv = np.zeros(n)
    t_upd = np.zeros(n)
    t_last = np.zeros(n)
    t_last[0] = 0.010  # neighbour of the centre fired at 10 ms
    t_last[4] = 0.015  # the centre itself fired at 15 ms
    ev_t = np.array([0.020, 0.045])
    ev_pix = np.array([4, 4], dtype=np.int64)
    ev_dl = np.array([0.3, -0.25])
    sp, siso, sref, win, qthr = 0.005, 0.03, 0.05, 0.010, 0.03 ** 2
    akf_events(FilterArrays(L, P, LF, Rinv, t_upd, t_last, np.zeros(n)), EventArrays(ev_t, ev_pix, ev_dl),
               EventUpdateParams(W, H, sp, siso, sref, win, qthr, False))
    p1 = 0.1 + sp * 0.020 + qthr + siso * (0.020 - 0.010) + sref * (0.020 - 0.015)
    p2 = p1 + sp * 0.025 + qthr + siso * (0.045 - 0.010)  # previous event 25 ms ago: beyond the window
    assert np.isclose(P[4], p2, rtol=1e-12)
    assert np.isclose(L[4], 0.05) and np.isclose(LF[4], 0.05)  # the frame value is advanced by the events too
    assert t_last[4] == 0.045 and P[0] == 0.1


def test_events_track_motion_between_frames():
    """With events, the output follows a ramp between frames; without them it would lag."""
    shape = (1, 1)
    T = 10e-3
    c = 0.1
    ev_t = np.arange(1, 40) * 0.25e-3  # +0.1 every 0.25 ms: ln Φ rises 0.4 per ms
    batch0 = EventBatch(ev_t, np.zeros(ev_t.size, np.int64), np.full(ev_t.size, c), 0.0, T)
    m0 = Measurement(0.0, T, 0.0, np.ones(1), 1e-30, np.full(1, 0.01), np.zeros(1), batch0, 8.0, T)
    times = np.array([2e-3, 5e-3, 9.9e-3])
    out = np.stack(list(akf_frames(iter([m0]), times, shape, AkfParams(q_threshold=0.0), None)))
    truth = c * np.floor(times / 0.25e-3 + 1e-9)
    assert np.allclose(np.log(out[:, 0, 0]), truth, atol=1e-5)


def test_event_noise_with_every_term_on_and_all_eight_neighbours_firing():
    """Hand-computed P after one event of the centre of a 3×3 array whose eight neighbours all fired, each at its
    own time: the isolation term takes the latest of the eight (the bottom-right one, so a neighbourhood missing a
    row or a column is caught), and the photoreceptor term is (c·τ/(τ + Δt))² with τ ≠ Δt."""
    W, H = 3, 3
    n = W * H
    # neighbours' last events (s); the centre (index 4) last fired at 14 ms; the latest neighbour is index 8
    t_last = np.array([0.011, 0.004, 0.012, 0.009, 0.014, 0.013, 0.006, 0.010, 0.0175])
    tau = np.full(n, 2e-3)  # photoreceptor time constant of the centre: 2 ms
    P = np.full(n, 0.1)
    L = np.zeros(n)
    LF = np.full(n, 0.5)
    Rinv = np.full(n, 40.0)
    t_upd = np.full(n, 0.012)
    t, dl = 0.019, -0.2
    sp, siso, sref, win, qthr = 0.005, 0.03, 0.05, 0.010, 0.03 ** 2
    akf_events(FilterArrays(L, P, LF, Rinv, t_upd, t_last, tau), EventArrays(np.array([t]), np.array([4]),
                                                                           np.array([dl])),
               EventUpdateParams(W, H, sp, siso, sref, win, qthr, True))
    dt, dtp = t - 0.012, t - 0.014  # since the centre's last update, since its last event (5 ms < 10 ms window)
    p_relaxed = 1.0 / (1.0 / 0.1 + 40.0 * dt)
    l_relaxed = 0.5 + (p_relaxed / 0.1) * (0.0 - 0.5)
    expected = (p_relaxed + sp * dt  # relaxation and process noise
                + qthr  # threshold mismatch
                + siso * (t - 0.0175)  # isolation: the latest of the eight neighbours, 1.5 ms before
                + sref * dtp  # refractory: the centre fired 5 ms before, inside the window
                + (dl * 2e-3 / (2e-3 + dtp)) ** 2)  # photoreceptor: the step lags by τ/(τ + Δt) = 2/7 of it
    assert P[4] == pytest.approx(expected, rel=1e-14)
    assert L[4] == pytest.approx(l_relaxed + dl, rel=1e-14) and LF[4] == pytest.approx(0.5 + dl, rel=1e-14)
    assert t_last[4] == t and np.all(P[np.arange(n) != 4] == 0.1)


def _random_state(H, W, seed):
    r = np.random.default_rng(seed)
    n = H * W
    return FilterArrays(r.normal(30.0, 1.0, n), r.uniform(0.01, 0.1, n), r.normal(30.0, 1.0, n),
                        r.uniform(0.0, 500.0, n), np.zeros(n), r.uniform(-0.01, 0.0, n), r.uniform(1e-4, 5e-3, n))


def test_event_kernel_matches_the_independent_vectorised_reference():
    """A dense random stream on a 9×11 array (every pixel fires ~30 times within 50 ms: refractory bursts, all
    eight neighbours active, simultaneous events) with every noise term on, against the vectorised reference of
    tests/helpers/references.py. Same operations per pixel in the same order: agreement to 10⁻¹² relative."""
    H, W = 9, 11
    rng = np.random.default_rng(0)
    n_ev = 3000
    t = np.sort(rng.uniform(0.0, 0.05, n_ev))
    t[100:110] = t[100]  # simultaneous events: Δt = 0 for the relaxation
    pix = rng.integers(0, H * W, n_ev)
    dl = np.where(rng.random(n_ev) < 0.5, 0.2, -0.15)
    params = EventUpdateParams(W, H, 0.005, 0.03, 0.05, 0.010, 0.03 ** 2, True)
    got, ref = _random_state(H, W, 1), _random_state(H, W, 1)
    akf_events(got, EventArrays(t, pix, dl), params)
    akf_events_reference(ref, t, pix, dl, params)
    for name, a, b in zip(FilterArrays._fields, got, ref):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, err_msg=name)
    # the stream exercises what it claims: bursts inside the refractory window and the bandwidth term's weight
    q, rank = event_noise_reference(t, pix, dl, _random_state(H, W, 1).t_last_ev, got.tau_pr, W, H, params)
    assert rank.max() >= 20 and (np.diff(t) == 0).any()
    assert np.ptp(q) > 0.01

"""AKF: covariance and state follow the closed-form equations; convergence to a step; event noise terms."""

import numpy as np

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

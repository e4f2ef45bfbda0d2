"""NEDI: the exact nonlinear SPAD response versus linear EDI on bits drawn from the exact Bernoulli model."""

import numpy as np
import pytest

from simspad.methods.event_batches import EventBatch
from simspad.methods.nedi import laplace_update, nedi_deblur
from simspad.methods.spad_response import estimate_flux, floor_flux, log_flux_variance
from tests.helpers.references import nedi_reference

Q_M2 = 0.45 * 0.105 * (16.38e-6) ** 2
BIN_S = 10.24e-6


def _blurred_aggregate(x_ref, n_bins, levels, c, shape, rng, dcr_cps=0.0):
    """Bits of ``n_bins`` bins whose flux steps through ``levels`` (event counts, equal durations) around f.

    Returns counts, bin times, the events (ON, at the step times, every pixel), f and the true Φ(f).
    """
    phi_f = x_ref / (Q_M2 * BIN_S)
    bin_t = (np.arange(n_bins) + 0.5) * BIN_S
    seg = np.minimum((np.arange(n_bins) * len(levels)) // n_bins, len(levels) - 1)
    a = np.exp(c * (np.asarray(levels, float)[seg]))
    p = -np.expm1(-(Q_M2 * phi_f * a + dcr_cps) * BIN_S)
    counts = (rng.random((n_bins,) + shape) < p[:, None, None]).sum(axis=0)
    step_idx = [int(np.argmax(seg == j)) for j in range(1, len(levels))]
    step_t = bin_t[step_idx] - 0.25 * BIN_S
    n_pix = shape[0] * shape[1]
    t = np.repeat(step_t, n_pix)
    pix = np.tile(np.arange(n_pix), len(step_t))
    batch = EventBatch(t, pix.astype(np.int64), np.full(t.size, c), 0.0, n_bins * BIN_S)
    # f: the instant where the level is 0 (the middle step)
    k0 = int(np.argmax(seg == list(levels).index(0)))
    f = bin_t[k0] + 0.1 * BIN_S
    return counts, bin_t, batch, f, phi_f


@pytest.mark.parametrize("x_ref, max_ratio", [(2.0, 0.5)])
def test_nedi_beats_linear_edi_where_response_is_nonlinear(x_ref, max_ratio):
    rng = np.random.default_rng(1)
    shape = (40, 50)
    counts, bin_t, ev, f, phi_f = _blurred_aggregate(x_ref, 976, [-2, -1, 0, 1, 2], 0.3, shape, rng)
    nedi, var, lref = nedi_deblur(counts, 976, bin_t, ev, f, Q_M2, BIN_S, 0.0)
    edi, _, _ = nedi_deblur(counts, 976, bin_t, ev, f, Q_M2, BIN_S, 0.0, linear=True)
    assert np.allclose(lref, 0.6)  # two ON events of 0.3 before f
    err_nedi = np.log(nedi / phi_f)
    err_edi = np.log(edi / phi_f)
    rmse_nedi = np.sqrt(np.mean(err_nedi ** 2))
    rmse_edi = np.sqrt(np.mean(err_edi ** 2))
    assert rmse_nedi < max_ratio * rmse_edi, (rmse_nedi, rmse_edi)
    # NEDI is unbiased to within its standard error and its spread matches the Cramér–Rao prediction.
    sd_pred = np.sqrt(np.mean(var))
    assert abs(err_nedi.mean()) < 4 * sd_pred / np.sqrt(err_nedi.size) + 0.005
    assert 0.85 < err_nedi.std() / sd_pred < 1.15
    # Linear EDI underestimates: the response saturates at the bright end of the window.
    assert err_edi.mean() < -0.1


def test_nedi_equals_edi_in_the_linear_regime():
    rng = np.random.default_rng(2)
    shape = (30, 40)
    counts, bin_t, ev, f, phi_f = _blurred_aggregate(0.02, 976, [-2, -1, 0, 1, 2], 0.3, shape, rng)
    nedi, _, _ = nedi_deblur(counts, 976, bin_t, ev, f, Q_M2, BIN_S, 0.0)
    edi, _, _ = nedi_deblur(counts, 976, bin_t, ev, f, Q_M2, BIN_S, 0.0, linear=True)
    rel = np.abs(nedi - edi) / phi_f
    assert rel.max() < 0.03


def test_nedi_without_events_is_the_ml_estimator_and_dark_counts_clip_to_zero():
    counts = np.array([[0, 1, 50, 244]])
    bin_t = (np.arange(244) + 0.5) * BIN_S
    dcr = np.array([[500.0, 1.0, 1.0, 1.0]])
    phi, var, _ = nedi_deblur(counts, 244, bin_t, None, 0.0, Q_M2, BIN_S, dcr)
    ml = estimate_flux(counts, 244, Q_M2, BIN_S, dcr)
    assert np.allclose(phi, ml, rtol=1e-9)
    assert phi[0, 0] == 0.0 and np.isfinite(phi[0, 3])
    assert np.allclose(var[0, 2], log_flux_variance(phi[0, 2], 244, Q_M2, BIN_S, 1.0), rtol=1e-9)


def test_nedi_solves_the_expected_count_equation_exactly():
    rng = np.random.default_rng(3)
    counts, bin_t, ev, f, phi_f = _blurred_aggregate(1.0, 244, [-1, 0, 1, 2], 0.5, (4, 5), rng, dcr_cps=1e3)
    phi, _, lref = nedi_deblur(counts, 244, bin_t, ev, f, Q_M2, BIN_S, 1e3)
    seg = np.minimum((np.arange(244) * 4) // 244, 3)
    a = np.exp(0.5 * (np.array([-1, 0, 1, 2])[seg]))
    expected = (-np.expm1(-(Q_M2 * phi.reshape(-1, 1) * a + 1e3) * BIN_S)).sum(axis=1)
    assert np.allclose(expected, np.minimum(counts.reshape(-1), 243), rtol=1e-8)


def test_low_count_update_is_unbiased_where_floored_logs_are_not():
    """Sequential posterior updates from sparse aggregates (0.3 expected ones each) converge to the truth."""
    rng = np.random.default_rng(5)
    n_pix, n_bins, windows = 400, 244, 300
    mu = 0.3  # expected ones per aggregate
    phi = -np.log1p(-mu / n_bins) / (Q_M2 * BIN_S)
    floor = floor_flux(n_bins, Q_M2, BIN_S)
    u = np.full(n_pix, np.log(floor))
    P = np.full(n_pix, 2.0)
    logs = []
    for _ in range(windows):
        S = rng.binomial(n_bins, mu / n_bins, n_pix)
        low, u_eq, var_eq = laplace_update(S, n_bins, Q_M2, BIN_S, 0.0, u, P)
        assert low.all()
        post_P = 1.0 / (1.0 / P + 1.0 / var_eq)
        u = post_P * (u / P + u_eq / var_eq)  # the Gaussian fusion the filter's relaxation performs
        P = post_P
        logs.append(np.log(np.maximum(estimate_flux(S, n_bins, Q_M2, BIN_S), floor)))
    assert abs(np.mean(np.exp(u)) / phi - 1) < 0.1
    assert np.exp(np.mean(logs)) / phi > 1.5  # the floored log average: biased high


def test_nedi_matches_the_independent_vectorised_reference():
    """Random counts and 0–6 events per pixel at random times (steps of ±0.3), with a dark count rate, against the
    vectorised SciPy solve of E[S](Φ) = S in tests/helpers/references.py: the same root to 10⁻⁹ relative (both
    solvers converge far tighter; the bound leaves room for the kernel's Newton stopping rule)."""
    rng = np.random.default_rng(3)
    side, n_bins = 24, 244
    n_pix = side * side
    x = rng.uniform(0.05, 3.0, n_pix)
    n_ev = rng.integers(0, 7, n_pix)
    pix = np.repeat(np.arange(n_pix), n_ev)
    t = rng.uniform(0, n_bins * BIN_S, pix.size)
    dl = np.where(rng.random(pix.size) < 0.5, 0.3, -0.3)
    order = np.argsort(t, kind="stable")
    batch = EventBatch(t[order], pix[order].astype(np.int64), dl[order], 0.0, n_bins * BIN_S)
    bin_t = (np.arange(n_bins) + 0.5) * BIN_S
    counts = rng.binomial(n_bins, -np.expm1(-x)).reshape(side, side)
    counts[0, :3] = (0, 1, n_bins)  # no ones, one, saturated (capped at n − 1 by both)
    t_ref = 0.4 * n_bins * BIN_S
    dcr = 50.0
    phi, _, lref = nedi_deblur(counts, n_bins, bin_t, batch, t_ref, Q_M2, BIN_S, dcr)
    ref = nedi_reference(counts, n_bins, bin_t, batch, t_ref, Q_M2, BIN_S, dcr)
    live = counts > 0
    np.testing.assert_allclose(phi[live], ref[live], rtol=1e-9, atol=0)
    assert np.ptp(np.log(phi[live])) > 3  # a wide range of fluxes, into the nonlinear regime

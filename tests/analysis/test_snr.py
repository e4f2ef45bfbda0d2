"""Analytic SNR curves: a hand-computed point per sensor, a Monte Carlo check of the gated SPAD, the CLI."""

import math

import numpy as np
import pytest
from PIL import Image

from simspad.analysis import snr
from simspad.cli import main

PHI = 1e15  # photons s⁻¹ m⁻² at the sensor plane (≈ 7 lx middle grey)
T = 10e-3


def test_frame_camera_hand_value():
    # Blackfly S: pitch 3.45 µm, qe 0.65, read 2.8 e⁻, dark 3 e⁻/s, K 0.38 DN/e⁻
    mu = 0.65 * PHI * 3.45e-6 ** 2 * T  # 77.366 e⁻
    var = mu + 2.8 ** 2 + 3.0 * T + 1 / (12 * 0.38 ** 2)
    assert mu == pytest.approx(77.366, abs=1e-3)
    assert snr.snr_frame_db(PHI, exposure_s=T) == pytest.approx(10 * math.log10(mu ** 2 / var), abs=1e-9)
    assert snr.snr_frame_db(PHI, exposure_s=T) == pytest.approx(18.4355, abs=1e-3)
    assert snr.snr_frame_db(1e18, exposure_s=T) == -np.inf  # 77 ke⁻ > 10.5 ke⁻ full well


def test_free_running_spad_hand_value():
    q = 0.45 * 0.105
    phi = PHI * 16.38e-6 ** 2  # photons s⁻¹ on the pixel
    qpt = q * phi * 100e-9
    bias = 7.5 / (q * phi) + 0.001 / 0.999 * math.exp(-qpt)
    rel_var = bias ** 2 + (1 + qpt) / (q * phi * T) + (1 + qpt) ** 4 / (12 * q ** 2 * phi ** 2 * T ** 2)
    assert snr.snr_spad_free_running_db(PHI, exposure_s=T) == pytest.approx(-10 * math.log10(rel_var), abs=1e-9)
    assert snr.snr_spad_free_running_db(PHI, exposure_s=T) == pytest.approx(21.03, abs=0.01)


def test_gated_spad_hand_value_and_monte_carlo():
    q = 0.45 * 0.105
    gate = 10.24e-6
    n = T / gate
    xs = q * PHI * 16.38e-6 ** 2 * gate
    x = xs + 7.5 * gate
    bias = (0.001 + 4 * 0.001) * (1 - math.exp(-x)) / xs
    expected = -10 * math.log10(math.expm1(x) / (n * xs ** 2) + bias ** 2)
    assert snr.snr_spad_gated_db(PHI, exposure_s=T) == pytest.approx(expected, abs=1e-9)
    # the variance term against simulated binomial counts of the same estimator (no secondaries)
    rng = np.random.default_rng(5)
    n_int = 977
    counts = rng.binomial(n_int, -math.expm1(-x), size=200_000)
    est = (-np.log1p(-np.minimum(counts, n_int - 1) / n_int) / gate - 7.5) / (q * 16.38e-6 ** 2)
    rel_var = np.var(est) / PHI ** 2
    analytic = math.expm1(x) / (n_int * xs ** 2)
    assert rel_var == pytest.approx(analytic, rel=0.03)  # sampling error ≈ 0.3 %; delta-method bias ≈ 1 % at ~120 counts
    # the auto gate keeps x at the optimum until the gate reaches its 5.75 ns floor
    assert snr.snr_spad_gated_db(1e19, exposure_s=T, gate_s="auto") > snr.snr_spad_gated_db(1e19, exposure_s=T)


def test_event_snr_hand_value():
    eta = 0.5 * 0.77
    lam = eta * PHI * 4.86e-6 ** 2 + 30.0
    fc = 3000.0 * lam / (lam + 1e6)
    var_log = math.pi * fc / lam
    delta = math.log(2.0) * (1 - math.exp(-2 * math.pi * fc * T))
    p_e = 0.5 * math.erfc(-(delta - 0.3) / math.sqrt(0.03 ** 2 + 2 * var_log) / math.sqrt(2))
    f1 = snr.reference_flux_1lx()
    assert f1 == pytest.approx(0.18 * 0.9 / 16 * 1.389e16, rel=2e-3)
    lam1 = eta * f1 * 4.86e-6 ** 2 + 30.0
    noise = T * (1.0 * math.sqrt(lam1 / lam) + 0.1)
    expected = 10 * math.log10(p_e * delta / 0.3 / noise)
    assert snr.snr_events_db(PHI, 1.0, window_s=T) == pytest.approx(expected, abs=1e-9)
    # a larger contrast change gives a better SNR (the paper's second observation)
    assert snr.snr_events_db(PHI, 1.0) > snr.snr_events_db(PHI, 0.3)


def test_snr_cli_draws_a_figure(tmp_path):
    out = tmp_path / "snr.png"
    assert main(["snr", "--out", str(out)]) == 0
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] > 300 and img.std() > 10
    assert (np.abs(img[..., 0].astype(int) - img[..., 2]) > 80).sum() > 1000  # coloured curves drawn

"""Evaluation metrics (docs/methods.md) against hand-computed values; alignment = exact least squares; MTF."""

import colour
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from simspad.evaluate import metrics
from simspad.evaluate.protocol import evaluation_indices
from simspad.scenes.assets.textures import siemens_star


def test_psnr_of_a_known_mse():
    gt = np.zeros((16, 16))
    assert metrics.psnr_db(np.full((16, 16), 0.1), gt) == pytest.approx(20.0, abs=1e-9)  # MSE 0.01
    rec = gt.copy()
    rec[:4] = 0.5  # MSE = 0.25 * 0.25 = 0.0625 -> 12.0412 dB
    assert metrics.psnr_db(rec, gt) == pytest.approx(-10 * np.log10(0.0625), abs=1e-9)
    assert metrics.psnr_db(gt, gt) == metrics.PSNR_CAP_DB


def test_display_mapping_hand_values():
    W = 200.0
    img = np.array([[-5.0, 0.0, 0.002 * W, 0.5 * W, W, 3 * W]])
    expected = [0.0, 0.0, 12.92 * 0.002, 1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0, 1.0]
    np.testing.assert_allclose(metrics.display_map(img, W)[0], expected, atol=2e-7)
    assert expected[3] == pytest.approx(0.735357, abs=1e-6)
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(metrics.srgb_encode(x), colour.cctf_encoding(x, function="sRGB"), atol=1e-6)
    with pytest.raises(ValueError):
        metrics.display_map(img, 0.0)


def test_white_point_is_the_99th_percentile_and_streams_exactly():
    values = np.arange(1, 1001, dtype=np.float64).reshape(10, 10, 10)
    # rank k = 0.99 * 999 = 989.01 -> 990 + 0.01 * (991 - 990)
    assert metrics.white_point(values) == pytest.approx(990.01)
    chunks = metrics.iter_chunks(lambda s: values[s], 10, chunk=3)
    assert metrics.white_point(chunks) == pytest.approx(990.01)
    rng = np.random.default_rng(1)
    frames = rng.lognormal(0, 2, (12, 20, 30)).astype(np.float32)
    frames[4] = 7.0  # many ties
    chunked = metrics.iter_chunks(lambda s: frames[s], 12, chunk=5)
    assert metrics.streamed_percentile(chunked, 99) == pytest.approx(float(np.percentile(frames.astype(np.float64), 99)), rel=1e-12)
    # force the histogram-narrowing path: keep at most 50 values in memory
    k = 3456
    v = metrics._order_statistic(chunked, k, float(frames.min()), float(frames.max()), max_keep=50)
    assert v == np.sort(frames.ravel())[k]
    assert metrics.white_point(np.zeros((2, 3, 3))) == 1.0  # all dark: a usable fallback


def test_order_statistic_narrows_down_to_ranges_a_few_ulps_wide():
    # values packed within a few ulps of 7 (and a spread elsewhere): narrowing ends on ranges whose 4097 edges
    # repeat, where numpy's equal-width histogram refuses and the explicit edges must take over
    rng = np.random.default_rng(5)
    ulps = np.nextafter(7.0, np.inf) - 7.0
    values = np.concatenate([7.0 + ulps * rng.integers(-3, 4, 3000), rng.lognormal(2, 1, 2000)])
    rng.shuffle(values)
    chunked = metrics.iter_chunks(lambda s: values[s], values.size, chunk=700)
    ordered = np.sort(values)
    for k in (0, 1234, 2500, 4000, values.size - 1):
        assert metrics._order_statistic(chunked, k, float(values.min()), float(values.max()), max_keep=20) == ordered[k]


def test_aligned_scoring_is_the_exact_least_squares_fit():
    rng = np.random.default_rng(3)
    W = 50.0
    gt = rng.uniform(0.0, 80.0, (20, 24))
    rec = 0.1 * gt ** 0.8 + rng.uniform(-1.0, 1.0, (20, 24))  # arbitrary scale, a few negative values hit the floor
    a, b = metrics.affine_log_fit(rec, gt)
    x = np.log(np.maximum(rec, 1e-3 * np.percentile(rec, 99))).ravel()
    y = np.log(np.maximum(gt, 1e-3 * np.percentile(gt, 99))).ravel()
    (a_ref, b_ref), *_ = np.linalg.lstsq(np.stack([x, np.ones_like(x)], 1), y, rcond=None)
    assert a == pytest.approx(a_ref, rel=1e-10)
    assert b == pytest.approx(b_ref, rel=1e-10, abs=1e-12)
    s = metrics.frame_scores(rec, gt, W, absolute_scale=False)
    aligned = np.exp(b_ref) * np.maximum(rec, 0.0) ** a_ref  # the fit applied to the reconstruction itself
    expected = metrics.psnr_db(metrics.display_map(aligned, W), metrics.display_map(gt, W))
    assert s["psnr_db"] == pytest.approx(expected, abs=1e-6)
    assert (s["fit_a"], s["fit_b"]) == (pytest.approx(a), pytest.approx(b))


def test_alignment_undoes_a_power_law_and_scale_but_absolute_scoring_does_not():
    rng = np.random.default_rng(4)
    gt = rng.uniform(5.0, 100.0, (16, 16))
    rec = 7.0 * gt ** 0.6  # what an events-only method with unknown gain and contrast would give
    aligned = metrics.frame_scores(rec, gt, 100.0, absolute_scale=False)
    absolute = metrics.frame_scores(rec, gt, 100.0, absolute_scale=True)
    assert aligned["psnr_db"] > 60.0 and aligned["fit_a"] == pytest.approx(1 / 0.6, rel=1e-6)
    assert absolute["psnr_db"] < 25.0 and np.isnan(absolute["fit_a"])
    assert metrics.ssim(metrics.display_map(gt, 100.0), metrics.display_map(gt, 100.0)) == pytest.approx(1.0)


def test_evaluation_grid_selects_ground_truth_instants():
    t = np.arange(21) / 2000.0 + 0.25  # 2 kHz ground truth
    np.testing.assert_array_equal(evaluation_indices(t, 1000.0), np.arange(0, 21, 2))
    np.testing.assert_array_equal(evaluation_indices(t, 4000.0), np.arange(21))  # coarser GT: all instants


def _star(size=128, cycles=36, shift=(0, 0)):
    img = siemens_star(size, cycles)[..., 1]
    return np.roll(img, shift, axis=(0, 1)) * 1e12


def test_mtf_of_a_gaussian_blur_matches_the_analytic_mtf50():
    gt = _star(shift=(3, -5))
    cy, cx, n, r_max = metrics.siemens_star_geometry(gt)
    assert n == 36
    assert abs(cy - (63.5 + 3)) <= 1.0 and abs(cx - (63.5 - 5)) <= 1.0
    f, m = metrics.mtf_siemens(gt, gt, geometry=(cy, cx, n, r_max))
    np.testing.assert_allclose(m, 1.0, atol=1e-9)
    sigma = 1.2
    f, m = metrics.mtf_siemens(gaussian_filter(gt, sigma), gt, geometry=(cy, cx, n, r_max))
    expected = np.sqrt(np.log(2) / (2 * np.pi ** 2)) / sigma  # exp(-2π²σ²f²) = 0.5
    assert metrics.mtf50(f, m) == pytest.approx(expected, rel=0.05)
    sharper = metrics.mtf50(*metrics.mtf_siemens(gaussian_filter(gt, 0.8), gt, geometry=(cy, cx, n, r_max)))
    assert sharper > metrics.mtf50(f, m)


def test_mtf_at_fixed_frequencies_matches_the_gaussian_mtf_and_says_where_it_cannot_measure():
    gt = _star(shift=(2, -3))
    geometry = metrics.siemens_star_geometry(gt)
    sigma = 0.7
    f, m = metrics.mtf_siemens(gaussian_filter(gt, sigma), gt, geometry=geometry)
    for f0 in metrics.STAR_FREQS_CYC_PX:
        assert metrics.mtf_at(f, m, f0) == pytest.approx(np.exp(-2 * np.pi ** 2 * sigma ** 2 * f0 ** 2), abs=0.04)
    # An unblurred reconstruction keeps full contrast up to Nyquist: MTF50 is not measurable (NaN, not 0.5)
    # while the fixed-frequency figures still read 1.
    f, m = metrics.mtf_siemens(gt, gt, geometry=geometry)
    assert np.isnan(metrics.mtf50(f, m))
    assert metrics.mtf_at(f, m, 0.25) == pytest.approx(1.0, abs=1e-9)
    # Below the lowest frequency the star's outer circle carries (n / 2π r_max), the figure is not invented.
    assert np.isnan(metrics.mtf_at(f, m, 0.5 * f.min()))

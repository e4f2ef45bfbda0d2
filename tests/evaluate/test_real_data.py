"""Scoring without ground truth: the evaluation instants and the Siemens-star MTF relative to a perfect print."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from simspad.evaluate.real_data import StarMtf, evaluation_times

N_CYCLES, CONTRAST, CENTRE = 32, 0.8, 128.0


@pytest.fixture(scope="module")
def star() -> np.ndarray:
    """A 257 × 257 square-wave star of 32 periods and Michelson contrast 0.8, each pixel the mean of 8 × 8
    samples (a pixel's area, as a sensor integrates it)."""
    ss, n = 8, 257
    ys, xs = np.mgrid[0:n * ss, 0:n * ss]
    ys, xs = (ys + 0.5) / ss - 0.5, (xs + 0.5) / ss - 0.5
    fine = 0.5 * (1 + CONTRAST * np.sign(np.sin(N_CYCLES * np.arctan2(ys - CENTRE, xs - CENTRE))))
    return fine.reshape(n, ss, n, ss).mean(axis=(1, 3)) * 1e10


def _mtf(img, contrast=CONTRAST, n_cycles=None):
    m = StarMtf({"center_x_px": CENTRE, "center_y_px": CENTRE, "radius_px": 120.0, "n_cycles": n_cycles,
                 "contrast": contrast})
    m.add(img)
    return m


def test_a_sharp_star_of_the_declared_contrast_has_mtf_one_at_low_frequency(star):
    m = _mtf(star)
    f, mtf = m.result()
    assert m.n == N_CYCLES  # found from the image
    assert f[0] < 0.05 and mtf[0] == pytest.approx(1.0, abs=0.02)
    assert f[-1] == pytest.approx(0.5, rel=1e-6)
    # a print of half the contrast, declared as such, measures the same; declared as 0.8 it measures half
    half = (star - star.mean()) * 0.5 + star.mean()
    np.testing.assert_allclose(_mtf(half, contrast=CONTRAST / 2).result()[1], mtf, rtol=1e-9)
    np.testing.assert_allclose(_mtf(half).result()[1], mtf / 2, rtol=1e-9)


@pytest.mark.parametrize("sigma", [1.0, 1.5])
def test_gaussian_blur_divides_out_as_its_transfer_function(star, sigma):
    """MTF(blurred) / MTF(sharp) = exp(−2π²σ²f²), the Gaussian's transfer function, below 0.25 cycles/px."""
    f, sharp = _mtf(star, n_cycles=N_CYCLES).result()
    _, blurred = _mtf(gaussian_filter(star, sigma), n_cycles=N_CYCLES).result()
    low = f <= 0.25
    np.testing.assert_allclose(blurred[low] / sharp[low], np.exp(-2 * np.pi ** 2 * sigma ** 2 * f[low] ** 2),
                               atol=0.02)


def test_mean_over_frames():
    m = StarMtf({"center_x_px": 20.0, "center_y_px": 20.0, "radius_px": 18.0, "n_cycles": 8, "contrast": 1.0})
    yy, xx = np.mgrid[0:41, 0:41]
    a = 1 + 0.5 * np.sin(8 * np.arctan2(yy - 20.0, xx - 20.0))
    m.add(a)
    m.add(np.ones_like(a))  # no modulation
    one = StarMtf({"center_x_px": 20.0, "center_y_px": 20.0, "radius_px": 18.0, "n_cycles": 8, "contrast": 1.0})
    one.add(a)
    np.testing.assert_allclose(m.result()[1], one.result()[1] / 2, rtol=1e-12)


class _Rec:
    def __init__(self, attrs, duration_s):
        self.attrs, self.duration_s = attrs, duration_s


def test_evaluation_instants_cover_the_span_end_excluded():
    t = evaluation_times(_Rec({"t_start_s": 0.0, "t_end_s": 0.02}, 0.02), 1000.0)
    np.testing.assert_array_equal(t, np.arange(20) / 1000.0)
    t = evaluation_times(_Rec({"t_start_s": 0.5}, 0.0105), 1000.0)
    assert t.size == 11 and t[0] == 0.5 and t[-1] < 0.5105

"""The compiled SSIM and the NumPy PSNR give scikit-image's figures to the last bit."""

import numpy as np
import pytest
from scipy import ndimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from simspad.evaluate import metrics
from simspad.evaluate.ssim import box_filter_reflect, mean_ssim


@pytest.mark.parametrize("shape", [(60, 80), (7, 7), (9, 300), (200, 150)])
def test_ssim_and_psnr_are_scikit_images(shape):
    rng = np.random.default_rng(sum(shape))
    gt = ndimage.gaussian_filter(rng.random(shape), 1.5)
    rec = np.clip(gt + rng.normal(size=shape) * 0.05, 0, 1)
    for win in (3, 5, 7):
        assert mean_ssim(gt, rec, win, 1.0) == structural_similarity(gt, rec, data_range=1.0, win_size=win)
    assert metrics.ssim(rec, gt) == structural_similarity(gt, rec, data_range=1.0, win_size=7)
    assert metrics.psnr_db(rec, gt) == peak_signal_noise_ratio(gt, rec, data_range=1.0)
    np.testing.assert_array_equal(box_filter_reflect(rec, 5), ndimage.uniform_filter(rec, 5))


def test_ssim_of_identical_frames_is_one_and_bad_windows_are_refused():
    img = np.random.default_rng(0).random((20, 30))
    assert mean_ssim(img, img) == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError):
        mean_ssim(img, img, win_size=4)
    with pytest.raises(ValueError):
        mean_ssim(img, img[:, :10])

"""QBP (S): hierarchical alignment recovers a translating texture's shift; the aligned merge beats the plain sum."""

import numpy as np
from scipy import ndimage

from simspad.methods.qbp import estimate_block_flow, qbp_merge, remove_hot_pixels


def _texture(shape, rng):
    tex = ndimage.gaussian_filter(rng.random(shape), 2.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    return 0.05 + 0.6 * tex  # detection probability per bin


def _blocks(p_img, shifts, block_bins, rng, crop):
    """Binomial block sums of the texture translated by ``shifts`` (dy, dx) px, cropped to ``crop``."""
    out, truth = [], []
    for dy, dx in shifts:
        p = ndimage.shift(p_img, (dy, dx), order=3, mode="wrap")[crop]
        p = np.clip(p, 0.0, 1.0)
        out.append(rng.binomial(block_bins, p).astype(np.float64))
        truth.append(block_bins * p)
    return out, truth


def test_alignment_recovers_subpixel_translation():
    rng = np.random.default_rng(7)
    big = _texture((96, 112), rng)
    crop = (slice(16, 80), slice(16, 96))  # 64 × 80
    shifts = [(0.0, 0.0), (1.7, -2.3), (-3.4, 4.6)]
    blocks, _ = _blocks(big, shifts, 100, rng, crop)
    for (dy, dx), b in zip(shifts[1:], blocks[1:]):
        fy, fx = estimate_block_flow(blocks[0], b, tile_px=16)
        # content moved by +d, so img(p + d) = ref(p): the flow equals the shift
        inner = (slice(1, -1), slice(1, -1))
        assert abs(np.median(fy[inner]) - dy) < 0.25, (np.median(fy[inner]), dy)
        assert abs(np.median(fx[inner]) - dx) < 0.25, (np.median(fx[inner]), dx)
        assert np.mean(np.hypot(fy[inner] - dy, fx[inner] - dx) < 0.25) > 0.8


def test_aligned_merge_beats_unaligned_sum():
    rng = np.random.default_rng(8)
    big = _texture((96, 112), rng)
    crop = (slice(16, 80), slice(16, 96))
    nb, ref = 7, 3
    shifts = [(0.6 * (k - ref), -0.9 * (k - ref)) for k in range(nb)]  # constant velocity
    blocks, truth = _blocks(big, shifts, 100, rng, crop)
    merged, _ = qbp_merge(blocks, ref, 100, tile_px=16)
    plain = np.sum(blocks, axis=0)
    target = nb * truth[ref]
    inner = (slice(6, -6), slice(6, -6))

    def psnr(img):
        mse = np.mean((img[inner] - target[inner]) ** 2)
        return 10 * np.log10((nb * 100) ** 2 / mse)

    p_merged, p_plain, p_ref_only = psnr(merged), psnr(plain), psnr(nb * blocks[ref])
    assert p_merged > p_plain + 3.0, (p_merged, p_plain)
    assert p_merged > p_ref_only + 3.0, (p_merged, p_ref_only)  # merging reduces photon noise


def test_hot_pixels_are_replaced_by_the_neighbourhood_median():
    counts = np.full((5, 5), 10.0)
    counts[2, 2] = 90.0
    hot = np.zeros((5, 5), bool)
    hot[2, 2] = True
    out = remove_hot_pixels(counts, hot)
    assert out[2, 2] == 10.0 and out.sum() == 250.0

"""Mean SSIM of two frames in one compiled pass, the figure of ``skimage.metrics.structural_similarity``.

scikit-image's SSIM (uniform 7×7 window, sample covariance, ``data_range`` given) is a dozen array calls, five
of them SciPy box filters: on the 80×60 frames of the mini dataset their call overhead was most of the scoring
time. :func:`mean_ssim` computes the same figure with the same arithmetic, operation by operation — SciPy's box
filter (running sum over the line extended by reflection, axis 0 then axis 1, each output the sum divided by
the window), scikit-image's expressions for the SSIM map, then NumPy's mean over its interior — so the scores are
scikit-image's to the last bit (``tests/evaluate/test_ssim.py`` compares them).
"""

from __future__ import annotations

import numba
import numpy as np


#: scikit-image's SSIM constants: C1 = (K1·R)², C2 = (K2·R)² for the data range R.
K1 = 0.01
K2 = 0.03


@numba.njit(cache=True)
def _reflect_index(n, size):
    # Sample index of each position of a line of n extended by size // 2 on the left and the rest on the right,
    # mode "reflect" (… b a | a b … y z | z y …).
    s1 = size // 2
    period = 2 * n
    idx = np.empty(n + size - 1, np.int64)
    for k in range(n + size - 1):
        j = (k - s1) % period
        idx[k] = period - 1 - j if j >= n else j
    return idx


@numba.njit(cache=True)
def box_filter_reflect(a, size):
    """``scipy.ndimage.uniform_filter(a, size)`` (mode ``"reflect"``) of a 2-D float64 array, bit for bit: along
    axis 0, then axis 1, a running sum over the extended line (first ``size`` samples added in order, then the
    entering minus the leaving sample at each step), each output that sum divided by ``size``."""
    H, W = a.shape
    tmp = np.empty((H, W))
    rows = _reflect_index(H, size)
    t = np.zeros(W)
    for k in range(size):
        for x in range(W):
            t[x] += a[rows[k], x]
    for x in range(W):
        tmp[0, x] = t[x] / size
    for y in range(1, H):
        enter = rows[y + size - 1]
        leave = rows[y - 1]
        for x in range(W):
            t[x] += a[enter, x] - a[leave, x]
            tmp[y, x] = t[x] / size
    out = np.empty((H, W))
    cols = _reflect_index(W, size)
    for y in range(H):
        s = 0.0
        for k in range(size):
            s += tmp[y, cols[k]]
        out[y, 0] = s / size
        for x in range(1, W):
            s += tmp[y, cols[x + size - 1]] - tmp[y, cols[x - 1]]
            out[y, x] = s / size
    return out


@numba.njit(cache=True)
def ssim_map(im1, im2, win, c1, c2, cov_norm):
    """scikit-image's SSIM map (uniform window ``win``, constants c1, c2, covariance factor ``cov_norm``)."""
    ux = box_filter_reflect(im1, win)
    uy = box_filter_reflect(im2, win)
    uxx = box_filter_reflect(im1 * im1, win)
    uyy = box_filter_reflect(im2 * im2, win)
    uxy = box_filter_reflect(im1 * im2, win)
    H, W = im1.shape
    out = np.empty((H, W))
    for y in range(H):
        for x in range(W):
            mx = ux[y, x]
            my = uy[y, x]
            vx = cov_norm * (uxx[y, x] - mx * mx)
            vy = cov_norm * (uyy[y, x] - my * my)
            vxy = cov_norm * (uxy[y, x] - mx * my)
            a1 = 2 * mx * my + c1
            a2 = 2 * vxy + c2
            b1 = mx * mx + my * my + c1
            b2 = vx + vy + c2
            out[y, x] = (a1 * a2) / (b1 * b2)
    return out


def mean_ssim(im1: np.ndarray, im2: np.ndarray, win_size: int = 7, data_range: float = 1.0) -> float:
    """Mean SSIM of two 2-D images (uniform ``win_size`` window, sample covariance, the window's half-width
    left out at the edges): ``skimage.metrics.structural_similarity(im1, im2, win_size=win_size,
    data_range=data_range)``, bit for bit.

    Parameters
    ----------
    im1, im2 : ndarray [H, W]
        Images of the same shape (converted to float64), both sides at least ``win_size``.
    win_size : int
        Odd window side (pixels).
    data_range : float
        Dynamic range of the images (1 for display-mapped frames).
    """
    im1 = np.ascontiguousarray(im1, np.float64)
    im2 = np.ascontiguousarray(im2, np.float64)
    if im1.shape != im2.shape or im1.ndim != 2:
        raise ValueError(f"expected two 2-D images of one shape, got {im1.shape} and {im2.shape}")
    if win_size % 2 != 1 or win_size > min(im1.shape):
        raise ValueError(f"window of {win_size} px: expected an odd size within the image {im1.shape}")
    n_window = win_size ** 2
    s = ssim_map(im1, im2, int(win_size), (K1 * data_range) ** 2, (K2 * data_range) ** 2, n_window / (n_window - 1))
    pad = (win_size - 1) // 2
    # NumPy's mean, as scikit-image takes it: its summation order over a 2-D view depends on NumPy's buffering.
    return float(s[pad:s.shape[0] - pad, pad:s.shape[1] - pad].mean(dtype=np.float64))

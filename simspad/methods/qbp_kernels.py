"""Compiled kernels of QBP's alignment and merge (:mod:`simspad.methods.qbp`).

Each kernel does per pixel or per tile what :mod:`scipy.ndimage` and NumPy calls did on whole arrays, in one pass
without temporaries: at the mini dataset's 80×60 px a burst is hundreds of small array operations, whose call
overhead was most of QBP's time. The arithmetic follows SciPy's and NumPy's operation by operation, so results
agree with them to the last bit with SciPy 1.17 and NumPy 2 (``tests/methods/test_qbp_kernels.py`` holds the
array-call versions and checks each kernel against them):

- :func:`bilinear_nearest` is ``ndimage.map_coordinates(img, coords, order=1, mode="nearest")`` at one point
  (weights ``1 − t`` and ``1 − (1 − t)``, nodes clamped to the image, products summed in SciPy's order);
- :func:`median3x3_nearest` is ``ndimage.median_filter(a, size=3, mode="nearest")`` (an exact selection);
- :func:`uniform_filter_nearest` is ``ndimage.uniform_filter(a, size, mode="nearest")`` (SciPy's running sum,
  axis 0 then axis 1);
- :func:`lucas_kanade_tiles` is QBP's per-tile Lucas–Kanade refinement, its tile sums added in the order of
  NumPy's ``sum(axis=(1, 3))`` over the zero-padded tiles (row by row, each row pairwise).

Every kernel is compiled with ``cache=True``: a new process loads them from numba's cache instead of compiling.
"""

from __future__ import annotations

import numba
import numpy as np

from simspad.physics.pairwise_sum import pairwise_sum


@numba.njit(cache=True, inline="always")
def _node(i, n):
    return min(max(i, 0), n - 1)


@numba.njit(cache=True)
def bilinear_nearest(img, cy, cx):
    """``img`` at (cy, cx) by bilinear interpolation, samples outside the image taken from its nearest edge pixel
    (SciPy's order-1 spline with ``mode="nearest"``, bit for bit with SciPy 1.17: weights from the unclamped
    coordinate, nodes clamped to the image)."""
    H, W = img.shape
    fy = np.floor(cy)
    fx = np.floor(cx)
    wy0 = 1.0 - (cy - fy)
    wx0 = 1.0 - (cx - fx)
    wy1 = 1.0 - wy0
    wx1 = 1.0 - wx0
    y0 = _node(int(fy), H)
    x0 = _node(int(fx), W)
    y1 = _node(int(fy) + 1, H)
    x1 = _node(int(fx) + 1, W)
    t = 0.0
    t += img[y0, x0] * wy0 * wx0
    t += img[y0, x1] * wy0 * wx1
    t += img[y1, x0] * wy1 * wx0
    t += img[y1, x1] * wy1 * wx1
    return t


@numba.njit(cache=True)
def dense_warp(img, tile_fy, tile_fx, tile):
    """``img(p + f(p))`` with ``f`` the per-tile flow interpolated bilinearly from the tile centres to every pixel
    (edges clamped): QBP's ``warp(img, dense_flow(fy), dense_flow(fx))`` in one pass."""
    H, W = img.shape
    out = np.empty((H, W))
    half = (tile - 1) / 2.0
    for y in range(H):
        v = (y - half) / tile
        for x in range(W):
            u = (x - half) / tile
            fy = bilinear_nearest(tile_fy, v, u)
            fx = bilinear_nearest(tile_fx, v, u)
            out[y, x] = bilinear_nearest(img, y + fy, x + fx)
    return out


@numba.njit(cache=True)
def median3x3_nearest(a):
    """3×3 median with edge samples repeated (``ndimage.median_filter(a, 3, mode="nearest")``)."""
    ny, nx = a.shape
    out = np.empty((ny, nx))
    buf = np.empty(9)
    for i in range(ny):
        for j in range(nx):
            k = 0
            for di in range(-1, 2):
                ii = min(max(i + di, 0), ny - 1)
                for dj in range(-1, 2):
                    jj = min(max(j + dj, 0), nx - 1)
                    v = a[ii, jj]
                    m = k  # insertion sort: nine values
                    while m > 0 and buf[m - 1] > v:
                        buf[m] = buf[m - 1]
                        m -= 1
                    buf[m] = v
                    k += 1
            out[i, j] = buf[4]
    return out


@numba.njit(cache=True)
def subpixel_median(d, cost):
    """3×3 median (edges repeated) of the integer displacement ``d`` [ny, nx] plus the vertex of the parabola
    through the L2 costs at ``d`` − 1, ``d``, ``d`` + 1 (``cost`` [ny, nx, 3]; offset in [−0.5, 0.5], 0 where the
    costs are not a finite upward parabola)."""
    ny, nx = d.shape
    f = np.empty((ny, nx))
    for i in range(ny):
        for j in range(nx):
            c0, c1, c2 = cost[i, j, 0], cost[i, j, 1], cost[i, j, 2]
            den = c0 - 2.0 * c1 + c2
            off = 0.0
            if np.isfinite(den) and den > 0:
                off = min(max(0.5 * (c0 - c2) / den, -0.5), 0.5)
            f[i, j] = d[i, j] + off
    return median3x3_nearest(f)


@numba.njit(cache=True)
def uniform_filter_nearest(a, size):
    """Box mean of side ``size`` with edge samples repeated (``ndimage.uniform_filter(a, size, mode="nearest")``),
    SciPy's running sum: along axis 0, then axis 1, the first ``size`` samples of the extended line added in
    order, then the entering minus the leaving sample at each step, each output that sum divided by ``size``."""
    H, W = a.shape
    s1 = size // 2
    tmp = np.empty((H, W))
    t = np.zeros(W)
    for k in range(size):
        r = min(max(k - s1, 0), H - 1)
        for x in range(W):
            t[x] += a[r, x]
    for x in range(W):
        tmp[0, x] = t[x] / size
    for y in range(1, H):
        enter = min(max(y + size - 1 - s1, 0), H - 1)
        leave = min(max(y - 1 - s1, 0), H - 1)
        for x in range(W):
            t[x] += a[enter, x] - a[leave, x]
            tmp[y, x] = t[x] / size
    out = np.empty((H, W))
    for y in range(H):
        v = 0.0
        for k in range(size):
            v += tmp[y, min(max(k - s1, 0), W - 1)]
        out[y, 0] = v / size
        for x in range(1, W):
            v += tmp[y, min(max(x + size - 1 - s1, 0), W - 1)] - tmp[y, min(max(x - 1 - s1, 0), W - 1)]
            out[y, x] = v / size
    return out


@numba.njit(cache=True)
def merge_block(total, ref, p_ref_var, warped, block_bins, c, window_px):
    """Add one aligned block to ``total``, pulled towards ``ref`` where their mismatch exceeds the binomial noise
    (the Wiener-like shrinkage of :func:`simspad.methods.qbp.robust_merge`); ``p_ref_var`` is p(1 − p) of the
    reference's per-bin detection probability p."""
    H, W = ref.shape
    var_in = np.empty((H, W))
    sq = np.empty((H, W))
    for y in range(H):
        for x in range(W):
            p = min(max(warped[y, x] / block_bins, 0.0), 1.0)
            var_in[y, x] = block_bins * (p * (1 - p) + p_ref_var[y, x])
            d = warped[y, x] - ref[y, x]
            sq[y, x] = d * d
    var = uniform_filter_nearest(var_in, window_px)
    m = uniform_filter_nearest(sq, window_px)
    for y in range(H):
        for x in range(W):
            excess = max(m[y, x] - var[y, x], 0.0)
            a = excess / (excess + c * var[y, x] + 1e-12)
            w = warped[y, x]
            total[y, x] += w + a * (ref[y, x] - w)


@numba.njit(cache=True)
def _gradient(a, axis, out):
    # np.gradient with unit spacing: central differences inside, one-sided at the two edges.
    H, W = a.shape
    if axis == 0:
        for x in range(W):
            out[0, x] = a[1, x] - a[0, x]
            out[H - 1, x] = a[H - 1, x] - a[H - 2, x]
        for y in range(1, H - 1):
            for x in range(W):
                out[y, x] = (a[y + 1, x] - a[y - 1, x]) / 2.0
    else:
        for y in range(H):
            out[y, 0] = a[y, 1] - a[y, 0]
            out[y, W - 1] = a[y, W - 1] - a[y, W - 2]
            for x in range(1, W - 1):
                out[y, x] = (a[y, x + 1] - a[y, x - 1]) / 2.0


@numba.njit(cache=True)
def lucas_kanade_tiles(ref, img, gy_ref, gx_ref, flow_y, flow_x, tile, iterations):
    """Lucas–Kanade refinement of a per-tile flow [ny, nx] (in place) such that ``img(p + f) ≈ ref(p)``.

    Each iteration warps ``img`` by the piecewise-constant tile flow (bilinear, edges clamped), averages its
    gradient with the reference's (``gy_ref``, ``gx_ref``), zeroes pixels whose sample fell outside the image,
    solves each tile's 2×2 normal equations and moves the flow by the step clipped to ±0.5 px (no step where the
    system is singular). Tile sums add row by row, each row pairwise, as NumPy's ``sum(axis=(1, 3))`` of the
    zero-padded tiles does: the flow is the array-call version's to the last bit.
    """
    H, W = ref.shape
    ny, nx = flow_y.shape
    w = np.empty((H, W))
    inside = np.empty((H, W))
    gwy = np.empty((H, W))
    gwx = np.empty((H, W))
    rows = np.zeros((5, tile))  # one tile row of gy², gy·gx, gx², gy·it, gx·it (zero past the image)
    sums = np.empty(5)
    for _ in range(iterations):
        for y in range(H):
            i = y // tile  # each tile's flow read once per row: two integer divisions per pixel were a fifth of this
            for j in range(nx):
                fy = flow_y[i, j]
                fx = flow_x[i, j]
                for x in range(j * tile, min((j + 1) * tile, W)):
                    sy = y + fy
                    sx = x + fx
                    w[y, x] = bilinear_nearest(img, sy, sx)
                    inside[y, x] = 1.0 if (sy >= 0 and sy <= H - 1 and sx >= 0 and sx <= W - 1) else 0.0
        _gradient(w, 0, gwy)
        _gradient(w, 1, gwx)
        for i in range(ny):
            for j in range(nx):
                for q in range(5):
                    sums[q] = 0.0
                for y in range(i * tile, min((i + 1) * tile, H)):
                    for k in range(tile):
                        x = j * tile + k
                        if x >= W:
                            for q in range(5):
                                rows[q, k] = 0.0
                            continue
                        gy = 0.5 * (gwy[y, x] + gy_ref[y, x]) * inside[y, x]
                        gx = 0.5 * (gwx[y, x] + gx_ref[y, x]) * inside[y, x]
                        it = w[y, x] - ref[y, x]
                        rows[0, k] = gy * gy
                        rows[1, k] = gy * gx
                        rows[2, k] = gx * gx
                        rows[3, k] = gy * it
                        rows[4, k] = gx * it
                    for q in range(5):
                        sums[q] += pairwise_sum(rows[q], 0, tile)
                a11, a12, a22, b1, b2 = sums[0], sums[1], sums[2], sums[3], sums[4]
                det = a11 * a22 - a12 * a12
                if det > 1e-9 * (a11 + a22) ** 2 + 1e-30:
                    sy = -(a22 * b1 - a12 * b2) / det
                    sx = -(a11 * b2 - a12 * b1) / det
                    flow_y[i, j] += min(max(sy, -0.5), 0.5)
                    flow_x[i, j] += min(max(sx, -0.5), 0.5)

"""QBP's compiled kernels against the SciPy/NumPy array calls they replace (the QBP code before the kernels)."""

import numpy as np
import pytest
from scipy import ndimage

from simspad.methods import qbp_kernels as k
from simspad.methods.qbp import TileMatches, TileSearch, estimate_block_flow, match_tiles

# Bilinear sampling outside the image: SciPy 1.17 weights the clamped nodes by the unclamped coordinate, older
# versions clamp the coordinate first; the two agree to rounding.
ROUNDING = dict(rtol=1e-13, atol=1e-11)


def _grid(shape):
    return np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)


def _warp(img, fy, fx):
    yy, xx = _grid(img.shape)
    return ndimage.map_coordinates(img, [yy + fy, xx + fx], order=1, mode="nearest")


def _dense_flow(tile_flow, shape, tile):
    yy, xx = _grid(shape)
    uv = np.stack([(yy - (tile - 1) / 2.0) / tile, (xx - (tile - 1) / 2.0) / tile])
    return ndimage.map_coordinates(tile_flow, uv, order=1, mode="nearest")


def _tile_sum(a, tile, grid):
    pad = np.zeros((grid[0] * tile, grid[1] * tile))
    pad[:a.shape[0], :a.shape[1]] = a
    return pad.reshape(grid[0], tile, grid[1], tile).sum(axis=(1, 3))


def _lucas_kanade(r, m, gy_r, gx_r, flow_y, flow_x, tile, iterations):
    """QBP's Lucas–Kanade refinement as array calls."""
    grid = flow_y.shape
    yy, xx = _grid(r.shape)
    for _ in range(iterations):
        fy = np.repeat(np.repeat(flow_y, tile, 0), tile, 1)[:r.shape[0], :r.shape[1]]
        fx = np.repeat(np.repeat(flow_x, tile, 0), tile, 1)[:r.shape[0], :r.shape[1]]
        w = _warp(m, fy, fx)
        inside = (yy + fy >= 0) & (yy + fy <= r.shape[0] - 1) & (xx + fx >= 0) & (xx + fx <= r.shape[1] - 1)
        gw = np.gradient(w)
        gy, gx = 0.5 * (gw[0] + gy_r) * inside, 0.5 * (gw[1] + gx_r) * inside
        it = w - r
        a11, a12, a22 = (_tile_sum(p, tile, grid) for p in (gy * gy, gy * gx, gx * gx))
        b1, b2 = _tile_sum(gy * it, tile, grid), _tile_sum(gx * it, tile, grid)
        det = a11 * a22 - a12 * a12
        ok = det > 1e-9 * (a11 + a22) ** 2 + 1e-30
        with np.errstate(invalid="ignore", divide="ignore"):
            flow_y = flow_y + np.clip(np.where(ok, -(a22 * b1 - a12 * b2) / det, 0.0), -0.5, 0.5)
            flow_x = flow_x + np.clip(np.where(ok, -(a11 * b2 - a12 * b1) / det, 0.0), -0.5, 0.5)
    return flow_y, flow_x


@pytest.mark.parametrize("shape", [(60, 80), (7, 5), (1, 4)])
def test_filters_are_scipys_to_the_last_bit(shape):
    rng = np.random.default_rng(1)
    img = rng.random(shape) * 100
    np.testing.assert_array_equal(k.median3x3_nearest(img), ndimage.median_filter(img, 3, mode="nearest"))
    for size in (3, 5):
        np.testing.assert_array_equal(k.uniform_filter_nearest(img, size),
                                      ndimage.uniform_filter(img, size, mode="nearest"))
    coords = rng.normal(size=(2,) + shape) * 5 + _grid(shape)  # many samples fall outside the image
    got = np.array([[k.bilinear_nearest(img, coords[0, i, j], coords[1, i, j]) for j in range(shape[1])]
                    for i in range(shape[0])])
    np.testing.assert_allclose(got, ndimage.map_coordinates(img, coords, order=1, mode="nearest"), **ROUNDING)


def test_warp_subpixel_and_merge_match_the_array_calls():
    rng = np.random.default_rng(2)
    img = rng.random((60, 80)) * 100
    tfy, tfx = rng.normal(size=(2, 4, 5)) * 3
    np.testing.assert_allclose(k.dense_warp(img, tfy, tfx, 16),
                               _warp(img, _dense_flow(tfy, img.shape, 16), _dense_flow(tfx, img.shape, 16)),
                               **ROUNDING)
    cost = rng.random((4, 5, 3))
    cost[0, 0, 0] = np.inf  # a candidate outside the image
    cost[1, 1] = [1.0, 2.0, 3.0]  # no minimum inside: offset clipped to -0.5
    d = rng.integers(-3, 3, (4, 5))
    den = cost[..., 0] - 2 * cost[..., 1] + cost[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.where(np.isfinite(den) & (den > 0), 0.5 * (cost[..., 0] - cost[..., 2]) / den, 0.0)
    np.testing.assert_array_equal(k.subpixel_median(d, cost),
                                  ndimage.median_filter(d + np.clip(np.nan_to_num(off), -0.5, 0.5), 3, mode="nearest"))
    ref = rng.binomial(100, 0.3, (60, 80)).astype(float)
    blocks = [rng.binomial(100, 0.3, (60, 80)).astype(float) for _ in range(3)]
    total = ref.copy()
    p_ref = np.clip(ref / 100, 0, 1)
    expected = ref.copy()
    for w in blocks:
        k.merge_block(total, ref, p_ref * (1 - p_ref), w, 100.0, 1.0, 5)
        p = np.clip(w / 100, 0, 1)
        var = ndimage.uniform_filter(100 * (p * (1 - p) + p_ref * (1 - p_ref)), 5, mode="nearest")
        m = ndimage.uniform_filter((w - ref) ** 2, 5, mode="nearest")
        excess = np.maximum(m - var, 0.0)
        expected += w + excess / (excess + var + 1e-12) * (ref - w)
    np.testing.assert_array_equal(total, expected)


def test_lucas_kanade_matches_the_array_calls_and_recovers_a_shift():
    rng = np.random.default_rng(3)
    r = ndimage.gaussian_filter(rng.random((60, 80)), 2) * 100
    m = ndimage.shift(r, (0.7, -1.2), order=3, mode="nearest")  # content moved by (+0.7, -1.2)
    gy, gx = np.gradient(r)
    fy, fx = np.zeros((4, 5)), np.zeros((4, 5))
    ey, ex = _lucas_kanade(r, m, gy, gx, fy, fx, 16, 3)
    k.lucas_kanade_tiles(r, m, gy, gx, fy, fx, 16, 3)
    np.testing.assert_allclose(fy, ey, **ROUNDING)
    np.testing.assert_allclose(fx, ex, **ROUNDING)
    inner = (slice(1, -1), slice(1, -1))
    assert abs(np.median(fy[inner]) - 0.7) < 0.05 and abs(np.median(fx[inner]) + 1.2) < 0.05


def test_block_flow_is_deterministic():
    rng = np.random.default_rng(4)
    ref = rng.binomial(100, 0.4, (60, 80)).astype(float)
    img = np.roll(ref, 2, axis=1)
    a = estimate_block_flow(ref, img)
    b = estimate_block_flow(ref.copy(), img.copy())
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def _match_tiles_per_pixel(ref, img, tile, radius, init_dy, init_dx, l2):
    """QBP's integer block matching as first written: every displacement of the window in turn, every pixel's
    displaced sample tested against the image bounds, the first smallest cost kept, then the L2 costs at ±1."""
    H, W = ref.shape

    def cost(y0, y1, x0, x1, cy, cx, sq):
        acc, cnt = 0.0, 0
        for y in range(y0, y1):
            for x in range(x0, x1):
                if 0 <= y + cy < H and 0 <= x + cx < W:
                    d = img[y + cy, x + cx] - ref[y, x]
                    acc += d * d if sq else abs(d)
                    cnt += 1
        return np.inf if 2 * cnt < (y1 - y0) * (x1 - x0) or cnt == 0 else acc / cnt

    ny, nx = init_dy.shape
    dy, dx = np.zeros((ny, nx), np.int64), np.zeros((ny, nx), np.int64)
    cost_y, cost_x = np.zeros((ny, nx, 3)), np.zeros((ny, nx, 3))
    for ty in range(ny):
        for tx in range(nx):
            y0, x0 = ty * tile, tx * tile
            y1, x1 = min(y0 + tile, H), min(x0 + tile, W)
            best, by, bx = np.inf, init_dy[ty, tx], init_dx[ty, tx]
            for ddy in range(-radius, radius + 1):
                for ddx in range(-radius, radius + 1):
                    c = cost(y0, y1, x0, x1, init_dy[ty, tx] + ddy, init_dx[ty, tx] + ddx, l2)
                    if c < best:
                        best, by, bx = c, init_dy[ty, tx] + ddy, init_dx[ty, tx] + ddx
            dy[ty, tx], dx[ty, tx] = by, bx
            for j in range(3):
                cost_y[ty, tx, j] = cost(y0, y1, x0, x1, by + j - 1, bx, True)
                cost_x[ty, tx, j] = cost(y0, y1, x0, x1, by, bx + j - 1, True)
    return dy, dx, cost_y, cost_x


@pytest.mark.parametrize("radius, l2", [(4, False), (1, True), (2, True), (0, True)])
def test_match_tiles_is_the_per_pixel_search_bit_for_bit(radius, l2):
    rng = np.random.default_rng(radius)
    ref = ndimage.gaussian_filter(rng.random((30, 37)), 1.5) * 100
    img = np.roll(ref, (1, -2), axis=(0, 1)) + rng.normal(0, 1, ref.shape)
    tile = 8
    grid = (4, 5)  # the last row and column of tiles are partial; edge tiles search partly outside the image
    init_dy = rng.integers(-3, 4, grid)
    init_dx = rng.integers(-3, 4, grid)
    got = TileMatches(np.zeros(grid, np.int64), np.zeros(grid, np.int64), np.zeros(grid + (3,)), np.zeros(grid + (3,)))
    match_tiles(ref, img, TileSearch(tile, radius, init_dy, init_dx, l2), got)
    want = _match_tiles_per_pixel(ref, img, tile, radius, init_dy, init_dx, l2)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)

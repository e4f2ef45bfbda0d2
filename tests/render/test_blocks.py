"""Blocks of an image rendered for real inside synthesized keyframes: the grid, and Mitsuba's block renders
against whole renders of the same pose (tiny renders)."""

import numpy as np
import pytest

from simspad.motion.generators import static_pose
from simspad.motion.trajectory import TrajectorySet
from simspad.render.blocks import (
    BLOCK_CALL_SAMPLES,
    TILE_PX,
    block_grid,
    block_seed,
    block_size_px,
    block_window,
    blocks_of_tiles,
    render_fraction,
    tiles_of_blocks,
)
from simspad.render.mitsuba_scene import PSF_REACH_PX, MitsubaScene
from simspad.render.renderer import select_variant
from simspad.scenes.library import resolve_scene


def test_block_grid_covers_the_image_once():
    assert block_size_px(64, 48) == TILE_PX and block_size_px(512, 512) == 4 * TILE_PX
    assert block_size_px(320, 240) == 3 * TILE_PX
    width, height, b = 100, 70, 16
    rows, cols = block_grid(width, height, b)
    covered = np.zeros((height, width), dtype=int)
    for r in range(rows):
        for c in range(cols):
            covered[block_window(r, c, width, height, b)] += 1
    assert (covered == 1).all()
    tiles = np.zeros((-(-height // TILE_PX), -(-width // TILE_PX)), dtype=bool)
    tiles[3, 5] = True  # in block (1, 2) of 2 × 2 tiles
    blocks = blocks_of_tiles(tiles, b)
    assert blocks.shape == (rows, cols) and np.argwhere(blocks).tolist() == [[1, 2]]
    back = tiles_of_blocks(blocks, tiles.shape, b)
    assert back.shape == tiles.shape and back.sum() == 4 and back[tiles].all()
    assert render_fraction(blocks, width, height, b, 2, 16) == pytest.approx((20 * 20 * 16 + BLOCK_CALL_SAMPLES) / (7000 * 16))
    seeds = {block_seed(7, r, c) for r in range(rows) for c in range(cols)}
    assert len(seeds) == rows * cols and all(0 <= s < 2**32 for s in seeds)
    assert block_seed(7, 1, 2) == block_seed(7, 1, 2) != block_seed(8, 1, 2)


@pytest.fixture(scope="module")
def _office():
    select_variant()
    info = resolve_scene("office")
    ts = TrajectorySet(camera=static_pose(), objects={}, source="<static>")  # the scene's own camera pose
    ms = MitsubaScene(info, ts, 72, 40, 16)
    ms.set_pose(ms.rest_camera_to_world, {})
    return ms


def test_blocks_render_what_a_whole_render_gives_up_to_monte_carlo_noise(_office):
    # Every block, border and partial ones included (72 x 40 in 8-pixel blocks, a 2-pixel blur margin), pasted
    # together: the same mean radiance as a whole render, and differences of the size two whole renders with
    # different seeds have, not larger (a misplaced block, a missing margin or a wrong blur would add the
    # image's edges to it).
    ms = _office
    assert ms.block_px == TILE_PX and PSF_REACH_PX == 2
    whole, other = ms.render_radiance(3), ms.render_radiance(4)
    pasted = np.zeros_like(whole)
    rows, cols = block_grid(ms.width, ms.height, ms.block_px)
    for r in range(rows):
        for c in range(cols):
            pasted[block_window(r, c, ms.width, ms.height, ms.block_px)] = ms.render_radiance_block(3, r, c)
    y = lambda a: a.mean(axis=-1)  # noqa: E731
    seed_to_seed = np.sqrt(np.mean((y(other) - y(whole)) ** 2))
    blocks_to_whole = np.sqrt(np.mean((y(pasted) - y(whole)) ** 2))
    assert 0.7 * seed_to_seed < blocks_to_whole < 1.3 * seed_to_seed, (blocks_to_whole, seed_to_seed)
    # Mean within 4 standard errors of the per-pixel difference.
    d = y(pasted) - y(whole)
    assert abs(d.mean()) < 4 * d.std() / np.sqrt(d.size)
    # The image border too: its pixels see the edge-repeating blur of a whole render.
    edge = np.r_[y(pasted)[0], y(pasted)[-1]] - np.r_[y(whole)[0], y(whole)[-1]]
    edge_ref = np.r_[y(other)[0], y(other)[-1]] - np.r_[y(whole)[0], y(whole)[-1]]
    assert np.sqrt(np.mean(edge ** 2)) < 1.6 * np.sqrt(np.mean(edge_ref ** 2))
    # Deterministic: the same block and seed give the same pixels.
    np.testing.assert_array_equal(ms.render_radiance_block(3, 1, 2), ms.render_radiance_block(3, 1, 2))

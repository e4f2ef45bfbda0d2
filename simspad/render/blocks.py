"""Square pixel blocks of a keyframe that are rendered for real inside a synthesized keyframe.

Where the two warps of a synthesized keyframe disagree in a few places only (a bright textured window behind
thin mullions, a specular highlight), rendering those places is cheaper than rendering the whole keyframe. The
image is cut into a fixed grid of square blocks (:func:`block_size_px`), aligned with the disagreement tiles
(:data:`TILE_PX`); a block is rendered with a margin as wide as the reconstruction blur's
reach (:data:`simspad.render.mitsuba_scene.PSF_REACH_PX`), so its pixels are those a whole render would give up to
Monte Carlo noise. The grid is fixed in screen space, and each block has its own seed, so a block's samples
stay put from keyframe to keyframe as a whole render's do (frozen screen-space noise).
"""

from __future__ import annotations

import numpy as np

#: Side of the square tiles over which the two warps' difference is compared with the render noise, pixels
#: (:mod:`simspad.render.warp.synthesis`); blocks are whole numbers of tiles. Defined here, below the warp package,
#: because the Mitsuba scene renders blocks and the warp package uses the Mitsuba scene.
TILE_PX = 8

#: Largest side of a block, pixels (a multiple of the disagreement tile). Larger blocks waste less on margins and
#: per-render overhead (≈ 30 ms a call here); smaller ones follow the disagreement more closely.
BLOCK_PX = 4 * TILE_PX
#: What one render call costs beyond its samples, in samples: Mitsuba traces the integrator and launches its kernel
#: again for every block. Measured here (plant, llvm): a 12×12-pixel block at 16 spp costs 6 % of a 128×96 render
#: (its samples 1.2 %), a 28×28 block at 64 spp 2.9 % of a 256×192 render (samples 1.6 %): ≈ 0.05–0.15 s a call.
BLOCK_CALL_SAMPLES = 16384
#: Blocks across the image's shorter side, at least (down to one tile per block).
MIN_BLOCKS_ACROSS = 8


def block_size_px(width: int, height: int) -> int:
    """Side of the blocks of a ``width`` × ``height`` image: the largest multiple of the tile up to
    :data:`BLOCK_PX` that still cuts the shorter side into :data:`MIN_BLOCKS_ACROSS` blocks."""
    k = min(width, height) // (MIN_BLOCKS_ACROSS * TILE_PX)
    return int(np.clip(k, 1, BLOCK_PX // TILE_PX)) * TILE_PX


def block_grid(width: int, height: int, block_px: int) -> tuple[int, int]:
    """Blocks per column and per row: (rows, columns); the last row and column may be partial."""
    return -(-height // block_px), -(-width // block_px)


def blocks_of_tiles(tiles: np.ndarray, block_px: int) -> np.ndarray:
    """Blocks (bool [rows, columns]) holding at least one of ``tiles`` (bool, tile grid of :data:`TILE_PX`)."""
    k = block_px // TILE_PX
    th, tw = tiles.shape
    rows, cols = -(-th // k), -(-tw // k)
    padded = np.zeros((rows * k, cols * k), dtype=bool)
    padded[:th, :tw] = tiles
    return padded.reshape(rows, k, cols, k).any(axis=(1, 3))


def tiles_of_blocks(blocks: np.ndarray, tile_shape: tuple[int, int], block_px: int) -> np.ndarray:
    """Tiles (bool, tile grid of shape ``tile_shape``) that ``blocks`` (bool [rows, columns]) cover."""
    k = block_px // TILE_PX
    tiles = np.repeat(np.repeat(blocks, k, axis=0), k, axis=1)
    return tiles[:tile_shape[0], :tile_shape[1]]


def block_window(row: int, col: int, width: int, height: int, block_px: int) -> tuple[slice, slice]:
    """The image pixels (rows, columns) of block (row, col)."""
    return (slice(row * block_px, min((row + 1) * block_px, height)),
            slice(col * block_px, min((col + 1) * block_px, width)))


def render_fraction(blocks: np.ndarray, width: int, height: int, block_px: int, margin_px: int, spp: int) -> float:
    """What rendering ``blocks`` (with ``margin_px`` extra pixels on every side) costs, as a fraction of a whole
    render: their pixel samples plus :data:`BLOCK_CALL_SAMPLES` for each block's own render call."""
    side = block_px + 2 * margin_px
    return float(blocks.sum()) * (side * side * spp + BLOCK_CALL_SAMPLES) / (width * height * spp)


def block_seed(seed: int, row: int, col: int) -> int:
    """Seed (32 bits) of block (row, col) of a render with ``seed``: blocks must not share one sample pattern."""
    x = (int(seed) * 0x9E3779B97F4A7C15 + (row << 20) + col + 1) % 2**64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) % 2**64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) % 2**64
    return (x ^ (x >> 31)) & 0xFFFFFFFF


__all__ = ["BLOCK_CALL_SAMPLES", "BLOCK_PX", "MIN_BLOCKS_ACROSS", "block_size_px", "block_grid", "block_seed", "block_window", "blocks_of_tiles",
           "render_fraction", "tiles_of_blocks"]

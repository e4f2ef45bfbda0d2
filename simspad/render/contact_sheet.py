"""``simspad scenes --contact-sheet``: render every scene once, tone-map, label, and tile them into one PNG.

Each scene is rendered by :func:`simspad.render.renderer.render_sequence` at the first instant of its default
trajectory (so the sheet shows what a dataset sequence starting at t = 0 sees), into a temporary directory that
is removed afterwards. Tone mapping is global: exposure from the log-average luminance and Reinhard's extended
operator with the white point at the 99.5th luminance percentile, so HDR scenes (a window > 10³ brighter than
the room) keep both the view outside and the dim interior visible.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from simspad.io.atomic import atomic_path
from simspad.io.trajectory_files import load_trajectory
from simspad.physics.colour import srgb_encode
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.timeline import Timeline
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.scenes.library import resolve_scene

#: Size of one tile (width, height) in pixels and its samples per pixel.
TILE_SIZE = (240, 180)
TILE_SPP = 64
#: Height of the name strip above each tile, pixels.
LABEL_HEIGHT_PX = 18


def tone_map(rgb: np.ndarray, key: float = 0.18, white_percentile: float = 99.5) -> np.ndarray:
    """Linear HDR RGB ``[H, W, 3]`` → sRGB-encoded display values in [0, 1] (global Reinhard operator).

    Parameters
    ----------
    rgb : ndarray
        Linear radiance, any positive scale.
    key : float
        Display value that the log-average luminance maps to.
    white_percentile : float
        Luminance percentile that maps to display white (at least the exposure-scaled value 1).
    """
    rgb = np.maximum(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0)
    lum = luminance_from_rgb(rgb).astype(np.float64)
    log_avg = float(np.exp(np.mean(np.log(lum + 1e-6))))
    x = rgb * (key / max(log_avg, 1e-12))
    white = max(float(np.percentile(lum, white_percentile)) * key / max(log_avg, 1e-12), 1.0)
    x = x * (1.0 + x / white**2) / (1.0 + x)
    x = np.clip(x, 0.0, 1.0)
    return srgb_encode(x).astype(np.float64)


def render_preview(scene, resolution=TILE_SIZE, spp: int = TILE_SPP, seed: int = 0) -> np.ndarray:
    """Linear RGB ``[H, W, 3]`` of ``scene`` at t = start of its default trajectory (a 1 ms, 2-keyframe render)."""
    info = resolve_scene(scene)
    t0 = load_trajectory(info.default_trajectory).t_start if info.default_trajectory else 0.0
    with tempfile.TemporaryDirectory(prefix="simspad-sheet-") as tmp:
        render_sequence(info, None, RenderSettings(duration_s=1e-3, start_s=t0, resolution=resolution, spp=spp,
                                                   seed=seed, max_flow_px=1e6, min_rate_hz=1e3),
                        out_dir=Path(tmp) / "render", progress=False)
        return np.array(Timeline.open(Path(tmp) / "render").rgb_keyframe(0), dtype=np.float32)


def _label(tile: np.ndarray, text: str) -> Image.Image:
    h, w = tile.shape[:2]
    img = Image.new("RGB", (w, h + LABEL_HEIGHT_PX), (20, 20, 20))
    img.paste(Image.fromarray((tile * 255 + 0.5).astype(np.uint8)), (0, LABEL_HEIGHT_PX))
    draw = ImageDraw.Draw(img)
    draw.text((6, 2), text, fill=(235, 235, 235), font=ImageFont.load_default(size=13))
    return img


def write_contact_sheet(path: Path, scenes, columns: int = 3, resolution=TILE_SIZE, spp: int = TILE_SPP) -> Path:
    """Render ``scenes`` (``SceneInfo``s or names), tone-map and tile them with their names into a PNG at ``path``.

    Returns
    -------
    Path
        ``path``, written atomically (nothing is left behind on failure).
    """
    tiles = [_label(tone_map(render_preview(s, resolution, spp)), getattr(s, "name", str(s))) for s in scenes]
    if not tiles:
        raise ValueError("no scenes to put on a contact sheet")
    tw, th = tiles[0].size
    columns = max(1, min(columns, len(tiles)))
    rows = -(-len(tiles) // columns)
    gap = 4
    sheet = Image.new("RGB", (columns * tw + (columns + 1) * gap, rows * th + (rows + 1) * gap), (60, 60, 60))
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        sheet.paste(tile, (gap + c * (tw + gap), gap + r * (th + gap)))
    path = Path(path)
    with atomic_path(path) as tmp:
        sheet.save(tmp, format="PNG", optimize=True)
    return path

"""Procedural textures as linear float32 arrays ``[H, W, 3]`` in [0, 1] (reflectance or relative radiance).

Each generator is deterministic (fixed seeds) and cached; callers must not modify the returned arrays (they
are marked read-only). Text and music notation are drawn with Pillow's built-in font, so nothing is downloaded.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from PIL import Image, ImageDraw, ImageFont
from scipy import ndimage

from simspad.physics.colour import srgb_decode as srgb_to_linear


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float32)
    a.setflags(write=False)
    return a


def value_noise(shape: tuple[int, int], scale_px: float, seed: int) -> np.ndarray:
    """Smooth noise in [0, 1] with feature size ``scale_px`` pixels (cubic-upsampled random lattice)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    gh, gw = max(2, int(np.ceil(h / scale_px)) + 3), max(2, int(np.ceil(w / scale_px)) + 3)
    lattice = rng.random((gh, gw))
    yy = np.arange(h) / scale_px + 1.0
    xx = np.arange(w) / scale_px + 1.0
    out = ndimage.map_coordinates(lattice, np.meshgrid(yy, xx, indexing="ij"), order=3, mode="reflect")
    out -= out.min()
    return out / max(out.max(), 1e-12)


def fractal_noise(shape: tuple[int, int], scale_px: float, seed: int, octaves: int = 4) -> np.ndarray:
    """Sum of value-noise octaves (halving scale, halving amplitude), normalised to [0, 1]."""
    acc = np.zeros(shape)
    amp = 1.0
    for k in range(octaves):
        acc += amp * value_noise(shape, max(scale_px / 2**k, 1.0), seed + 101 * k)
        amp *= 0.5
    acc -= acc.min()
    return acc / max(acc.max(), 1e-12)


def _mix(a, b, t) -> np.ndarray:
    t = np.asarray(t)[..., None]
    return (1 - t) * np.asarray(a, dtype=np.float64) + t * np.asarray(b, dtype=np.float64)


@lru_cache(maxsize=None)
def siemens_star(size_px: int = 1024, cycles: int = 36, black: float = 0.03, white: float = 0.85,
                 supersample: int = 4) -> np.ndarray:
    """ISO 12233-style sinusoid-free (binary) Siemens star on a white square, ``cycles`` black + white pairs.

    The star fills the inscribed circle of radius 0.95 (UV units from the centre); outside it is white, with a
    thin black ring at the rim and a black centre dot, as on printed targets. Antialiased by supersampling.
    """
    n = size_px * supersample
    c = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(c, -c)
    r = np.hypot(x, y)
    theta = np.arctan2(y, x)
    sector = (np.floor(theta / (2 * np.pi) * 2 * cycles) % 2) == 0
    v = np.where(sector, black, white)
    v = np.where(r > 0.95, white, v)
    v = np.where((r > 0.95) & (r < 0.965), black, v)
    v = np.where(r < 0.02, black, v)
    v = v.reshape(size_px, supersample, size_px, supersample).mean(axis=(1, 3))
    return _frozen(np.repeat(v[..., None], 3, axis=2))


@lru_cache(maxsize=None)
def wood(shape: tuple[int, int] = (512, 1024), light=(0.62, 0.42, 0.24), dark=(0.36, 0.21, 0.10),
         seed: int = 7) -> np.ndarray:
    """Plank wood: growth rings along U (long axis) distorted by noise, fine grain streaks, plank seams."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    warp = fractal_noise(shape, 120, seed) * 40 + fractal_noise(shape, 30, seed + 1) * 6
    rings = 0.5 + 0.5 * np.sin(2 * np.pi * (yy + warp) / 23.0)
    rings = rings**3
    grain = fractal_noise((h, w // 8 + 1), 3, seed + 2, octaves=2)
    grain = np.repeat(grain, 8, axis=1)[:, :w]
    t = np.clip(0.55 * rings + 0.35 * grain + 0.15 * fractal_noise(shape, 60, seed + 3), 0, 1)
    rgb = _mix(srgb_to_linear(light), srgb_to_linear(dark), t)
    seams = (np.abs((yy % (h / 4)) - 0) < 2.0)
    rgb[seams] *= 0.35
    return _frozen(rgb)


@lru_cache(maxsize=None)
def carpet(shape: tuple[int, int] = (512, 512), seed: int = 11) -> np.ndarray:
    """Patterned rug: nested diamonds and a border over a woven (checked micro-texture) fabric."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    d = np.abs(u - 0.5) + np.abs(v - 0.5)
    tile = np.abs(((u * 6) % 1) - 0.5) + np.abs(((v * 6) % 1) - 0.5)
    base = srgb_to_linear((0.55, 0.12, 0.10))
    navy = srgb_to_linear((0.10, 0.14, 0.35))
    cream = srgb_to_linear((0.85, 0.78, 0.60))
    gold = srgb_to_linear((0.80, 0.58, 0.18))
    rgb = np.broadcast_to(base, (h, w, 3)).copy()
    rgb[tile < 0.22] = navy
    rgb[(tile > 0.30) & (tile < 0.34)] = cream
    rgb[(d > 0.25) & (d < 0.30)] = gold
    rgb[(d < 0.12)] = cream
    rgb[(d < 0.07)] = navy
    border = (np.minimum.reduce([u, v, 1 - u, 1 - v]) < 0.06)
    rgb[border] = navy
    rgb[(np.minimum.reduce([u, v, 1 - u, 1 - v]) > 0.035) & border & ((np.floor(u * 40) + np.floor(v * 40)) % 2 == 0)] = cream
    yy, xx = np.mgrid[0:h, 0:w]
    weave = 0.85 + 0.15 * (((yy // 2) + (xx // 2)) % 2)
    wear = 0.8 + 0.2 * fractal_noise(shape, 40, seed)
    return _frozen(rgb * (weave * wear)[..., None])


@lru_cache(maxsize=None)
def plaster(shape: tuple[int, int] = (256, 256), colour=(0.78, 0.76, 0.70), seed: int = 3,
            amount: float = 0.18) -> np.ndarray:
    """Painted wall: a flat colour with soft blotches and fine roughness."""
    n = 0.6 * fractal_noise(shape, 50, seed) + 0.4 * value_noise(shape, 2, seed + 9)
    return _frozen(srgb_to_linear(colour) * (1 - amount + amount * n)[..., None])


@lru_cache(maxsize=None)
def wallpaper(shape: tuple[int, int] = (512, 512), seed: int = 5) -> np.ndarray:
    """Striped wallpaper with small repeated motifs (diamonds) between the stripes."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    base = srgb_to_linear((0.72, 0.70, 0.58))
    stripe = srgb_to_linear((0.35, 0.45, 0.40))
    rgb = np.broadcast_to(base, (h, w, 3)).copy()
    su = (u * 8) % 1
    rgb[(su < 0.12)] = stripe
    motif = np.abs(((u * 8) % 1) - 0.56) * 3 + np.abs(((v * 12) % 1) - 0.5)
    rgb[motif < 0.18] = srgb_to_linear((0.55, 0.25, 0.20))
    return _frozen(rgb * (0.9 + 0.1 * fractal_noise(shape, 30, seed))[..., None])


@lru_cache(maxsize=None)
def bricks(shape: tuple[int, int] = (512, 512), rows: int = 16, seed: int = 13) -> np.ndarray:
    """Running-bond brick wall with per-brick colour variation and grey mortar."""
    h, w = shape
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    bh = h / rows
    bw = 2.2 * bh
    row = (yy // bh).astype(int)
    xs = xx + (row % 2) * bw / 2
    col = (xs // bw).astype(int)
    tint = rng.uniform(0.7, 1.15, size=(rows + 1, int(w / bw) + 3))
    brick = srgb_to_linear((0.62, 0.28, 0.20)) * tint[row, col][..., None]
    mortar = ((yy % bh) < 0.12 * bh) | ((xs % bw) < 0.08 * bh)
    rgb = np.where(mortar[..., None], srgb_to_linear((0.62, 0.60, 0.56)), brick)
    return _frozen(rgb * (0.8 + 0.2 * fractal_noise(shape, 6, seed + 1))[..., None])


def _lines_of_text(seed: int, n: int) -> list[str]:
    words = ("photon spad event frame gate bin flux lux exposure kalman filter deblur noise sensor pixel "
             "render timeline radiance trajectory def return import numpy array for in if else while class "
             "self dataset recording quanta burst").split()
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        indent = "    " * int(rng.integers(0, 3))
        out.append(indent + " ".join(rng.choice(words, size=int(rng.integers(2, 8)))))
    return out


@lru_cache(maxsize=None)
def screen_text(shape: tuple[int, int] = (384, 640), seed: int = 17) -> np.ndarray:
    """A code editor on a dark background: coloured lines of text, a title bar and a side panel."""
    h, w = shape
    img = Image.new("RGB", (w, h), (24, 26, 33))
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=max(8, h // 26))
    draw.rectangle([0, 0, w, h // 14], fill=(60, 64, 80))
    draw.rectangle([0, h // 14, w // 6, h], fill=(36, 38, 48))
    colours = [(220, 220, 200), (120, 200, 255), (250, 170, 90), (150, 230, 140), (230, 120, 160)]
    rng = np.random.default_rng(seed)
    line_h = h // 24
    for i, line in enumerate(_lines_of_text(seed, 22)):
        y = h // 14 + 4 + i * line_h
        draw.text((w // 6 + 10, y), line, fill=colours[int(rng.integers(len(colours)))], font=font)
        draw.text((6, y), f"{i + 1:>3}", fill=(110, 110, 120), font=font)
    rgb = np.asarray(img, dtype=np.float64) / 255.0
    return _frozen(srgb_to_linear(rgb))


@lru_cache(maxsize=None)
def book_cover(index: int, shape: tuple[int, int] = (256, 64)) -> np.ndarray:
    """A book spine: a saturated colour with gold bands and a title printed along it."""
    palette = [(0.55, 0.08, 0.08), (0.08, 0.20, 0.45), (0.10, 0.35, 0.15), (0.85, 0.75, 0.55),
               (0.25, 0.10, 0.35), (0.90, 0.45, 0.10), (0.15, 0.15, 0.15), (0.60, 0.60, 0.62)]
    titles = ["OPTICS", "PHOTONS", "SIGNALS", "KALMAN", "NOISE", "SENSORS", "ALGEBRA", "EVENTS"]
    h, w = shape
    base = tuple(int(255 * c) for c in palette[index % len(palette)])
    ink = (235, 205, 120) if sum(base) < 400 else (30, 30, 30)
    img = Image.new("RGB", (h, w), base)  # drawn lying down, rotated to a spine below
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=int(w * 0.45))
    draw.rectangle([int(0.06 * h), 0, int(0.09 * h), w], fill=ink)
    draw.rectangle([int(0.91 * h), 0, int(0.94 * h), w], fill=ink)
    draw.text((int(0.15 * h), int(0.22 * w)), titles[index % len(titles)], fill=ink, font=font)
    spine = np.asarray(img.rotate(90, expand=True), dtype=np.float64) / 255.0
    return _frozen(srgb_to_linear(spine))


@lru_cache(maxsize=None)
def sheet_music(shape: tuple[int, int] = (560, 400), seed: int = 23) -> np.ndarray:
    """A printed score: staves of five lines, bar lines, clefs, note heads with stems and beams."""
    h, w = shape
    img = Image.new("L", (w, h), 238)
    draw = ImageDraw.Draw(img)
    rng = np.random.default_rng(seed)
    gap = h / 70.0
    font = ImageFont.load_default(size=int(3 * gap))
    draw.text((w * 0.3, gap * 1.5), "Nocturne No. 2", fill=20, font=font)
    for s in range(8):
        top = gap * 8 + s * gap * 7.6
        left, right = w * 0.06, w * 0.95
        for k in range(5):
            y = top + k * gap
            draw.line([(left, y), (right, y)], fill=25, width=max(1, int(gap / 5)))
        draw.ellipse([left + gap * 0.5, top + gap, left + gap * 2.2, top + gap * 3.4], outline=20,
                     width=max(1, int(gap / 3)))
        draw.line([(left + gap * 1.6, top - gap), (left + gap * 1.3, top + gap * 5)], fill=20,
                  width=max(1, int(gap / 3)))
        nbars = 4
        bar_w = (right - left - gap * 4) / nbars
        for b in range(nbars + 1):
            x = left + gap * 4 + b * bar_w
            draw.line([(x, top), (x, top + 4 * gap)], fill=20, width=max(1, int(gap / 4)))
        for b in range(nbars):
            n_notes = int(rng.choice([2, 3, 4, 4, 6, 8]))
            xs = left + gap * 4 + b * bar_w + (np.arange(n_notes) + 0.6) * bar_w / (n_notes + 0.4)
            pitches = rng.integers(-2, 10, size=n_notes)
            for x, p in zip(xs, pitches):
                y = top + 4 * gap - p * gap / 2
                filled = n_notes >= 3 or rng.random() < 0.5
                box = [x - gap * 0.65, y - gap * 0.45, x + gap * 0.65, y + gap * 0.45]
                if filled:
                    draw.ellipse(box, fill=15)
                else:
                    draw.ellipse(box, outline=15, width=max(1, int(gap / 4)))
                stem_up = p < 4
                sx = x + gap * 0.6 if stem_up else x - gap * 0.6
                draw.line([(sx, y), (sx, y - 3.3 * gap if stem_up else y + 3.3 * gap)], fill=15,
                          width=max(1, int(gap / 5)))
                for ledger in range(-2, p - 9, -2) if p >= 10 else []:
                    pass
                if p <= -2:
                    draw.line([(x - gap, top + 5 * gap), (x + gap, top + 5 * gap)], fill=20, width=1)
            if n_notes >= 6:
                draw.line([(xs[0] + gap * 0.6, top - gap * 1.5), (xs[-1] + gap * 0.6, top - gap * 1.5)],
                          fill=15, width=max(2, int(gap * 0.5)))
    grey = np.asarray(img, dtype=np.float64) / 255.0
    paper = grey[..., None] * srgb_to_linear((1.0, 0.97, 0.90))
    return _frozen(srgb_to_linear(np.clip(paper, 0, 1)))


@lru_cache(maxsize=None)
def outdoor_view(shape: tuple[int, int] = (256, 384), seed: int = 29) -> np.ndarray:
    """What a window shows, as relative radiance: bright sky with clouds over a tree line and a facade."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    sky = _mix(srgb_to_linear((0.55, 0.75, 1.0)), srgb_to_linear((0.9, 0.95, 1.0)), yy)
    clouds = np.clip(fractal_noise(shape, 60, seed) * 1.6 - 0.7, 0, 1)
    sky = _mix(sky, (1.0, 1.0, 1.0), clouds)
    horizon = 0.62 + 0.08 * fractal_noise((1, w), 25, seed + 1)[0] + 0.05 * value_noise((1, w), 6, seed + 2)[0]
    trees = yy > horizon[None, :]
    foliage = srgb_to_linear((0.18, 0.32, 0.12)) * (0.5 + 0.8 * fractal_noise(shape, 8, seed + 3))[..., None]
    rgb = np.where(trees[..., None], foliage * 0.5, sky)
    facade = (xx > 0.68) & (yy > 0.35)
    win = ((xx * 30) % 1 > 0.4) & ((yy * 18) % 1 > 0.45)
    rgb = np.where(facade[..., None], np.where(win[..., None], srgb_to_linear((0.25, 0.3, 0.38)),
                                               srgb_to_linear((0.85, 0.8, 0.72))), rgb)
    return _frozen(rgb)


@lru_cache(maxsize=None)
def poster(shape: tuple[int, int] = (384, 512), seed: int = 31) -> np.ndarray:
    """A busy printed poster: a grid of coloured circles, squares and bars with a heading (fan background)."""
    h, w = shape
    img = Image.new("RGB", (w, h), (236, 232, 220))
    draw = ImageDraw.Draw(img)
    rng = np.random.default_rng(seed)
    cols = [(200, 40, 40), (30, 90, 180), (240, 190, 30), (30, 140, 80), (30, 30, 30), (230, 110, 30)]
    cell = w // 8
    for gy in range(1, h // cell):
        for gx in range(8):
            x0, y0 = gx * cell + 4, gy * cell + 4
            c = cols[int(rng.integers(len(cols)))]
            kind = int(rng.integers(3))
            if kind == 0:
                draw.ellipse([x0, y0, x0 + cell - 8, y0 + cell - 8], fill=c)
            elif kind == 1:
                draw.rectangle([x0 + 6, y0 + 6, x0 + cell - 14, y0 + cell - 14], fill=c)
            else:
                for k in range(4):
                    draw.rectangle([x0, y0 + k * cell // 4, x0 + cell - 8, y0 + k * cell // 4 + cell // 10], fill=c)
    font = ImageFont.load_default(size=cell // 2)
    draw.text((cell // 3, cell // 5), "HIGH-SPEED IMAGING", fill=(20, 20, 20), font=font)
    rgb = np.asarray(img, dtype=np.float64) / 255.0
    return _frozen(srgb_to_linear(rgb))


@lru_cache(maxsize=None)
def terracotta(shape: tuple[int, int] = (128, 256), seed: int = 37) -> np.ndarray:
    """Clay pot: warm orange with horizontal throwing marks and blotches."""
    h, w = shape
    yy = np.mgrid[0:h, 0:w][0]
    rings = 0.9 + 0.1 * np.sin(yy / h * 2 * np.pi * 14)
    n = 0.8 + 0.2 * fractal_noise(shape, 20, seed)
    return _frozen(srgb_to_linear((0.72, 0.38, 0.22)) * (rings * n)[..., None])


@lru_cache(maxsize=None)
def leaf_texture(shape: tuple[int, int] = (32, 256), seed: int = 41) -> np.ndarray:
    """A long leaf (U along its length): green with a pale midrib and parallel veins, darker at the tip."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    base = _mix(srgb_to_linear((0.25, 0.50, 0.15)), srgb_to_linear((0.12, 0.30, 0.08)), u)
    veins = 0.85 + 0.15 * np.cos(v * 2 * np.pi * 6) ** 2
    rib = np.exp(-((v - 0.5) / 0.05) ** 2)
    rgb = base * veins[..., None]
    rgb = _mix(rgb, srgb_to_linear((0.62, 0.72, 0.35)), 0.7 * rib)
    return _frozen(rgb)


@lru_cache(maxsize=None)
def brushed_metal(shape: tuple[int, int] = (64, 256), seed: int = 43, tone: float = 0.55) -> np.ndarray:
    """Brushed-metal streaks along U."""
    h, w = shape
    rng = np.random.default_rng(seed)
    streaks = ndimage.gaussian_filter1d(rng.random((h, w)), sigma=20, axis=1)
    streaks = (streaks - streaks.min()) / np.ptp(streaks)
    return _frozen(np.repeat((tone * (0.8 + 0.4 * streaks))[..., None], 3, axis=2))


@lru_cache(maxsize=None)
def checker(shape: tuple[int, int] = (256, 256), n: int = 8, a: float = 0.1, b: float = 0.7) -> np.ndarray:
    """A plain checkerboard of ``n × n`` squares."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    c = ((yy * n // h) + (xx * n // w)) % 2
    return _frozen(np.repeat(np.where(c == 0, a, b)[..., None].astype(np.float64), 3, axis=2))

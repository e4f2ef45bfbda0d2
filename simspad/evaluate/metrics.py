"""Image-quality metrics of the evaluation protocol (:mod:`simspad.evaluate.protocol`).

Display mapping, applied identically to ground truth and reconstruction::

    D(x) = srgb( clip(x / W, 0, 1) )

with W the sequence white point (99th percentile of the ground-truth photon irradiance over the whole
sequence) and ``srgb`` the IEC 61966-2-1 transfer curve (12.92·v below 0.0031308, 1.055·v^(1/2.4) − 0.055
above; identical to ``colour.cctf_encoding(v, function="sRGB")``).

Methods without an absolute scale (events only) are scored after a per-frame least-squares fit in log space.
Each side is floored at 10⁻³ of its own frame's 99th percentile: the floor only keeps the logarithm finite, and
touches only pixels a thousand times darker than the frame's bright end (about sRGB 0.013 on the display)::

    x = ln(max(rec, ε_rec)),  ε_rec = 10⁻³ · p99(rec)        y = ln(max(gt, ε_gt)),  ε_gt = 10⁻³ · p99(gt)
    (a, b) = argmin Σ (a·x + b − y)²   over all pixels:  a = Σ(x − x̄)(y − ȳ) / Σ(x − x̄)²,  b = ȳ − a·x̄
    aligned = e^b · rec^a                                 (rec ≤ 0 ↦ 0; for a ≤ 0, e^b · max(rec, ε_rec)^a)

The same relative floor on both sides makes the fit exact on its own family: a reconstruction k·gt^γ (any gain
k > 0, any contrast γ > 0) has x = γ·y + ln k wherever neither side is floored, so a = 1/γ and b = −ln(k)/γ, and
the aligned frame is the ground truth itself — a submission of the ground truth (k = γ = 1) scores the PSNR cap
and SSIM 1 with or without absolute scale. The fit is applied to the reconstruction itself, not to its floored
copy, so pixels below the floor keep their own values.

PSNR and SSIM are scikit-image's (``peak_signal_noise_ratio``, ``structural_similarity``) with ``data_range=1``
on the display-mapped frames, computed here with the same arithmetic to the last bit (:func:`psnr_db` in NumPy,
SSIM in :mod:`simspad.evaluate.ssim`): scikit-image's PSNR alone imports ``scipy.stats`` (≈ 1 s of CPU in every
process), and its SSIM's call overhead dominated scoring. PSNR is capped at :data:`PSNR_CAP_DB` (a frame
identical to the ground truth would otherwise give +inf and poison the mean).

MTF (Siemens star): along circles of radius r around the star's centre the star is a periodic pattern of
``n_cycles`` periods, i.e. spatial frequency f = n_cycles / (2π r) cycles per pixel. On each circle h = F_n/F_0 is
the n_cycles-th angular Fourier coefficient over the mean (half the Michelson contrast of a sinusoid);
MTF(f) = Re(h_rec·conj(h_gt))/|h_gt|², the reconstruction's modulation relative to the ground truth's (projected
on its phase, so noise does not masquerade as contrast). The figures reported are the MTF at the fixed
frequencies :data:`STAR_FREQS_CYC_PX` (informative even when a method keeps more than half the contrast up to
Nyquist, as most do on a static star) and MTF50, the lowest frequency where it falls to 0.5 (NaN when it does
not inside the measured band).
"""

from __future__ import annotations

import functools
from typing import Callable, Iterable, Iterator

import numpy as np
from scipy.ndimage import map_coordinates

from simspad.evaluate.ssim import mean_ssim
from simspad.physics.colour import srgb_encode

PSNR_CAP_DB = 100.0
WHITE_PERCENTILE = 99.0
LOG_FLOOR_REL = 1e-3
#: Fewest cycles a Siemens star is assumed to have (lower harmonics are the star's outline, not its spokes).
MIN_STAR_CYCLES = 8
#: Spatial frequencies (cycles/px) at which the Siemens-star MTF is reported: half Nyquist and 0.8 Nyquist.
STAR_FREQS_CYC_PX = (0.25, 0.4)


# -- display mapping -------------------------------------------------------------------------------------------

def display_map(img: np.ndarray, white: float) -> np.ndarray:
    """Display-map linear irradiance ``img`` (ph s⁻¹ m⁻²) with white point ``white`` (same units) to [0, 1]."""
    if not (np.isfinite(white) and white > 0):
        raise ValueError(f"white point must be finite and > 0, got {white}")
    return srgb_encode(np.clip(np.asarray(img, dtype=np.float64) / white, 0.0, 1.0))


# -- white point -----------------------------------------------------------------------------------------------

def white_point(gt_frames: np.ndarray | Callable[[], Iterable[np.ndarray]]) -> float:
    """Sequence white point W: the 99th percentile of the ground-truth irradiance over the whole sequence.

    Parameters
    ----------
    gt_frames : ndarray [N,H,W] or callable
        The ground-truth frames, or a callable returning a fresh iterator of chunks (``[n,H,W]`` arrays) so
        long sequences are read a few frames at a time (memory independent of length; exact result, equal to
        ``np.percentile(all, 99)`` with linear interpolation).

    Returns
    -------
    float
        W in the units of the frames (ph s⁻¹ m⁻²). Falls back to the maximum, then 1, for an all-dark sequence.
    """
    if callable(gt_frames):
        w = streamed_percentile(gt_frames, WHITE_PERCENTILE)
        if not w > 0:
            w = max((float(np.max(c)) for c in gt_frames()), default=0.0)
    else:
        a = np.asarray(gt_frames, dtype=np.float64)
        w = float(np.percentile(a, WHITE_PERCENTILE))
        if not w > 0:
            w = float(a.max()) if a.size else 0.0
    return float(w) if w > 0 else 1.0


def _order_statistics(chunks: Callable[[], Iterable[np.ndarray]], rank: int, lo: float, hi: float,
                      max_keep: int = 1 << 22) -> tuple[float, float | None]:
    """The ``rank``-th smallest value (0-based) among all chunk values and, when it is in the same final bin,
    the next one (else None), by histogram narrowing.

    Each pass counts values below ``lo`` and histograms [lo, hi]; once the range holding the rank has few
    enough values, they are collected and sorted. Memory stays at ``max_keep`` values whatever the length.
    """
    def arrays():
        for c in chunks():
            yield np.asarray(c, dtype=np.float64).ravel()

    for _ in range(64):
        below = inside = 0
        for c in arrays():
            below += int(np.count_nonzero(c < lo))
            inside += int(np.count_nonzero((c >= lo) & (c <= hi)))
        if inside <= max_keep or hi <= lo:
            vals = np.concatenate([c[(c >= lo) & (c <= hi)] for c in arrays()] or [np.empty(0)])
            vals.sort()
            j = rank - below
            return float(vals[j]), (float(vals[j + 1]) if j + 1 < vals.size else None)
        edges = np.linspace(lo, hi, 4097)
        hist = np.zeros(4096, np.int64)
        # bins=4096 with range=(lo, hi) is numpy's equal-width path: O(n), over these very edges (it corrects each
        # index against them), so the same counts. bins=edges sorts every 65536 values instead (0.5 s of the white
        # point of 200 frames of 256², hours at paper scale); it is kept for a range a few ulps wide, whose edges
        # repeat and which the equal-width path refuses.
        equal_width = bool(np.all(edges[1:] > edges[:-1]))
        for c in arrays():
            inside_values = c[(c >= lo) & (c <= hi)]
            hist += (np.histogram(inside_values, bins=4096, range=(lo, hi)) if equal_width
                     else np.histogram(inside_values, bins=edges))[0]
        k = int(np.searchsorted(below + np.cumsum(hist), rank, side="right"))
        new_lo = edges[k]
        # numpy histogram bins are half-open except the last: keep the narrowed range closed and exact
        new_hi = np.nextafter(edges[k + 1], -np.inf) if k < 4095 else edges[k + 1]
        if new_lo == lo and new_hi == hi:
            break
        lo, hi = new_lo, new_hi
    return float(lo), None


def _order_statistic(chunks, rank: int, lo: float, hi: float, max_keep: int = 1 << 22) -> float:
    """The ``rank``-th smallest value (0-based) among all chunk values (see :func:`_order_statistics`)."""
    return _order_statistics(chunks, rank, lo, hi, max_keep)[0]


def streamed_percentile(chunks: Callable[[], Iterable[np.ndarray]], q: float) -> float:
    """Exact ``np.percentile(all_values, q)`` (linear interpolation) over chunks read a few times."""
    n = 0
    lo, hi = np.inf, -np.inf
    for c in chunks():
        c = np.asarray(c)
        if c.size:
            n += c.size
            lo, hi = min(lo, float(c.min())), max(hi, float(c.max()))
    if n == 0:
        return 0.0
    k = q / 100.0 * (n - 1)
    k0 = int(np.floor(k))
    v0, v1 = _order_statistics(chunks, k0, lo, hi)
    if k0 + 1 >= n or k == k0:
        return v0
    if v1 is None:
        v1 = _order_statistic(chunks, k0 + 1, v0, hi)
    return v0 + (k - k0) * (v1 - v0)


# -- alignment of methods without absolute scale ---------------------------------------------------------------

def _log_floored(img: np.ndarray, eps: float) -> np.ndarray:
    return np.log(np.maximum(np.asarray(img, dtype=np.float64), eps))


def log_floor(img: np.ndarray) -> float:
    """Log floor of one frame (either side of the fit): 10⁻³ × its 99th percentile (> 0).

    Falls back to 10⁻³ × the largest magnitude, then 10⁻³⁰, for a frame whose 99th percentile is not positive.
    """
    img = np.asarray(img, dtype=np.float64)  # float32 and float64 copies of one frame get the same floor
    p = float(np.percentile(img, WHITE_PERCENTILE)) if img.size else 0.0
    if not (np.isfinite(p) and p > 0):
        p = float(np.max(np.abs(img))) if img.size else 0.0
    return LOG_FLOOR_REL * p if p > 0 else 1e-30


def affine_log_fit(rec: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    """Least-squares (a, b) of a·ln(rec) + b ≈ ln(gt) over all pixels of one frame, each side floored at 10⁻³ of
    its own 99th percentile (:func:`log_floor`).

    Parameters
    ----------
    rec, gt : ndarray [H,W]
        Reconstruction (any scale) and ground truth (ph s⁻¹ m⁻²).

    Returns
    -------
    (a, b) : floats. A constant reconstruction (zero log-variance) gives a = 0, b = mean(ln gt).
    """
    return _fit_log(_log_floored(rec, log_floor(rec)), gt)


def _fit_log(x: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    """:func:`affine_log_fit` given the floored log of the reconstruction ``x``."""
    x = x.ravel()
    y = _log_floored(gt, log_floor(gt)).ravel()
    xm, ym = x.mean(), y.mean()
    dx = x - xm
    sxx = float(dx @ dx)
    a = float(dx @ (y - ym)) / sxx if sxx > 0 else 0.0
    return a, float(ym - a * xm)


def _apply_fit(rec: np.ndarray, a: float, b: float) -> np.ndarray:
    """e^b · rec^a (float64), with rec ≤ 0 mapped to 0; for a ≤ 0 (no monotone map), e^b · max(rec, ε_rec)^a."""
    rec = np.asarray(rec, dtype=np.float64)
    if a > 0:
        return np.exp(b) * np.power(np.maximum(rec, 0.0), a)
    return np.exp(a * _log_floored(rec, log_floor(rec)) + b)


def align_log_affine(rec: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """The reconstruction after the per-frame log-space affine fit: e^b · rec^a (:func:`affine_log_fit`), float64."""
    a, b = affine_log_fit(rec, gt)
    return _apply_fit(rec, a, b)


# -- image metrics ---------------------------------------------------------------------------------------------

def psnr_db(rec_display: np.ndarray, gt_display: np.ndarray) -> float:
    """PSNR (dB) of display-mapped frames in [0, 1], capped at PSNR_CAP_DB: scikit-image's
    ``peak_signal_noise_ratio(gt, rec, data_range=1)``, the same NumPy operations."""
    gt = np.asarray(gt_display, np.float64)
    rec = np.asarray(rec_display, np.float64)
    if gt.shape != rec.shape:
        raise ValueError(f"frames of different shapes {gt.shape} and {rec.shape}")
    mse = float(np.mean((gt - rec) ** 2, dtype=np.float64))
    if mse <= 10 ** (-PSNR_CAP_DB / 10):
        return PSNR_CAP_DB
    return float(10 * np.log10((1.0 ** 2) / np.float64(mse)))


def ssim(rec_display: np.ndarray, gt_display: np.ndarray) -> float:
    """SSIM of display-mapped frames in [0, 1]: scikit-image's ``structural_similarity(gt, rec, data_range=1)``
    with a 7×7 window, or the largest odd window that fits a tiny image (:func:`simspad.evaluate.ssim.mean_ssim`,
    bit for bit)."""
    g = np.asarray(gt_display, np.float64)
    r = np.asarray(rec_display, np.float64)
    win = min(7, min(g.shape[-2:]))
    win -= 1 - win % 2
    if win < 3:
        return float("nan")
    return mean_ssim(g, r, win_size=win, data_range=1.0)


def frame_scores(rec: np.ndarray, gt: np.ndarray, white: float, absolute_scale: bool,
                 gt_display: np.ndarray | None = None) -> dict:
    """PSNR and SSIM of one frame under the protocol (alignment first when not ``absolute_scale``).

    ``gt_display`` (optional) is ``display_map(gt, white)`` when the caller keeps it for several methods.
    Returns ``{"psnr_db", "ssim", "fit_a", "fit_b"}`` (fit_* NaN for absolute-scale methods).
    """
    rec = np.asarray(rec, dtype=np.float64)
    a = b = float("nan")
    if not absolute_scale:
        a, b = affine_log_fit(rec, gt)
        rec = _apply_fit(rec, a, b)
    rd = display_map(rec, white)
    gd = display_map(gt, white) if gt_display is None else gt_display
    return {"psnr_db": psnr_db(rd, gd), "ssim": ssim(rd, gd), "fit_a": a, "fit_b": b}


# -- MTF from a Siemens star ------------------------------------------------------------------------------------

def _circle_coordinates(cy: float, cx: float, r: float, n_samples: int) -> np.ndarray:
    theta = np.arange(n_samples) * (2 * np.pi / n_samples)
    return np.vstack([cy + r * np.sin(theta), cx + r * np.cos(theta)])


def _circle_samples(img: np.ndarray, cy: float, cx: float, r: float, n_samples: int) -> np.ndarray:
    return map_coordinates(np.asarray(img, np.float64), _circle_coordinates(cy, cx, r, n_samples), order=1,
                           mode="nearest")


def _harmonic_samples(r: float, n_cycles: int) -> int:
    """Samples on the circle of radius ``r`` for its ``n_cycles``-th harmonic: ≥ 64, 8 per cycle, 2 per px."""
    return max(64, int(8 * n_cycles), int(np.ceil(2 * np.pi * r * 2)))


def _harmonic(samples: np.ndarray, n_cycles: int) -> complex:
    f = np.fft.rfft(samples)
    return complex(f[n_cycles] / f[0]) if abs(f[0]) > 0 else 0j


def _circle_harmonic(img: np.ndarray, cy: float, cx: float, r: float, n_cycles: int) -> complex:
    """The ``n_cycles``-th angular Fourier coefficient on the circle of radius ``r``, divided by the mean."""
    return _harmonic(_circle_samples(img, cy, cx, r, _harmonic_samples(r, n_cycles)), n_cycles)


def circle_modulation(img: np.ndarray, cy: float, cx: float, r: float, n_cycles: int) -> float:
    """Modulation of the ``n_cycles``-th angular harmonic on the circle of radius ``r``: 2|F_n| / F_0."""
    return 2 * abs(_circle_harmonic(img, cy, cx, r, n_cycles))


def siemens_star_geometry(gt: np.ndarray, max_cycles: int = 128) -> tuple[float, float, int, float]:
    """Locate a Siemens star in a ground-truth frame.

    The angular spectra on circles of radius 0.45–0.9 R (R = half the smaller image side) are summed; the
    centre is searched on a grid around the image centre (± R/2: a coarse pass, then 1 px steps) to maximise the
    dominant harmonic of that sum, and ``n_cycles`` is that harmonic. Outer circles dominate, where the star is
    best resolved (inner ones alias).

    Returns
    -------
    (cy, cx, n_cycles, r_max_px)
    """
    gt = np.asarray(gt, np.float64)
    H, W = gt.shape
    R = min(H, W) / 2 - 1
    radii = np.linspace(0.45, 0.9, 6) * R

    def best_harmonic(cy, cx):
        # every circle sampled in one call; the spectra summed circle by circle
        coords = np.concatenate([_circle_coordinates(cy, cx, r, 1024) for r in radii], axis=1)
        v = map_coordinates(gt, coords, order=1, mode="nearest").reshape(radii.size, 1024)
        means = [row.mean() for row in v]
        amp = np.abs(np.fft.rfft(v - np.array(means)[:, None]))[:, :max_cycles + 1]
        spec = np.zeros(max_cycles + 1)
        for a, m in zip(amp, means):
            spec += a / m if m > 0 else 0.0
        k = MIN_STAR_CYCLES + int(np.argmax(spec[MIN_STAR_CYCLES:]))
        return spec[k], k

    span = max(2, int(R // 2))
    best = (-1.0, (H - 1) / 2, (W - 1) / 2, 1)
    coarse = max(1, span // 4)
    for step, rng, centred in ((coarse, span, True), (1, coarse, False)):
        cy0, cx0 = ((H - 1) / 2, (W - 1) / 2) if centred else (best[1], best[2])
        for dy in np.arange(-rng, rng + 1, step):
            for dx in np.arange(-rng, rng + 1, step):
                power, k = best_harmonic(cy0 + dy, cx0 + dx)
                if power > best[0]:
                    best = (power, cy0 + dy, cx0 + dx, k)
    _, cy, cx, n = best
    r_max = min(0.95 * R, cy, cx, H - 1 - cy, W - 1 - cx)
    return float(cy), float(cx), int(n), float(r_max)


def _star_radii(geometry: tuple[float, float, int, float], n_radii: int) -> np.ndarray | None:
    """The circles :func:`mtf_siemens` samples (Nyquist radius to the star's edge); None when none fits."""
    _, _, n, r_max = geometry
    r_min = max(n / np.pi, 2.0)  # f = n / (2π r) = 0.5 cycles/px
    if r_max <= r_min:
        return None
    return np.geomspace(r_min, r_max, n_radii)


@functools.lru_cache(maxsize=16)
def _star_circles(geometry: tuple[float, float, int, float], n_radii: int) -> tuple[np.ndarray, tuple[int, ...]]:
    """Sample positions [2, N] on every circle of :func:`star_harmonics` (one after the other) and the samples
    per circle, read-only (the same for every frame of a recording)."""
    cy, cx, n, _ = geometry
    counts = tuple(_harmonic_samples(r, n) for r in _star_radii(geometry, n_radii))
    coords = np.concatenate([_circle_coordinates(cy, cx, r, c)
                             for r, c in zip(_star_radii(geometry, n_radii), counts)], axis=1)
    coords.flags.writeable = False
    return coords, counts


def star_harmonics(img: np.ndarray, geometry: tuple[float, float, int, float], n_radii: int = 24) -> np.ndarray:
    """The star's normalised harmonic F_n/F_0 on each circle of :func:`mtf_siemens` (empty when none fits)."""
    geometry = (float(geometry[0]), float(geometry[1]), int(geometry[2]), float(geometry[3]))
    if _star_radii(geometry, n_radii) is None:
        return np.empty(0, complex)
    coords, counts = _star_circles(geometry, n_radii)
    v = map_coordinates(np.asarray(img, np.float64), coords, order=1, mode="nearest")  # every circle at once
    ends = np.cumsum(counts)
    return np.array([_harmonic(v[e - c:e], geometry[2]) for c, e in zip(counts, ends)])


def mtf_siemens(rec: np.ndarray, gt: np.ndarray, *, n_radii: int = 24,
                geometry: tuple[float, float, int, float] | None = None,
                gt_harmonics: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """MTF of a reconstruction of a Siemens star relative to its ground truth.

    On each circle the reconstruction's normalised harmonic is projected on the ground truth's:
    MTF = Re(h_rec·conj(h_gt)) / |h_gt|² with h = F_n / F_0. Noise then averages out instead of adding
    modulation, and a phase lag (motion blur, latency) lowers the MTF as it should.

    Parameters
    ----------
    rec, gt : ndarray [H,W]
        Reconstruction and ground truth (linear; any common scale: the measure is scale-free).
    n_radii : int
        Circles sampled between the Nyquist radius (f = 0.5 cycles/px) and the star's edge.
    geometry : (cy, cx, n_cycles, r_max), optional
        From :func:`siemens_star_geometry` (computed from ``gt`` if omitted).
    gt_harmonics : ndarray of complex, optional
        ``star_harmonics(gt, geometry, n_radii)`` when the caller keeps it for several methods.

    Returns
    -------
    freq_cyc_px, mtf : ndarrays sorted by increasing frequency; NaN on circles where the ground truth shows
    less than 10 % of its strongest modulation (outside the star).
    """
    geometry = geometry or siemens_star_geometry(gt)
    cy, cx, n, r_max = geometry
    radii = _star_radii(geometry, n_radii)
    if radii is None:
        return np.empty(0), np.empty(0)
    h_gt = star_harmonics(gt, geometry, n_radii) if gt_harmonics is None else gt_harmonics
    h_rec = star_harmonics(rec, geometry, n_radii)
    keep = np.abs(h_gt) > 0.1 * np.abs(h_gt).max() if np.abs(h_gt).max() > 0 else np.zeros(radii.size, bool)
    freq = n / (2 * np.pi * radii)
    with np.errstate(divide="ignore", invalid="ignore"):
        mtf = np.where(keep, (h_rec * np.conj(h_gt)).real / np.abs(h_gt) ** 2, np.nan)
    order = np.argsort(freq)
    return freq[order], mtf[order]


def mtf50(freq_cyc_px: np.ndarray, mtf: np.ndarray) -> float:
    """Lowest frequency (cycles/px) where the MTF falls to 0.5, linearly interpolated.

    NaN when it cannot be measured: no data, an MTF already below 0.5 at the lowest measured frequency, or one
    that never falls to 0.5 inside the measured band (it is then only known to lie above the highest measured
    frequency, usually Nyquist; :func:`mtf_at` still tells methods apart there).
    """
    ok = np.isfinite(mtf)
    f, m = np.asarray(freq_cyc_px)[ok], np.asarray(mtf)[ok]
    if f.size == 0 or m[0] < 0.5:
        return float("nan")
    below = np.nonzero(m < 0.5)[0]
    if below.size == 0:
        return float("nan")
    i = int(below[0])
    f0, f1, m0, m1 = f[i - 1], f[i], m[i - 1], m[i]
    return float(f0 + (m0 - 0.5) * (f1 - f0) / (m0 - m1))


def mtf_at(freq_cyc_px: np.ndarray, mtf: np.ndarray, f_cyc_px: float) -> float:
    """The MTF at the spatial frequency ``f_cyc_px`` (cycles/px), linearly interpolated between measured circles.

    NaN when ``f_cyc_px`` lies outside the measured band: a star of ``n`` cycles fitting a radius ``r_max`` is
    measured only from ``n / (2π r_max)`` up to Nyquist, so low frequencies cannot be measured on small images.
    """
    ok = np.isfinite(mtf)
    f, m = np.asarray(freq_cyc_px, np.float64)[ok], np.asarray(mtf, np.float64)[ok]
    if f.size == 0 or not (f[0] <= f_cyc_px <= f[-1]):
        return float("nan")
    return float(np.interp(f_cyc_px, f, m))


def iter_chunks(read: Callable[[slice], np.ndarray], n: int, chunk: int = 16) -> Callable[[], Iterator[np.ndarray]]:
    """A callable yielding ``read(slice(i, i+chunk))`` over ``range(0, n, chunk)`` (for :func:`white_point`)."""
    def gen():
        for i in range(0, n, chunk):
            yield read(slice(i, min(i + chunk, n)))
    return gen

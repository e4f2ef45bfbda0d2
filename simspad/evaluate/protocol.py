"""The evaluation protocol, shared by ``simspad evaluate`` and ``simspad score``.

1. The evaluation instants are the ``/gt/t`` instants that lie on the evaluation grid t₀ + k/rate_hz
   (default 1 kHz, or the dataset spec's ``evaluation.rate_hz``): :func:`evaluation_indices`.
2. The white point W is the 99th percentile of ground truth over those instants (read in chunks, exact, once
   per recording): :func:`gt_white_point`.
3. Each reconstructed frame is scored as it arrives (:func:`simspad.evaluate.metrics.frame_scores`: display
   mapping, log-affine alignment for methods without absolute scale, PSNR, SSIM), so memory does not grow with
   the sequence length: :func:`score_frames`.
4. Siemens-star recordings (scene name containing ``siemens``) also get the MTF (mean over frames), reported by
   :func:`star_figures` as its value at the fixed frequencies ``metrics.STAR_FREQS_CYC_PX`` and MTF50.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from simspad import defaults
from simspad.errors import InputError, SimSpadError
from simspad.evaluate import metrics
from simspad.io.results_dir import CROP_PX, crop

DEFAULT_RATE_HZ = defaults.GT_RATE_HZ
#: A ground-truth instant is on the evaluation grid when within this fraction of a period of a grid point.
GRID_TOLERANCE = 1e-6
#: Ground-truth frames read at a time for the white point.
_WHITE_CHUNK_FRAMES = 16
#: Most bytes of ground-truth frames (and what is derived from them) kept per recording for its methods.
GT_CACHE_BYTES = 256 * 2**20


def evaluation_indices(gt_t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the ground-truth instants lying on the grid t₀ + k/rate_hz (one per grid point).

    A ground-truth instant is on the grid when it is within 10⁻⁶ of a period of it. When the ground truth is
    sampled more coarsely than the grid, every ground-truth instant is on it.
    """
    gt_t = np.asarray(gt_t, np.float64)
    if gt_t.size == 0:
        return np.empty(0, np.int64)
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise SimSpadError(f"evaluation rate must be > 0, got {rate_hz}", field="--rate")
    k = (gt_t - gt_t[0]) * rate_hz
    on_grid = np.abs(k - np.round(k)) < GRID_TOLERANCE
    idx = np.nonzero(on_grid)[0]
    _, first = np.unique(np.round(k[idx]).astype(np.int64), return_index=True)
    return idx[np.sort(first)]


def is_siemens_star(scene: str) -> bool:
    """Whether the scene is a Siemens star (scored for MTF too)."""
    return "siemens" in scene.lower()


def gt_white_point(rec, idx: np.ndarray) -> float:
    """The sequence white point W (ph s⁻¹ m⁻²) of the recording's ground truth at the instants ``idx``."""
    def chunks():
        for i in range(0, idx.size, _WHITE_CHUNK_FRAMES):
            block = rec.gt.flux(idx[i:i + _WHITE_CHUNK_FRAMES].tolist())
            bad = ~np.isfinite(block) | (block < 0)
            if bad.any():  # every score is measured against it: refuse, naming the first bad frame and pixel
                k, row, col = np.argwhere(bad)[0]
                raise InputError(f"ground-truth flux {block[k, row, col]} at pixel (row {row}, col {col}) of frame "
                                 f"{int(idx[i + k])} (expected finite values ≥ 0)", path=rec.path, field="/gt/flux")
            yield block
    return metrics.white_point(chunks)


class _MeanMtf:
    """Running mean of per-frame MTF curves, frequency by frequency, ignoring NaN values."""

    def __init__(self) -> None:
        self.freq = self.total = self.count = None

    def add(self, f: np.ndarray, m: np.ndarray) -> None:
        if not f.size:
            return
        if self.total is None:
            self.freq, self.total, self.count = f, np.zeros_like(m), np.zeros(m.shape, np.int64)
        ok = np.isfinite(m)
        self.total[ok] += m[ok]
        self.count[ok] += 1

    def result(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(freq, mean MTF) or None when no frame gave a curve."""
        if self.total is None:
            return None
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.freq, np.where(self.count > 0, self.total / np.maximum(self.count, 1), np.nan)


def _checked_frame(img, i: int, n: int, shape: tuple[int, int]) -> np.ndarray:
    """Frame ``i`` as an array; ValueError on one frame too many, a wrong shape or a non-finite value."""
    if i >= n:
        raise ValueError(f"more frames than the {n} evaluation instants")
    img = np.asarray(img)
    if img.shape != shape:
        raise ValueError(f"frame {i} has shape {img.shape}, expected {shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError(f"frame {i} holds NaN or inf values")
    return img


class CheckedFrames:
    """A method's frames as ``(i, frame)``, each checked as it arrives (:func:`_checked_frame`), the count checked
    at the end; ``method_s`` sums the time spent inside the method's iterator only (not the caller's scoring),
    ``n`` is the number of frames once iterated."""

    def __init__(self, frames, n: int, shape: tuple[int, int]):
        self._frames, self._n, self._shape = frames, n, shape
        self.method_s = 0.0
        self.n = 0

    def __iter__(self):
        it = iter(self._frames)
        i = 0
        while True:
            t0 = time.perf_counter()
            try:
                img = next(it)
            except StopIteration:
                self.method_s += time.perf_counter() - t0
                break
            self.method_s += time.perf_counter() - t0
            yield i, _checked_frame(img, i, self._n, self._shape)
            i += 1
        if i != self._n:
            raise ValueError(f"{i} frames for {self._n} evaluation instants")
        self.n = i


class GroundTruthCache:
    """What scoring derives from a recording's ground truth, computed once for all the methods scored on it.

    Holds, per evaluation instant, the ground-truth frame, its display mapping and (Siemens star) its angular
    harmonics, and the star's geometry, up to ``max_bytes`` of frames: past that, frames are computed again for
    each method, so memory does not grow with the sequence length. Scores are identical with or without it.
    """

    def __init__(self, white: float, max_bytes: int = GT_CACHE_BYTES):
        self.white = white
        self.max_bytes = int(max_bytes)
        self._bytes = 0
        self._frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._harmonics: dict[int, np.ndarray] = {}
        self.geometry = None

    def frame(self, rec, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(ground truth, its display mapping) at ground-truth index ``index``."""
        hit = self._frames.get(index)
        if hit is not None:
            return hit
        gt = np.asarray(rec.gt.flux(index))
        pair = (gt, metrics.display_map(gt, self.white))
        for a in pair:
            a.flags.writeable = False  # shared by every method scored on this recording
        size = gt.nbytes + pair[1].nbytes
        if self._bytes + size <= self.max_bytes:
            self._frames[index] = pair
            self._bytes += size
        return pair

    def star(self, index: int, gt: np.ndarray) -> tuple[tuple, np.ndarray]:
        """(star geometry, ground-truth harmonics) at ``index``; the geometry from the first frame asked for."""
        if self.geometry is None:
            self.geometry = metrics.siemens_star_geometry(gt)
        h = self._harmonics.get(index)
        if h is None:
            h = metrics.star_harmonics(gt, self.geometry)
            if self._bytes + h.nbytes <= self.max_bytes:
                self._harmonics[index] = h
                self._bytes += h.nbytes
        return self.geometry, h


@dataclass(frozen=True)
class ScoringRun:
    """How one method's frames on one recording are scored, and the labels of its per-frame rows.

    Attributes
    ----------
    method : str
        Method name (the ``method`` column).
    recording : str
        Recording path relative to the dataset (the ``recording`` column).
    scene : str
        Scene name (Siemens-star scenes also get the MTF).
    white : float
        Sequence white point (ph s⁻¹ m⁻²).
    absolute_scale : bool
        False: each frame is aligned by the log-affine fit before scoring.
    image_frame : int
        Position (in the evaluation indices) of the instant whose display-mapped crops are returned.
    """

    method: str
    recording: str
    scene: str
    white: float
    absolute_scale: bool
    image_frame: int


def score_frames(rec, idx: np.ndarray, frames, run: ScoringRun, frame_sink=None,
                 gt_cache: GroundTruthCache | None = None):
    """Score a stream of reconstructed frames against the recording's ground truth at ``idx``.

    Parameters
    ----------
    rec : Recording
    idx : ndarray of int
        Ground-truth frame indices (the evaluation instants), in order.
    frames : iterable of ndarray [H,W]
        The reconstruction, one frame per index.
    run : ScoringRun
        White point, scale, labels and the frame whose crops are returned.
    frame_sink : callable(i, frame), optional
        Receives each frame (to save the reconstructions).
    gt_cache : GroundTruthCache, optional
        Ground truth shared with the other methods scored on this recording (same white point); the scores are
        identical without it.

    Returns
    -------
    dict with ``frame_rows``, ``psnr_db``, ``ssim``, ``n_frames``, ``mtf`` (freq, mtf) or None, ``images``
    (rec and gt display crops at ``image_frame``) and ``method_s`` (time spent inside the frame iterator).
    Raises ValueError on a frame of the wrong shape, a non-finite value or a wrong number of frames.
    """
    white, absolute_scale, image_frame = run.white, run.absolute_scale, run.image_frame
    H, W = rec.height, rec.width
    t = rec.gt.t
    frame_rows, psnrs, ssims = [], [], []
    star = is_siemens_star(run.scene)
    if gt_cache is None or gt_cache.white != white:
        gt_cache = GroundTruthCache(white, max_bytes=0)  # nothing kept: each frame computed once, here
    mtf = _MeanMtf()
    images = None
    checked = CheckedFrames(frames, idx.size, (H, W))
    for i, img in checked:
        if frame_sink is not None:
            frame_sink(i, img)
        gt, gt_display = gt_cache.frame(rec, int(idx[i]))
        s = metrics.frame_scores(img, gt, white, absolute_scale, gt_display=gt_display)
        frame_rows.append({"method": run.method, "recording": run.recording, "frame": i, "t_s": float(t[idx[i]]),
                           **s})
        psnrs.append(s["psnr_db"])
        ssims.append(s["ssim"])
        if star or i == image_frame:
            shown = img if absolute_scale else metrics.align_log_affine(img, gt)
        if star:
            geometry, h_gt = gt_cache.star(int(idx[i]), gt)
            mtf.add(*metrics.mtf_siemens(shown, gt, geometry=geometry, gt_harmonics=h_gt))
        if i == image_frame:
            images = (crop(metrics.display_map(shown, white)), crop(gt_display))
    i, method_s = checked.n, checked.method_s
    return {"frame_rows": frame_rows, "psnr_db": float(np.mean(psnrs)) if psnrs else float("nan"),
            "ssim": float(np.nanmean(ssims)) if ssims and not np.all(np.isnan(ssims)) else float("nan"),
            "n_frames": i, "mtf": mtf.result(), "images": images, "method_s": method_s}


def star_column(f_cyc_px: float) -> str:
    """The results.csv column of the MTF at ``f_cyc_px``: ``mtf_at_0p25_cyc_px`` for 0.25 cycles/px."""
    return f"mtf_at_{f_cyc_px:.2f}_cyc_px".replace(".", "p")


def star_figures(mtf: tuple[np.ndarray, np.ndarray] | None) -> dict:
    """The Siemens-star columns of a results row from a mean MTF curve (freq, mtf); all NaN for None.

    ``mtf_at_*_cyc_px`` is NaN where the frequency lies outside the band the star measures at this resolution,
    ``mtf50_cyc_px`` where the MTF does not cross 0.5 inside it (see :func:`metrics.mtf50`).
    """
    if mtf is None:
        out = {star_column(f): float("nan") for f in metrics.STAR_FREQS_CYC_PX}
        out["mtf50_cyc_px"] = float("nan")
        return out
    f, m = mtf
    out = {star_column(f0): metrics.mtf_at(f, m, f0) for f0 in metrics.STAR_FREQS_CYC_PX}
    out["mtf50_cyc_px"] = metrics.mtf50(f, m)
    return out


def protocol_metadata() -> dict:
    """The protocol constants recorded in ``results.json``."""
    return {"white_point": f"{metrics.WHITE_PERCENTILE:g}th percentile of ground truth over the sequence",
            "display": "clip(x / W, 0, 1) then the sRGB transfer curve",
            "alignment": "methods without absolute scale: per-frame least-squares a*ln(rec)+b ~ ln(gt), each "
                         f"side floored at {metrics.LOG_FLOOR_REL:g}*p99 of its own frame; aligned = exp(b)*rec^a",
            "psnr": f"scikit-image, data_range=1, capped at {metrics.PSNR_CAP_DB:g} dB, mean over frames",
            "ssim": "scikit-image, data_range=1, 7x7 window, mean over frames",
            "image_crop_px": CROP_PX}

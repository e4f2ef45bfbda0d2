"""The evaluation protocol (DESIGN §8), shared by ``simspad evaluate`` and ``simspad score``.

1. The evaluation instants are the ``/gt/t`` instants that lie on the evaluation grid t₀ + k/rate_hz
   (default 1 kHz, or the dataset spec's ``evaluation.rate_hz``): :func:`evaluation_indices`.
2. The white point W is the 99th percentile of ground truth over those instants (read in chunks, exact, once
   per recording): :func:`gt_white_point`.
3. Each reconstructed frame is scored as it arrives (:func:`simspad.evaluate.metrics.frame_scores`: display
   mapping, log-affine alignment for methods without absolute scale, PSNR, SSIM), so memory does not grow with
   the sequence length: :func:`score_frames`.
4. Siemens-star recordings (scene name containing ``siemens``) also get the MTF (mean over frames) and MTF50.
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


def score_frames(rec, idx: np.ndarray, frames, run: ScoringRun, frame_sink=None):
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
    geometry = None
    mtf = _MeanMtf()
    images = None
    method_s = 0.0
    it = iter(frames)
    i = 0
    while True:
        t0 = time.perf_counter()
        try:
            img = next(it)
        except StopIteration:
            method_s += time.perf_counter() - t0
            break
        method_s += time.perf_counter() - t0
        img = _checked_frame(img, i, idx.size, (H, W))
        if frame_sink is not None:
            frame_sink(i, img)
        gt = rec.gt.flux(int(idx[i]))
        s = metrics.frame_scores(img, gt, white, absolute_scale)
        frame_rows.append({"method": run.method, "recording": run.recording, "frame": i, "t_s": float(t[idx[i]]),
                           **s})
        psnrs.append(s["psnr_db"])
        ssims.append(s["ssim"])
        if star or i == image_frame:
            shown = img if absolute_scale else metrics.align_log_affine(img, gt, white)
        if star:
            if geometry is None:
                geometry = metrics.siemens_star_geometry(gt)
            mtf.add(*metrics.mtf_siemens(shown, gt, geometry=geometry))
        if i == image_frame:
            images = (crop(metrics.display_map(shown, white)), crop(metrics.display_map(gt, white)))
        i += 1
    if i != idx.size:
        raise ValueError(f"{i} frames for {idx.size} evaluation instants")
    return {"frame_rows": frame_rows, "psnr_db": float(np.mean(psnrs)) if psnrs else float("nan"),
            "ssim": float(np.nanmean(ssims)) if ssims and not np.all(np.isnan(ssims)) else float("nan"),
            "n_frames": i, "mtf": mtf.result(), "images": images, "method_s": method_s}


def protocol_metadata() -> dict:
    """The protocol constants recorded in ``results.json``."""
    return {"white_point": f"{metrics.WHITE_PERCENTILE:g}th percentile of ground truth over the sequence",
            "display": "clip(x / W, 0, 1) then the sRGB transfer curve",
            "alignment": "methods without absolute scale: per-frame least-squares a*ln(rec)+b ~ ln(gt), "
                         f"floors {metrics.LOG_FLOOR_REL:g}*W (gt) and {metrics.LOG_FLOOR_REL:g}*p99(rec)",
            "psnr": f"scikit-image, data_range=1, capped at {metrics.PSNR_CAP_DB:g} dB, mean over frames",
            "ssim": "scikit-image, data_range=1, 7x7 window, mean over frames",
            "image_crop_px": CROP_PX}

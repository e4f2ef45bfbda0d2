"""Evaluating recordings without ground truth (real captures built by ``simspad import``).

Such a recording has no ``/gt``; every method its sensors allow still runs, and what can be measured without
ground truth is reported:

- **Instants**: the grid ``t_start_s + k/rate_hz`` inside the recorded span ``[t_start_s, t_end_s)``, k = 0, 1, …
  (the instants a simulated recording's ground truth would have at that rate).
- **Reconstructions** are saved as for any recording; **bandwidth** is the method's own tally.
- **PSNR and SSIM** are not available: NaN in ``results.csv`` (never 0), with the reason in ``results.json``'s
  ``notes`` and ``ground_truth``.
- **Image**: the reconstruction at the middle instant, display-mapped with the 99th percentile of the method's own
  frame as white (there is no sequence white point without ground truth).
- **Siemens-star MTF**, when the recording declares a star region (root attribute ``star_region``, from the
  calibration's ``[star]``: centre, outer radius, spokes, printed contrast). Without ground truth the MTF is the
  star's modulation relative to a perfect print: on a circle of radius r the star has ``n`` periods, frequency
  f = n/(2πr) cycles/px; the modulation of the n-th angular harmonic is ``2|F_n|/F_0``, which for a square-wave
  star of Michelson contrast C is ``(4/π)·C`` when perfectly resolved, so
  ``MTF(f) = 2|F_n|/F_0 / ((4/π)·C)``, averaged over the evaluated frames. Circles from the Nyquist radius
  (f = 0.5) to 0.95 of the declared radius are measured. ``n`` is the declared ``n_cycles`` or, when absent, the
  dominant angular harmonic (≥ 8) of the first reconstructed frame between 0.45 and 0.9 of the radius. MTF50 and
  the fixed-frequency values follow as for simulated stars (:func:`simspad.evaluate.protocol.star_figures`).
  The modulation is measured on the frame as reconstructed (methods without absolute scale included: the ratio
  ``F_n/F_0`` does not depend on a scale, though a log-domain offset changes it).
"""

from __future__ import annotations

import json
import math

import numpy as np

from simspad.evaluate import metrics
from simspad.evaluate.protocol import CheckedFrames

#: The note results.json carries for recordings without ground truth.
NO_GT_NOTE = ("psnr_db and ssim are NaN for recordings without ground truth (/gt): not available, not zero; the "
              "Siemens-star MTF of such recordings is relative to a perfect print of the declared contrast")


def evaluation_times(rec, rate_hz: float) -> np.ndarray:
    """The instants ``t_start_s + k/rate_hz`` inside ``[t_start_s, t_end_s)``, s."""
    t0 = float(rec.attrs.get("t_start_s", 0.0))
    t1 = float(rec.attrs.get("t_end_s", t0 + rec.duration_s))
    n = int(math.ceil((t1 - t0) * rate_hz - 1e-9))
    return t0 + np.arange(max(n, 0)) / rate_hz


def star_region(rec) -> dict | None:
    """The recording's declared Siemens-star region (None when it declares none or it is unreadable)."""
    text = rec.attrs.get("star_region")
    if not text:
        return None
    try:
        star = json.loads(text)
    except (TypeError, json.JSONDecodeError):
        return None
    return star if isinstance(star, dict) and "radius_px" in star else None


def star_cycles(img: np.ndarray, cy: float, cx: float, radius: float) -> int:
    """The star's number of periods: the dominant angular harmonic (≥ ``metrics.MIN_STAR_CYCLES``) summed over
    circles of 0.45–0.9 of ``radius``."""
    spec = np.zeros(129)
    for r in np.linspace(0.45, 0.9, 6) * radius:
        v = metrics._circle_samples(img, cy, cx, r, 1024)
        m = v.mean()
        if m > 0:
            spec += np.abs(np.fft.rfft(v - m))[:129] / m
    return metrics.MIN_STAR_CYCLES + int(np.argmax(spec[metrics.MIN_STAR_CYCLES:]))


class StarMtf:
    """Mean MTF over frames of a declared star region, relative to a perfect print (module docstring)."""

    def __init__(self, star: dict, n_radii: int = 24):
        self.cx, self.cy = float(star["center_x_px"]), float(star["center_y_px"])
        self.radius = float(star["radius_px"])
        self.contrast = float(star.get("contrast") or 1.0)
        self.n = int(star["n_cycles"]) if star.get("n_cycles") else None
        self.n_radii = n_radii
        self.total = self.count = self.freq = None

    def add(self, img: np.ndarray) -> None:
        img = np.asarray(img, np.float64)
        if self.n is None:
            self.n = star_cycles(img, self.cy, self.cx, self.radius)
        r_min, r_max = max(self.n / np.pi, 2.0), 0.95 * self.radius
        if r_max <= r_min:
            return
        radii = np.geomspace(r_min, r_max, self.n_radii)
        ideal = 4.0 / np.pi * self.contrast
        m = np.array([metrics.circle_modulation(img, self.cy, self.cx, r, self.n) for r in radii]) / ideal
        if self.total is None:
            self.freq = self.n / (2 * np.pi * radii)
            self.total, self.count = np.zeros(radii.size), np.zeros(radii.size, np.int64)
        ok = np.isfinite(m)
        self.total[ok] += m[ok]
        self.count[ok] += 1

    def result(self):
        """(freq, mean MTF) sorted by frequency, or None."""
        if self.total is None:
            return None
        with np.errstate(invalid="ignore", divide="ignore"):
            mtf = np.where(self.count > 0, self.total / np.maximum(self.count, 1), np.nan)
        order = np.argsort(self.freq)
        return self.freq[order], mtf[order]


def score_without_gt(rec, times: np.ndarray, frames, star: dict | None, frame_sink=None):
    """Consume a method's frames at ``times``: save them, measure the star MTF, keep the middle frame's image.

    Returns
    -------
    dict with ``n_frames``, ``method_s`` (time inside the frame iterator), ``mtf`` (freq, mtf) or None and
    ``image`` (display-mapped middle frame, [H, W] in [0, 1]) or None. Raises ValueError on a frame of the wrong
    shape, a non-finite value or a wrong number of frames.
    """
    H, W = rec.height, rec.width
    mtf = StarMtf(star) if star is not None else None
    image = None
    checked = CheckedFrames(frames, times.size, (H, W))
    for i, img in checked:
        if frame_sink is not None:
            frame_sink(i, img)
        if mtf is not None:
            mtf.add(img)
        if i == times.size // 2:
            white = float(np.percentile(img, metrics.WHITE_PERCENTILE))
            image = metrics.display_map(img, white if white > 0 else 1.0)
    i, method_s = checked.n, checked.method_s
    return {"n_frames": i, "method_s": method_s, "mtf": mtf.result() if mtf is not None else None, "image": image}

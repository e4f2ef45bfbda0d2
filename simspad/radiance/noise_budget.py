"""Render-noise budget: how much Monte Carlo noise a render's radiance carries, and how many events it alone makes.

Both figures come from a *noise probe*: keyframe 0 rendered a second time with the next seed. The two renders
see the same scene through independent Monte Carlo samples, so they differ by the render noise alone.

- **Relative render noise** (:func:`relative_noise`): per pixel, |Y₀ − Y₁| / √2 over the pair's mean luminance.
  The difference of two independent renders has √2 times the spread of one render's error, so |Y₀ − Y₁| / √2 is
  distributed like the error of one render against converged radiance; its median over pixels estimates the
  median per-pixel relative error of the ground truth (the figure docs/rendering.md reports against brute-force
  references), without rendering a reference. Its RMS over the image is reported too.
- **Spurious-event fraction** (:func:`spurious_event_fraction`): the fraction of pixels at which a noise-free
  event sensor (nominal thresholds, no shot noise, leak, hot pixels or threshold mismatch; settled, so its
  bandwidth does not matter) fires at least one event when the render noise at the pixel is drawn anew: when its
  log signal moves from the first render's to the second's by at least a threshold. A fixed render seed freezes
  the noise on a static camera, but under camera motion the paths a pixel traces change and its noise is drawn
  anew; each such renewal costs about this fraction of the pixels one event that the scene did not cause.

Both are cheap: the probe is one keyframe render (1/N of a render of N keyframes); the statistics are numpy over
two images.
"""

from __future__ import annotations

import math

import numpy as np

#: The probe is keyframe 0 rendered with the render's seed plus this.
PROBE_SEED_OFFSET = 1
#: Contrast threshold (log units) of the render-level spurious-event fraction: the default event sensor's nominal
#: ON and OFF thresholds (``simspad.sensors.presets.EventParams``; a test keeps the two equal).
DEFAULT_THRESHOLD_LOG = 0.3
#: Floor of the luminance in the render-level (bright-light) figure, as a fraction of the image's mean: keeps the
#: log finite on black pixels without reaching into the radiance of any visible surface.
LOG_FLOOR_OF_MEAN = 1e-6


def relative_noise(y0: np.ndarray, y1: np.ndarray) -> tuple[float, float]:
    """Relative Monte Carlo noise of one render, from two renders of one pose with independent seeds.

    Parameters
    ----------
    y0, y1 : ndarray [H, W]
        Luminance of the two renders (any linear unit).

    Returns
    -------
    (float, float)
        The median over pixels of |y0 − y1| / √2 ÷ (y0 + y1)/2 (pixels black in both left out; 0 when all are),
        and the image's RMS of (y0 − y1)/√2 ÷ its mean luminance (0 for a black image). Dimensionless.
    """
    y0 = np.asarray(y0, dtype=np.float64)
    y1 = np.asarray(y1, dtype=np.float64)
    err = np.abs(y0 - y1) / math.sqrt(2.0)
    mean = 0.5 * (y0 + y1)
    lit = mean > 0
    median = float(np.median(err[lit] / mean[lit])) if np.any(lit) else 0.0
    image_mean = float(mean.mean())
    rms = float(np.sqrt(np.mean(err ** 2)) / image_mean) if image_mean > 0 else 0.0
    return median, rms


def spurious_event_fraction(s0: np.ndarray, s1: np.ndarray, threshold_on: float, threshold_off: float,
                            floor: float = 0.0) -> float:
    """Fraction of pixels whose log signal moves by at least a threshold from ``s0`` to ``s1``.

    Parameters
    ----------
    s0, s1 : ndarray
        The signal an event pixel takes the log of (photocurrent, e⁻ s⁻¹, or luminance) for the two renders.
    threshold_on, threshold_off : float
        Contrast thresholds, log units (> 0): ON when ln s1 − ln s0 ≥ θ_on, OFF when ≤ −θ_off.
    floor : float
        Added to both signals before the log (≥ 0; > 0 where a signal can be 0).

    Returns
    -------
    float
        Pixels that fire either polarity, over all pixels (0 for an empty image).
    """
    a = np.log(np.asarray(s0, dtype=np.float64) + floor)
    b = np.log(np.asarray(s1, dtype=np.float64) + floor)
    change = b - a
    fires = (change >= threshold_on) | (change <= -threshold_off)
    return float(fires.mean()) if fires.size else 0.0


def render_noise_budget(y0: np.ndarray, y1: np.ndarray, threshold_log: float = DEFAULT_THRESHOLD_LOG) -> dict:
    """The render-level budget stored in ``timeline.json`` (``render_noise``, docs/format.md section 2).

    ``spurious_event_fraction`` here is the bright-light limit: the log of luminance itself (a floor of
    :data:`LOG_FLOOR_OF_MEAN` of the mean), as a sensor whose dark current is negligible sees it. A recording
    states its own figure at its lux level (:func:`simspad.sensors.render_noise.render_noise_attrs`).
    """
    median, rms = relative_noise(y0, y1)
    floor = LOG_FLOOR_OF_MEAN * max(float(np.mean(y0)), np.finfo(np.float64).tiny)
    return {"relative_noise_median": median, "relative_noise_rms": rms,
            "spurious_event_fraction": spurious_event_fraction(y0, y1, threshold_log, threshold_log, floor),
            "threshold_log": float(threshold_log)}

"""Event camera model (docs/sensors.md, preset ``prophesee_gen4``): a per-pixel DVS with exact crossing times.

Per pixel (flattened index ``y·W + x``):

- **photocurrent** ``I(t) = qe·fill·pitch²·Φ(t) + dark_current`` (e⁻ s⁻¹), linear in time between keyframes;
- **photoreceptor**: first-order low-pass of ``ln I`` with cutoff ``f_c = f_max·I/(I + I_ref)``, so dim pixels
  lag (``τ = 1/(2π f_c)``; the formulas live in :mod:`simspad.physics.photoreceptor`). It is integrated *exactly*
  for an input whose log is linear in time over each internal step (:mod:`.kernel`);
- **change detector**: ON when ``D = L_p − ref + leak·(t − t_ref) ≥ θ_on``, OFF when ``D ≤ −θ_off``; at an event
  the reference resets to the current ``L_p``. Crossings are solved to 1 ns (:mod:`.crossing`): nothing snaps to
  keyframes;
- **thresholds** ``θ ~ N(nominal, threshold_sigma)`` per pixel and polarity, fixed for the recording, clamped to
  ``≥ threshold_min`` (> 0);
- **leak**: the reference drifts down at ``leak_rate·θ_on`` per second (log-normal per-pixel rate, median
  ``leak_rate_hz``): a static pixel emits ON events at that rate. The sensor starts in its steady state, each
  pixel at a uniformly random phase of its leak cycle, so leak events come at that rate from the first instant.
  An ON event whose change since the last reset owes more to the drift than to the light is labelled leak (2);
- **shot noise** (label 1): a Poisson process of random polarity with rate ``r(I) = r₁·(I₁/I)^γ``, where ``I₁`` is
  the photocurrent of a pixel seeing the scene's mean luminance at 1 lx (plus dark current) and
  ``r₁ = shot_noise_rate_hz_at_1lux``. Graça & Delbruck (2021) explain why DVS noise rises as light falls: the
  photocurrent's relative shot-noise amplitude grows as ``1/sqrt(I)``, and in dim light it is no longer offset by a
  shrinking photoreceptor bandwidth alone. We model the result, not the first-passage process: a power law in the
  photocurrent, ``γ = shot_noise_current_exponent`` (default 0.5, the amplitude's scaling), calibrated at 1 lx.
  The rate saturates in the dark because ``I ≥ I_dark``, and the refractory period caps it. Noise events do not
  move the reference (they are transient excursions), so a static scene yields only noise-labelled events;
- **hot pixels** (label 3): a fraction of pixels fire an extra Poisson process at ``hot_pixel_rate_hz``;
- **readout**: timestamp = detection + ``max(0, latency + jitter·z)``; the pixel is blind from detection until
  ``refractory_s`` after its event is read out, so events of one pixel are ≥ ``refractory_s`` apart; a signal
  crossing that falls in that window fires when the window ends (if the change still exceeds the threshold).

This module holds what the parameters alone determine: the event labels, the fixed pattern (:class:`PixelMaps`),
the parameter checks, the sensor's photocurrent and the bound on the noise processes' work
(:func:`noise_work_problem`).
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np

from simspad import defaults
from simspad.physics.photoreceptor import photocurrent_e_s, reference_current_1lux, shot_noise_rate_hz
from simspad.sensors.presets import EventParams

LABEL_SIGNAL, LABEL_SHOT, LABEL_LEAK, LABEL_HOT = 0, 1, 2, 3
LABEL_NAMES = {LABEL_SIGNAL: "signal", LABEL_SHOT: "shot_noise", LABEL_LEAK: "leak", LABEL_HOT: "hot_pixel"}
_FIELD = "sensors.events"


class PixelMaps(NamedTuple):
    """Fixed per-pixel properties of one sensor, flattened to ``[H·W]`` (a NamedTuple: numba kernels take it).

    Attributes
    ----------
    threshold_on, threshold_off : ndarray float64
        Contrast thresholds (log units), ≥ ``threshold_min``.
    leak_rate_hz : ndarray float64
        Leak event rate (reference drift ``leak_rate_hz·threshold_on`` per second).
    hot_rate_hz : ndarray float64
        Extra event rate of hot pixels (0 elsewhere), Hz.
    rng_state : ndarray uint64
        Seeds of the per-pixel random streams.
    """

    threshold_on: np.ndarray
    threshold_off: np.ndarray
    leak_rate_hz: np.ndarray
    hot_rate_hz: np.ndarray
    rng_state: np.ndarray


def draw_pixel_maps(params: EventParams, shape: tuple[int, int], rng: np.random.Generator) -> PixelMaps:
    """Draw the fixed pattern (in this order: ON, OFF thresholds, leak rates, hot pixels, stream seeds)."""
    n = int(shape[0]) * int(shape[1])
    theta_on = params.threshold_on + params.threshold_sigma * rng.standard_normal(n)
    theta_off = params.threshold_off + params.threshold_sigma * rng.standard_normal(n)
    leak = params.leak_rate_hz * np.exp(params.leak_rate_log_sigma * rng.standard_normal(n))
    hot = np.where(rng.random(n) < params.hot_pixel_fraction, params.hot_pixel_rate_hz, 0.0)
    seeds = rng.integers(0, np.iinfo(np.uint64).max, size=n, dtype=np.uint64, endpoint=True)
    return PixelMaps(threshold_on=np.maximum(theta_on, params.threshold_min),
                     threshold_off=np.maximum(theta_off, params.threshold_min),
                     leak_rate_hz=leak, hot_rate_hz=hot, rng_state=seeds)


def noise_rates_hz(params: EventParams, lux: float, mean_ratio: float | None = None) -> tuple[float, float]:
    """Mean noise-process rates per pixel, Hz: (shot noise, hot pixels); each is one hazard draw per event.

    ``mean_ratio`` is the pixels' mean of ``(I₁/I)^γ`` when the scene is known (see
    :func:`mean_shot_noise_ratio`). Without it the shot-noise rate is taken at the scene's mean luminance for the
    brightest or darkest possible scene, ``r₁·min(1, lux^−γ)`` (the mean pixel's current is ``lux·a + I_dark``
    with ``I₁ = a + I_dark``): a lower bound whatever the scene, since ``I^−γ`` is convex (Jensen).
    """
    exponent = params.shot_noise_current_exponent
    if mean_ratio is None:
        mean_ratio = math.exp(min(0.0, -exponent * math.log(lux))) if lux > 0 else 1.0  # min(1, lux^−γ)
    return params.shot_noise_rate_hz_at_1lux * mean_ratio, params.hot_pixel_fraction * params.hot_pixel_rate_hz


def mean_shot_noise_ratio(current_e_s: np.ndarray, current_1lux: float, params: EventParams) -> float:
    """Mean over pixels of ``(I₁/I)^γ``: the shot-noise rate of photocurrents ``current_e_s`` over ``r₁``."""
    rate = shot_noise_rate_hz(current_e_s, current_1lux, 1.0, params.shot_noise_current_exponent)
    return float(np.mean(rate, dtype=np.float64))


def leak_event_rate_hz(params: EventParams) -> float:
    """Leak events per pixel-second, a lower bound: half the pixels leak at least the median rate (log-normal
    spread), and a pixel is blind from detection until ``refractory_s`` after its readout (latency plus jitter,
    taken at 4 σ, plus the kernel's 1 ns guard)."""
    blind_s = max(params.refractory_s, 0.0) + max(params.latency_s + 4 * params.jitter_s, 0.0) + 1e-9
    return 0.5 * min(params.leak_rate_hz, 1.0 / blind_s)


def noise_work_problem(params: EventParams, n_pixels: int, duration_s: float, lux: float,
                       mean_ratio: float | None = None) -> str | None:
    """Why the noise processes of ``n_pixels`` over ``duration_s`` would take too much work, or None.

    The kernel draws a hazard for every shot-noise and hot-pixel event, even while the pixel is blind after an
    event (the refractory period caps the events written, not these draws), and writes every leak event, so the
    work is pixels × seconds × rate, refused above :data:`~simspad.defaults.MAX_EVENT_NOISE_DRAWS`
    (``SIMSPAD_IGNORE_LIMITS=1`` lifts it).
    """
    if os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1":
        return None
    shot_hz, hot_hz = noise_rates_hz(params, lux, mean_ratio)
    leak_hz = leak_event_rate_hz(params)
    rate_hz = shot_hz + hot_hz + leak_hz
    work = float(n_pixels) * float(duration_s) * rate_hz
    if not work > defaults.MAX_EVENT_NOISE_DRAWS:
        return None
    shot = (f"{shot_hz:.3g} Hz at the first keyframe" if mean_ratio is not None
            else f"≥ {shot_hz:.3g} Hz at the scene's mean luminance")
    return (f"{n_pixels} pixels × {duration_s:g} s × {rate_hz:.3g} noise events per pixel-second (shot noise "
            f"{shot} at {lux:g} lx; hot pixels {hot_hz:.3g} Hz on average; leak ≥ {leak_hz:.3g} Hz) is "
            f"{work:.3g} random draws, above the limit of {defaults.MAX_EVENT_NOISE_DRAWS:.3g} (~"
            f"{work * 20e-9 / 3600:.3g} CPU-hours; the refractory period caps the events, not this work): lower "
            "shot_noise_rate_hz_at_1lux, hot_pixel_rate_hz or leak_rate_hz, or set SIMSPAD_IGNORE_LIMITS=1 to try "
            "anyway")


def noise_field(params: EventParams, lux: float) -> str:
    """The parameter that contributes most of the noise work (for a message's field)."""
    shot_hz, hot_hz = noise_rates_hz(params, lux)
    rates = {"shot_noise_rate_hz_at_1lux": shot_hz, "hot_pixel_rate_hz": hot_hz,
             "leak_rate_hz": leak_event_rate_hz(params)}
    return f"{_FIELD}.{max(rates, key=rates.get)}"


def sensor_photocurrent_e_s(flux_ph_s_m2, params: EventParams, out: np.ndarray | None = None) -> np.ndarray:
    """Photocurrent of this sensor's pixels, e⁻ s⁻¹ (float64), for photon irradiance ``flux_ph_s_m2``
    (photons s⁻¹ m⁻²): :func:`simspad.physics.photoreceptor.photocurrent_e_s` with the sensor's pixel.

    ``out``: a float64 array of the flux's size to write into (no temporaries; the same values)."""
    return photocurrent_e_s(flux_ph_s_m2, params.pixel_pitch_m, params.fill_factor, params.qe,
                            params.dark_current_e_s, out=out)


def sensor_current_1lux_e_s(mean_flux_ph_s_m2: float, lux: float, params: EventParams) -> float:
    """``I₁`` of this sensor (shot-noise normalisation), e⁻ s⁻¹:
    :func:`simspad.physics.photoreceptor.reference_current_1lux` with the sensor's pixel."""
    return reference_current_1lux(mean_flux_ph_s_m2, lux, params.pixel_pitch_m, params.fill_factor, params.qe,
                                  params.dark_current_e_s)

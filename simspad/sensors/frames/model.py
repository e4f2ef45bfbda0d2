"""Conventional frame camera model (docs/sensors.md, preset ``blackfly_s``): the EMVA 1288 linear camera.

Chain, per pixel and frame (after the EMVA 1288 reference code ``emva1288/camera/camera.py``)::

    photons  = ∫ Φ(t) dt over the pixel's exposure window · pitch² · fill_factor      (motion blur)
    e⁻       = Poisson(η · photons · PRNU map) + Poisson(dark_current · t_exp) + DSNU map
    e⁻       = min(e⁻, full_well)
    e⁻      += N(0, read_noise²)
    DN       = clip(round(K · e⁻ + black_level), 0, 2^bits − 1)            uint16

``pitch² · fill_factor`` is :func:`simspad.physics.radiometry.sensitive_area_m2`; η (``qe``) is applied in the
electron draw, so the detection area of the other sensors is not formed here.

The fixed-pattern maps (PRNU: relative gain ``1 + prnu·z``; DSNU: ``dsnu_e·z`` electrons, z standard normal)
are drawn once per recording from the sensor's random stream, before any frame (:func:`draw_fixed_pattern`).

RGB (``rgb = true``): an RGGB Bayer mosaic (:func:`bayer_channel_map`); the colour filters' transmission is
folded into ``qe``. Exposure windows and the exposure integral are in :mod:`simspad.sensors.frames.simulator`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simspad.errors import SimSpadError
from simspad.physics.radiometry import sensitive_area_m2
from simspad.sensors.presets import FrameParams

#: Bayer colour-filter layout: channel index (0 R, 1 G, 2 B) of the 2×2 cell, row-major.
BAYER_RGGB = np.array([[0, 1], [1, 2]], dtype=np.intp)
_FIELD = "sensors.frames"


# ----------------------------------------------------------------------------------------------- fixed pattern
@dataclass(frozen=True)
class FixedPattern:
    """Per-pixel fixed-pattern maps of one camera.

    Attributes
    ----------
    prnu_gain : ndarray [H, W] float64
        Relative photo-response (mean 1, rms ``prnu``), ≥ 0.
    dsnu_e : ndarray [H, W] float64
        Dark-signal offset in electrons (mean 0, rms ``dsnu_e``).
    """

    prnu_gain: np.ndarray
    dsnu_e: np.ndarray


def draw_fixed_pattern(params: FrameParams, shape: tuple[int, int], rng: np.random.Generator) -> FixedPattern:
    """Draw the PRNU and DSNU maps (Gaussian white fixed pattern); call once per recording."""
    prnu_gain = np.maximum(1.0 + params.prnu * rng.standard_normal(shape), 0.0)
    dsnu_e = params.dsnu_e * rng.standard_normal(shape)
    return FixedPattern(prnu_gain=prnu_gain, dsnu_e=dsnu_e)


# ----------------------------------------------------------------------------------------------- the EMVA chain
def dn_max(params: FrameParams) -> int:
    """Largest output value of the ADC, 2^bits − 1."""
    return (1 << int(params.bit_depth)) - 1


def photons_per_pixel(fluence_ph_m2: np.ndarray, params: FrameParams) -> np.ndarray:
    """Photons reaching a pixel's sensitive area from a fluence (∫Φ dt, photons m⁻²)."""
    return np.asarray(fluence_ph_m2, dtype=np.float64) * sensitive_area_m2(params.pixel_pitch_m, params.fill_factor)


def expose(photons: np.ndarray, exposure_s: float, pattern: FixedPattern, params: FrameParams,
           rng: np.random.Generator) -> np.ndarray:
    """One raw frame from the photons per pixel collected during ``exposure_s``.

    Parameters
    ----------
    photons : ndarray [H, W]
        Mean photons per pixel over the exposure (before quantum efficiency).
    exposure_s : float
        Exposure time, s (sets the dark-current electrons).
    pattern : FixedPattern
        The camera's PRNU/DSNU maps.
    params : FrameParams
    rng : numpy.random.Generator

    Returns
    -------
    ndarray [H, W] uint16
        Digital numbers.
    """
    mean_photo_e = params.qe * np.asarray(photons, dtype=np.float64) * pattern.prnu_gain
    electrons = rng.poisson(mean_photo_e).astype(np.float64)
    dark_e = params.dark_current_e_s * exposure_s
    if dark_e > 0:
        electrons += rng.poisson(dark_e, size=electrons.shape)
    electrons += pattern.dsnu_e
    np.minimum(electrons, params.full_well_e, out=electrons)
    electrons += params.read_noise_e * rng.standard_normal(electrons.shape)
    dn = np.rint(params.gain_dn_per_e * electrons + params.black_level_dn)
    return np.clip(dn, 0, dn_max(params)).astype(np.uint16)


# ----------------------------------------------------------------------------------------------- exposure control
def auto_exposure(flux_ph_s_m2: np.ndarray, params: FrameParams) -> float:
    """Longest exposure keeping the 99th-percentile signal at or below ``auto_max_fill`` of the full well.

    Bounded by ``max_exposure_s`` and the frame period ``1 / frame_rate_hz``.

    Parameters
    ----------
    flux_ph_s_m2 : ndarray [H, W]
        Photon irradiance of the first keyframe (per-pixel channel flux for a Bayer sensor).

    Returns
    -------
    float
        Exposure in seconds.
    """
    limit_s = min(params.max_exposure_s, 1.0 / params.frame_rate_hz)
    p99 = float(np.percentile(np.asarray(flux_ph_s_m2, dtype=np.float64), 99.0))
    rate_e_s = params.qe * float(photons_per_pixel(p99, params)) + params.dark_current_e_s
    if rate_e_s <= 0:
        return limit_s
    return min(limit_s, params.auto_max_fill * params.full_well_e / rate_e_s)


def resolve_exposure(params: FrameParams, first_flux_ph_s_m2: np.ndarray) -> float:
    """The exposure in seconds: the fixed value (> 0 and within the frame period: the record,
    :class:`~simspad.sensors.presets.FrameParams`, checked it) or :func:`auto_exposure`."""
    if params.exposure_s == "auto":
        return auto_exposure(first_flux_ph_s_m2, params)
    return float(params.exposure_s)


def validate_params(params: FrameParams, height: int) -> None:
    """Raise :class:`SimSpadError` naming the field when the parameters do not fit an image ``height`` rows high
    (the rolling-shutter readout must end within the frame period); every other rule is the record's own
    (:class:`~simspad.sensors.presets.FrameParams`, checked when it was built)."""
    readout_s = (height - 1) * params.rolling_shutter_line_s
    if readout_s >= 1.0 / params.frame_rate_hz:
        raise SimSpadError(f"rolling-shutter readout {readout_s!r} s ({height} rows) exceeds the frame period",
                           field=f"{_FIELD}.rolling_shutter_line_s")


# ----------------------------------------------------------------------------------------------- colour mosaic
def bayer_channel_map(height: int, width: int, pattern: np.ndarray = BAYER_RGGB) -> np.ndarray:
    """Channel index (0 R, 1 G, 2 B) of every pixel of a Bayer mosaic, [H, W] intp."""
    rows = np.arange(height)[:, None] % 2
    cols = np.arange(width)[None, :] % 2
    return pattern[rows, cols]

"""Event-pixel photoreceptor: photocurrent, its intensity-dependent bandwidth, and the shot-noise event rate.

- **photocurrent** ``I = qe·fill·pitch²·Φ + I_dark`` (e⁻ s⁻¹), Φ the sensor-plane photon irradiance
  (photons s⁻¹ m⁻²; detection area as :func:`simspad.physics.radiometry.detection_rate`);
- **photoreceptor**: a first-order low-pass of ``ln I`` with cutoff

      f_c = f_max·I/(I + I_ref),      τ = 1/(2π f_c) = (I + I_ref)/(2π f_max I),

  so dim pixels lag: the bandwidth is proportional to the photocurrent below ``I_ref`` and saturates at
  ``f_max`` above it;
- **shot-noise event rate** ``r(I) = r₁·(I₁/I)^γ``, where ``I₁`` is the photocurrent of a pixel seeing the scene's
  mean luminance at 1 lx (plus dark current) and ``r₁`` the rate there. Graça & Delbruck (2021, "Unraveling the
  paradox of intensity-dependent DVS pixel noise") explain why DVS noise rises as light falls: the photocurrent's
  relative shot-noise amplitude grows as ``1/sqrt(I)``, and in dim light it is no longer offset by a shrinking
  photoreceptor bandwidth alone. This is the result as a power law in the photocurrent (``γ = 0.5`` is the
  amplitude's scaling), calibrated at 1 lx, not the first-passage process; the rate saturates in the dark because
  ``I ≥ I_dark``.

The functions take plain numbers and arrays (no sensor parameter record: physics knows nothing of the sensors).
:func:`time_constant_pair` is the numba form of :func:`time_constant_s` for the event kernel, with the same
calling convention; it rounds differently (τ and 1/τ from one division) and must stay as it is for the recordings
to stay byte-identical.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from simspad.physics.radiometry import detection_area_m2, detection_rate

#: Smallest photocurrent the models take, e⁻ s⁻¹: keeps ln I finite if a user sets the dark current to 0.
MIN_CURRENT_E_S = 1e-6
_TWO_PI = 2.0 * math.pi


def photocurrent_e_s(flux_ph_s_m2, pixel_pitch_m: float, fill_factor: float, qe: float,
                     dark_current_e_s: float, out: np.ndarray | None = None) -> np.ndarray:
    """Photo-electron rate plus dark current.

    Parameters
    ----------
    flux_ph_s_m2 : float or ndarray
        Photon irradiance at the sensor plane, photons s⁻¹ m⁻².
    pixel_pitch_m : float
        Pixel pitch, m.
    fill_factor, qe : float
        Sensitive fraction of the pixel and its quantum efficiency.
    dark_current_e_s : float
        Dark current, e⁻ s⁻¹.
    out : ndarray float64, optional
        Written in place instead of allocating (the flux reshaped to its shape; the same values): streaming
        callers fill chunk buffers without temporaries.

    Returns
    -------
    ndarray float64
        Photocurrent ``I``, e⁻ s⁻¹ (``out`` when given).
    """
    if out is None:
        signal = detection_rate(np.asarray(flux_ph_s_m2, dtype=np.float64), pixel_pitch_m, fill_factor, qe)
        return signal + dark_current_e_s
    np.multiply(np.asarray(flux_ph_s_m2).reshape(out.shape), detection_area_m2(pixel_pitch_m, fill_factor, qe),
                out=out, dtype=np.float64)
    out += dark_current_e_s
    return out


def cutoff_hz(photocurrent, cutoff_hz_max: float, cutoff_ref_rate_e_s: float) -> np.ndarray:
    """Photoreceptor cutoff frequency ``f_c = f_max·I/(I + I_ref)``.

    Parameters
    ----------
    photocurrent : float or ndarray
        Photocurrent ``I``, e⁻ s⁻¹.
    cutoff_hz_max : float
        Bandwidth ``f_max`` of a bright pixel, Hz.
    cutoff_ref_rate_e_s : float
        Photocurrent ``I_ref`` at which the cutoff reaches half of ``f_max``, e⁻ s⁻¹.

    Returns
    -------
    ndarray float64
        Cutoff frequency, Hz.
    """
    current = np.asarray(photocurrent, dtype=np.float64)
    return cutoff_hz_max * current / (current + cutoff_ref_rate_e_s)


def time_constant_s(photocurrent, cutoff_hz_max: float, cutoff_ref_rate_e_s: float):
    """Photoreceptor time constant ``τ = 1/(2π f_c) = (I + I_ref)/(2π f_max I)``.

    Parameters are those of :func:`cutoff_hz`; returns τ in s, of the type numpy gives the arithmetic (float or
    ndarray).
    """
    return (photocurrent + cutoff_ref_rate_e_s) / (2.0 * np.pi * cutoff_hz_max * photocurrent)


@numba.njit(cache=True, inline="always", error_model="numpy")
def time_constant_pair(photocurrent, cutoff_hz_max, cutoff_ref_rate_e_s):
    """``(τ, 1/τ)`` of :func:`time_constant_s` for one photocurrent (s, s⁻¹), for numba kernels.

    Both come from one division (``q = 1/(I·(I + I_ref))``): the event kernel takes them once per internal step.
    Inlined, so the loop-invariant ``2π f_max`` and its inverse are hoisted out of the caller's loop.
    """
    two_pi_fmax = _TWO_PI * cutoff_hz_max
    inv_two_pi_fmax = 1.0 / (_TWO_PI * cutoff_hz_max)
    q = 1.0 / (photocurrent * (photocurrent + cutoff_ref_rate_e_s))
    tau = (photocurrent + cutoff_ref_rate_e_s) * (photocurrent + cutoff_ref_rate_e_s) * q * inv_two_pi_fmax
    inv_tau = photocurrent * photocurrent * q * two_pi_fmax
    return tau, inv_tau


def reference_current_1lux(mean_flux_ph_s_m2: float, lux: float, pixel_pitch_m: float, fill_factor: float,
                           qe: float, dark_current_e_s: float) -> float:
    """``I₁``: photocurrent of a pixel at the scene's mean luminance scaled to 1 lx, plus dark current.

    Parameters
    ----------
    mean_flux_ph_s_m2 : float
        Mean sensor-plane photon irradiance of the scene at illuminance ``lux``, photons s⁻¹ m⁻².
    lux : float
        That scene illuminance, lx (≤ 0 or None: no signal part).
    pixel_pitch_m, fill_factor, qe, dark_current_e_s : float
        As :func:`photocurrent_e_s`.

    Returns
    -------
    float
        ``I₁``, e⁻ s⁻¹.
    """
    signal = float(detection_rate(mean_flux_ph_s_m2, pixel_pitch_m, fill_factor, qe))
    per_lux = signal / lux if lux and lux > 0 else 0.0
    return per_lux + dark_current_e_s


def shot_noise_rate_hz(photocurrent, current_1lux_e_s: float, rate_hz_at_1lux: float,
                       current_exponent: float) -> np.ndarray:
    """Shot-noise event rate ``r₁·(I₁/I)^γ``.

    Parameters
    ----------
    photocurrent : float or ndarray
        Photocurrent ``I``, e⁻ s⁻¹ (clamped to ≥ :data:`MIN_CURRENT_E_S`).
    current_1lux_e_s : float
        ``I₁`` of :func:`reference_current_1lux`, e⁻ s⁻¹.
    rate_hz_at_1lux : float
        ``r₁``, Hz.
    current_exponent : float
        ``γ``.

    Returns
    -------
    ndarray float64
        Rate, Hz.
    """
    current = np.maximum(np.asarray(photocurrent, dtype=np.float64), MIN_CURRENT_E_S)
    return rate_hz_at_1lux * (current_1lux_e_s / current) ** current_exponent

"""Radiometry (docs/sensors.md): relative rendered luminance → lux level → photon irradiance at the sensor plane.

Chain, for a scene lit by illuminance E (lux) and rendered in relative units Y_rel:

1. scene luminance  L = Y_rel · ρ̄·E / (π · mean(Y_rel))           cd m⁻²   (mean luminance = ρ̄E/π, ρ̄ = 0.18)
2. sensor-plane illuminance  E_img = π · L · T_lens / (4 N²)          lx       (camera equation)
3. photon irradiance  Φ = E_img · photons_per_lux(illuminant)         photons s⁻¹ m⁻²
4. per-pixel detection rate  λ = Φ · q,  q = pitch² · fill_factor · qe      photons s⁻¹  (q: detection area, m²)

The photons-per-lux factor integrates the illuminant's spectral distribution over the visible band with
colour-science: ∫S(λ)·λ/(hc) dλ ÷ (K_m·∫V(λ)S(λ) dλ).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from simspad.physics.colour_tables import PHOTONS_PER_LUX, SRGB_TO_Y, photons_per_lux_from_spectrum

#: Middle-grey reflectance of incident-light metering: the scene's mean luminance is ρ̄·E/π.
MEAN_REFLECTANCE = 0.18
#: Default f-number and lens transmission of the camera equation.
DEFAULT_F_NUMBER = 2.0
DEFAULT_LENS_TRANSMISSION = 0.9
DEFAULT_ILLUMINANT = "D65"


@dataclass(frozen=True)
class Optics:
    """Lens and illumination assumptions that map lux to sensor-plane photons.

    Attributes
    ----------
    f_number : float
        Lens f-number N.
    lens_transmission : float
        Lens transmittance T_lens in (0, 1].
    illuminant : str or float
        A colour-science illuminant name (``"D65"``, ``"A"``, ``"LED-B3"``, ...) or a wavelength in nm for
        monochromatic light.
    reflectance : float
        Mean scene reflectance ρ̄ assumed by the lux convention.
    """

    f_number: float = DEFAULT_F_NUMBER
    lens_transmission: float = DEFAULT_LENS_TRANSMISSION
    illuminant: str | float = DEFAULT_ILLUMINANT
    reflectance: float = MEAN_REFLECTANCE

    def __post_init__(self):
        if not (self.f_number > 0):
            raise ValueError(f"optics.f_number must be > 0, got {self.f_number}")
        if not (0 < self.lens_transmission <= 1):
            raise ValueError(f"optics.lens_transmission must be in (0, 1], got {self.lens_transmission}")
        if not (0 < self.reflectance <= 1):
            raise ValueError(f"optics.reflectance must be in (0, 1], got {self.reflectance}")
        photons_per_lux(self.illuminant)  # fail early on an unknown illuminant

    def to_attrs(self) -> dict:
        """Flat attributes for HDF5 (every value a scalar or string)."""
        return {"f_number": float(self.f_number), "lens_transmission": float(self.lens_transmission),
                "illuminant": str(self.illuminant), "reflectance": float(self.reflectance),
                "photons_per_lux": photons_per_lux(self.illuminant)}


@functools.lru_cache(maxsize=None)
def photons_per_lux(illuminant: str | float = DEFAULT_ILLUMINANT) -> float:
    """Photon irradiance per lux of an illuminant, photons s⁻¹ m⁻² lx⁻¹.

    The named illuminants of colour-science come from :data:`~simspad.physics.colour_tables.PHOTONS_PER_LUX`
    (the same numbers, tabulated so that a process need not import colour-science); a wavelength or a name
    spelled otherwise is computed with colour-science
    (:func:`~simspad.physics.colour_tables.photons_per_lux_from_spectrum`).

    Parameters
    ----------
    illuminant : str or float
        Name in ``colour.SDS_ILLUMINANTS`` (D65 ≈ 1.389e16, A ≈ 2.10e16, LED-B3 ≈ 8.97e15), or a wavelength in
        nm for monochromatic light (555 nm ≈ 4.09e15).

    Raises
    ------
    ValueError
        Unknown illuminant name.
    """
    if isinstance(illuminant, str) and illuminant in PHOTONS_PER_LUX:
        return PHOTONS_PER_LUX[illuminant]
    return photons_per_lux_from_spectrum(illuminant)


@functools.lru_cache(maxsize=1)
def _rgb_to_y_weights() -> np.ndarray:
    return np.asarray(SRGB_TO_Y, dtype=np.float32)


def luminance_from_rgb(rgb: np.ndarray) -> np.ndarray:
    """Relative luminance Y of linear sRGB / Rec.709 values (the middle row of colour's RGB→XYZ matrix).

    Parameters
    ----------
    rgb : ndarray [..., 3]
        Linear (not gamma-encoded) RGB.

    Returns
    -------
    ndarray [...]
        float32 luminance in the units of ``rgb``: ``(R·w_R + G·w_G) + B·w_B``, each operation rounded to
        float32, so every machine gives the same bits.
    """
    rgb = np.asarray(rgb)
    if rgb.shape[-1] != 3:
        raise ValueError(f"expected a last axis of 3 (R, G, B), got shape {rgb.shape}")
    rgb = rgb.astype(np.float32, copy=False)
    return luminance_from_planes(rgb[..., 0], rgb[..., 1], rgb[..., 2])


def luminance_from_planes(r: np.ndarray, g: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`luminance_from_rgb` of the separate float32 planes ``r``, ``g``, ``b`` (the same bits)."""
    w_r, w_g, w_b = _rgb_to_y_weights()
    # Element-wise products and sums, not a matrix product: NumPy hands `@` to BLAS, whose kernel (chosen for the
    # CPU at run time) sets the summation order and whether it fuses multiply-adds. An AVX-512 and an AVX2 machine
    # then differ in the last bit of ~20 % of the pixels, and with them every SPAD bit, event and ground-truth
    # value downstream: one spec and seed would give different recordings on different workers of a cluster.
    y = np.multiply(r, w_r, dtype=np.float32)
    y += np.multiply(g, w_g, dtype=np.float32)
    y += np.multiply(b, w_b, dtype=np.float32)
    return y


def luminance_scale(mean_relative_luminance: float, lux: float, optics: Optics | None = None) -> float:
    """Factor from relative rendered luminance to cd m⁻², so that the mean becomes ρ̄·E/π."""
    optics = optics or Optics()
    _check_positive(mean_relative_luminance, "mean_relative_luminance")
    _check_positive(lux, "lux")
    return optics.reflectance * lux / math.pi / mean_relative_luminance


def sensor_illuminance_per_luminance(optics: Optics | None = None) -> float:
    """Camera equation factor π·T_lens/(4N²): sensor-plane lux per cd m⁻² of scene luminance."""
    optics = optics or Optics()
    return math.pi * optics.lens_transmission / (4.0 * optics.f_number**2)


def flux_scale(mean_relative_luminance: float, lux: float, optics: Optics | None = None) -> float:
    """Factor from relative rendered luminance to sensor-plane photon irradiance.

    ``flux_ph_s_m2 = flux_scale(mean(Y_rel), E) * Y_rel``, with mean(Y_rel) taken on the sequence's first
    keyframe (docs/sensors.md).

    Parameters
    ----------
    mean_relative_luminance : float
        Mean of the relative luminance image the lux level refers to (> 0).
    lux : float
        Scene illuminance E in lux (> 0).
    optics : Optics, optional
        Default ``Optics()``: f-number, lens transmission, illuminant and reference reflectance.

    Returns
    -------
    float
        photons s⁻¹ m⁻² per relative luminance unit.
    """
    optics = optics or Optics()
    return (luminance_scale(mean_relative_luminance, lux, optics) * sensor_illuminance_per_luminance(optics)
            * photons_per_lux(optics.illuminant))


def sensitive_area_m2(pixel_pitch_m: float, fill_factor: float) -> float:
    """Light-sensitive area of one pixel, ``pitch² · fill_factor`` (m²).

    Parameters
    ----------
    pixel_pitch_m : float
        Pixel pitch, m.
    fill_factor : float
        Fraction of the pixel area that is sensitive, in (0, 1].

    Returns
    -------
    float
        m²: photons per pixel per photon m⁻² of fluence (before quantum efficiency).
    """
    return pixel_pitch_m**2 * fill_factor


def detection_area_m2(pixel_pitch_m: float, fill_factor: float, qe: float) -> float:
    """Detection area of one pixel, ``q = pitch² · fill_factor · qe`` (m²).

    The simulators and the analyses call it (the SPAD records it as its ``detection_area_m2`` attribute).
    Evaluated as ``(pitch² · fill_factor) · qe``. The fusion methods multiply in their historic order,
    ``(qe · fill_factor) · pitch²`` (:func:`simspad.methods.spad_response.attrs_detection_area_m2`), up to 1 ulp
    apart; they keep it so that evaluation results stay bit-identical.

    Parameters
    ----------
    pixel_pitch_m : float
        Pixel pitch, m.
    fill_factor : float
        Fraction of the pixel area that is sensitive, in (0, 1].
    qe : float
        Quantum efficiency (photon detection probability), spectrally weighted, in (0, 1].

    Returns
    -------
    float
        m²: detections s⁻¹ per photon s⁻¹ m⁻² (``q·Φ`` is the pixel's detection rate).
    """
    return sensitive_area_m2(pixel_pitch_m, fill_factor) * qe


def detection_rate(flux_ph_s_m2, pixel_pitch_m: float, fill_factor: float, qe: float):
    """Detected photons per second per pixel: λ = Φ · pitch² · fill_factor · qe (see :func:`detection_area_m2`).

    Parameters
    ----------
    flux_ph_s_m2 : float or ndarray
        Photon irradiance at the sensor plane, photons s⁻¹ m⁻².
    pixel_pitch_m : float
        Pixel pitch in metres.
    fill_factor, qe : float
        Fraction of the pixel that is sensitive and its (spectrally weighted) quantum efficiency.
    """
    return np.asarray(flux_ph_s_m2) * detection_area_m2(pixel_pitch_m, fill_factor, qe)


def _check_positive(value: float, name: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value}")

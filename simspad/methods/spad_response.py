"""Sensor responses as seen by the methods: SPAD gated binary response and the EMVA 1288 frame response.

Everything is read from a recording's attrs (docs/format.md), never from the simulator, so the same code inverts
real captures converted to the recording layout.

SPAD (docs/sensors.md; Ma et al., SIGGRAPH 2020): a bin's bit is 1 with probability
``p = 1 − exp(−(q·Φ + r_dark)·gate_s)``, with ``q = qe·fill_factor·pixel_pitch_m²`` the detection efficiency per
unit photon irradiance (m²), so ``q·Φ`` is the detection rate of a pixel. With S ones in n bins the ML estimate
is ``Φ̂ = (−ln(1 − S/n)/gate_s − r_dark)/q`` (S = n clamped to n − 1 as in the QBP code) and, by the Fisher
information of n Bernoulli bins, ``Var(ln Φ̂) = (e^y − 1)/(n·x²)`` with ``x = q·Φ·gate_s`` and
``y = x + r_dark·gate_s`` (the dark-count term; with r_dark = 0 this is docs/sensors.md's ``(eˣ − 1)/(n·x²)``).

Frames (EMVA 1288): electrons ``μ_e = (DN − black)/K``; photon irradiance
``Φ = μ_e/(qe·fill_factor·pixel_pitch_m²·exposure_s)``; ``Var(ln Φ̂) = (μ_e + σ_r² + 1/(12K²))/μ_e²``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simspad.errors import InputError
from simspad.physics import spad_statistics as _stats
from simspad.physics.spad_statistics import detection_probability  # noqa: F401  (re-exported)

# A log estimate from fewer than this many expected detections/electrons is treated as this many: it keeps
# ln Φ finite for empty pixels and gives them a correspondingly large variance (≈ 1/FLOOR_COUNT).
FLOOR_COUNT = 0.5


def attrs_detection_area_m2(pixel_pitch_m: float, fill_factor: float, qe: float) -> float:
    """Detection area ``qe·fill_factor·pixel_pitch_m²`` (m²) of a sensor group, as the methods compute it.

    Multiplied in the order the methods have always used, ``(qe·fill_factor)·pitch²``: it can differ by 1 ulp
    from :func:`simspad.physics.radiometry.detection_area_m2` (``(pitch²·fill_factor)·qe``, the simulators'
    order, recorded as ``/spad`` ``detection_area_m2``), and that ulp changes some evaluation results (NEDI+AKF
    on the mini dataset's plant at 10000 lx). Kept so evaluations stay bit-identical across the restructuring;
    moving to the simulators' product is a behaviour change of its own.
    """
    return qe * fill_factor * pixel_pitch_m ** 2


@dataclass(frozen=True)
class SpadResponse:
    """Parameters of the SPAD response, from ``/spad`` attrs.

    Attributes
    ----------
    q_m2 : float
        Detection efficiency per unit photon irradiance, ``qe·fill_factor·pixel_pitch_m²`` (m²).
    gate_s, bin_s : float
        Gate (exposure) within each bin and the bin period (s).
    dcr_cps : ndarray [H, W]
        Dark count rate map (counts s⁻¹).
    """

    q_m2: float
    gate_s: float
    bin_s: float
    dcr_cps: np.ndarray

    @classmethod
    def from_recording(cls, rec) -> "SpadResponse":
        a = rec.spad.attrs
        try:
            q = attrs_detection_area_m2(float(a["pixel_pitch_m"]), float(a["fill_factor"]), float(a["qe"]))
            bin_s = float(a["bin_s"])
            gate_s = float(a.get("gate_s", bin_s))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"SPAD attrs incomplete or not numeric ({exc})", path=rec.path, field="/spad attrs")
        if not (q > 0 and gate_s > 0 and bin_s > 0):
            raise InputError("qe, fill_factor, pixel_pitch_m, gate_s, bin_s must be > 0", path=rec.path,
                             field="/spad attrs")
        dcr = np.asarray(rec.spad.dcr_cps, dtype=np.float64)
        return cls(q, gate_s, bin_s, dcr)


def estimate_flux(counts, n_bins, q_m2, gate_s, dcr_cps=0.0):
    """ML photon irradiance (ph s⁻¹ m⁻²) from ``counts`` ones in ``n_bins`` bins, clipped at 0 (an image)."""
    return np.maximum(_stats.estimate_flux(counts, n_bins, q_m2, gate_s, dcr_cps), 0.0)


def floor_flux(n_bins, q_m2, gate_s):
    """Irradiance giving ``FLOOR_COUNT`` expected detections in ``n_bins`` gates: the log-domain floor."""
    return FLOOR_COUNT / (n_bins * gate_s * q_m2)


def log_flux_variance(flux_ph_s_m2, n_bins, q_m2, gate_s, dcr_cps=0.0):
    """Cramér–Rao variance of ln Φ̂ (:func:`simspad.physics.spad_statistics.log_flux_variance`), with irradiances
    below :func:`floor_flux` evaluated at the floor."""
    flux = np.maximum(np.asarray(flux_ph_s_m2, dtype=np.float64), floor_flux(n_bins, q_m2, gate_s))
    return _stats.log_flux_variance(flux, n_bins, q_m2, gate_s, dcr_cps)


@dataclass(frozen=True)
class FrameResponse:
    """EMVA 1288 parameters of the conventional camera, from ``/frames`` attrs."""

    gain_dn_per_e: float
    black_level_dn: float
    read_noise_e: float
    full_well_e: float
    bit_depth: int
    area_eff_m2: float
    """``qe·fill_factor·pixel_pitch_m²``: electrons per (ph m⁻²)."""

    @classmethod
    def from_recording(cls, rec) -> "FrameResponse":
        a = rec.frames.attrs
        try:
            return cls(float(a["gain_dn_per_e"]), float(a["black_level_dn"]), float(a["read_noise_e"]),
                       float(a["full_well_e"]), int(a["bit_depth"]),
                       attrs_detection_area_m2(float(a["pixel_pitch_m"]), float(a.get("fill_factor", 1.0)),
                                               float(a["qe"])))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"frame attrs incomplete or not numeric ({exc})", path=rec.path,
                             field="/frames attrs")

    @property
    def max_dn(self) -> float:
        return 2.0 ** self.bit_depth - 1.0

    def electrons(self, dn) -> np.ndarray:
        return (np.asarray(dn, dtype=np.float64) - self.black_level_dn) / self.gain_dn_per_e

    def saturated(self, dn) -> np.ndarray:
        """Pixels at the ADC ceiling or at the full well (their value is only a lower bound)."""
        e = self.electrons(dn)
        return (np.asarray(dn) >= self.max_dn) | (e >= 0.999 * self.full_well_e)

    def flux(self, dn, exposure_s: float) -> np.ndarray:
        """Photon irradiance (ph s⁻¹ m⁻²) from DN, clipped at 0."""
        return np.maximum(self.electrons(dn), 0.0) / (self.area_eff_m2 * exposure_s)

    def log_variance(self, dn) -> np.ndarray:
        """Var(ln Φ̂) from shot, read and quantisation noise; saturated pixels get a large variance (1)."""
        e = np.maximum(self.electrons(dn), FLOOR_COUNT)
        var = (e + self.read_noise_e ** 2 + 1.0 / (12.0 * self.gain_dn_per_e ** 2)) / (e * e)
        return np.where(self.saturated(dn), np.maximum(var, 1.0), var)

    def log_variance_at_flux(self, flux_ph_s_m2, exposure_s: float, saturated=False) -> np.ndarray:
        """Var(ln Φ̂) of a frame at a given irradiance (shot + read + quantisation), large where ``saturated``."""
        e = np.maximum(np.asarray(flux_ph_s_m2, dtype=np.float64) * self.area_eff_m2 * exposure_s, FLOOR_COUNT)
        var = (e + self.read_noise_e ** 2 + 1.0 / (12.0 * self.gain_dn_per_e ** 2)) / (e * e)
        return np.where(saturated, np.maximum(var, 1.0), var)

    def floor_flux(self, exposure_s: float) -> float:
        return FLOOR_COUNT / (self.area_eff_m2 * exposure_s)

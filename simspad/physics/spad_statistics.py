"""The gated binary SPAD's response and its maximum-likelihood inverse (docs/sensors.md).

One place for the formulas that the simulator (``sensors/spad/``) and the methods
(``methods/spad_response.py``) share; it imports nothing else of SimSPAD, so the methods' wall (they read only
recordings, never the simulator) holds. Every function takes the same arguments in the same order:
``q_m2 = qe·fill_factor·pixel_pitch_m²`` is the detection area (detections s⁻¹ per photon s⁻¹ m⁻², so ``q·Φ`` is
a pixel's detection rate), ``gate_s`` the gate in seconds and ``dcr_cps`` the dark count rate.

Sources: the binary-SPAD image formation and ML estimator of quanta burst photography (Ma et al., SIGGRAPH 2020,
and its released code ``genBinImg.m``, ``mleIntensity.m``).
"""

from __future__ import annotations

import numpy as np


def detection_probability(flux_ph_s_m2, q_m2: float, gate_s: float, dcr_cps=0.0):
    """Probability that a gated bin reads 1 under constant irradiance: ``1 − exp(−(q·Φ + r_dark)·gate_s)``.

    Parameters
    ----------
    flux_ph_s_m2 : float or ndarray
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    q_m2 : float
        Detection area (pitch²·fill factor·qe), m².
    gate_s : float
        Gate duration, s.
    dcr_cps : float or ndarray
        Dark count rate, counts s⁻¹.

    Returns
    -------
    float or ndarray
        P(bit = 1), computed with ``expm1`` so tiny probabilities keep full precision.
    """
    rate = np.asarray(flux_ph_s_m2, dtype=np.float64) * q_m2 + np.asarray(dcr_cps, dtype=np.float64)
    return -np.expm1(-rate * gate_s)


def estimate_flux(counts, n_bins: int, q_m2: float, gate_s: float, dcr_cps=0.0):
    """Maximum-likelihood irradiance from ``counts`` ones in ``n_bins`` gated bins.

    ``Φ̂ = (−ln(1 − S/n)/gate_s − r_dark)/q``, with ``S = n`` clamped to ``n − 1`` (the ML estimate is infinite
    there). Not clipped: it may be slightly negative where S is at the dark level, which keeps it unbiased
    for statistics; reconstructions clip it.

    Returns
    -------
    ndarray
        Photon irradiance, photons s⁻¹ m⁻² (float64).
    """
    s = np.minimum(np.asarray(counts, dtype=np.float64), n_bins - 1.0)
    rate = -np.log1p(-s / n_bins) / gate_s
    return (rate - np.asarray(dcr_cps, dtype=np.float64)) / q_m2


def log_flux_variance(flux_ph_s_m2, n_bins: int, q_m2: float, gate_s: float, dcr_cps=0.0):
    """Cramér–Rao variance of ``ln Φ̂``: ``(e^y − 1)/(n·x²)``, ``x = q·Φ·gate_s``, ``y = x + r_dark·gate_s``.

    With ``r_dark = 0`` this is docs/sensors.md's ``(eˣ − 1)/(n·x²)``; the dark counts add to the detection
    probability (y) but carry no signal (x). A pixel whose every bin fires (y ≳ 709, far past saturation) gets
    +inf: its count says nothing about Φ, and ``eʸ`` overflows float64 exactly there.
    """
    x = q_m2 * np.asarray(flux_ph_s_m2, dtype=np.float64) * gate_s
    y = x + np.asarray(dcr_cps, dtype=np.float64) * gate_s
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.expm1(y) / (n_bins * x * x)

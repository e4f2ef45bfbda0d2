"""EMVA 1288 photon-transfer analysis of flat-field stacks (release 4.0 conventions).

Follows the EMVA 1288 reference code (``emva1288/process/results.py``):

- temporal noise σ²_y of a flat field: per-pixel variance over the stack's frames (for two frames this is the
  standard's ½·mean((y_A − y_B)²)), averaged over pixels — fixed-pattern noise cancels;
- system gain K: slope of (σ²_y − σ²_y.dark) against (μ_y − μ_y.dark) over the linear range, 0–70 % of the
  saturation signal;
- saturation: the point of maximum temporal variance; capacity μ_e.sat = (μ_y.sat − μ_y.dark)/K;
- temporal dark noise σ_d = sqrt(σ²_y.dark − σ²_q)/K with the quantisation noise σ²_q = 1/12 DN²;
- spatial variance of a stack of L frames: s²_y = var_pixels(mean image) − σ²_y/L;
- DSNU = s_y.dark / K (e⁻); PRNU = sqrt(s²_y.50 − s²_y.dark)/(μ_y.50 − μ_y.dark) at the level nearest 50 % of
  saturation;
- quantum efficiency η = R / K, R the slope of (μ_y − μ_y.dark) against photons per pixel μ_p (linear range).

The spatial nonuniformities are taken as white (no high-pass filtering of the mean images), which is what the
simulated fixed pattern is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

#: Variance of uniform quantisation with a step of 1 DN.
QUANTISATION_VARIANCE_DN2 = 1.0 / 12.0
#: Upper end of the linear range for the gain fit, as a fraction of the saturation signal (EMVA 1288 4.0).
LINEAR_RANGE_FRACTION = 0.7


@dataclass(frozen=True)
class PhotonTransfer:
    """Result of :func:`photon_transfer` (electrons, DN and ratios; numpy arrays per illumination level).

    Attributes
    ----------
    gain_dn_per_e : float
        System gain K, DN per electron.
    read_noise_e : float
        Temporal dark noise σ_d, electrons rms.
    saturation_e : float
        Saturation capacity μ_e.sat, electrons.
    dsnu_e : float
        Dark-signal non-uniformity, electrons rms.
    prnu : float
        Photo-response non-uniformity, relative rms.
    qe : float or None
        Quantum efficiency η (None without photon counts).
    mu_y, var_y, mu_y_dark, var_y_dark : ndarray [n]
        Mean and temporal variance of each level and of its dark reference, DN and DN².
    linear : ndarray [n] bool
        Levels used for the gain fit.
    saturation_index, prnu_index : int
        Level of maximum variance; level used for the PRNU.
    """

    gain_dn_per_e: float
    read_noise_e: float
    saturation_e: float
    dsnu_e: float
    prnu: float
    qe: float | None
    mu_y: np.ndarray = field(repr=False)
    var_y: np.ndarray = field(repr=False)
    mu_y_dark: np.ndarray = field(repr=False)
    var_y_dark: np.ndarray = field(repr=False)
    linear: np.ndarray = field(repr=False)
    saturation_index: int = 0
    prnu_index: int = 0


def temporal_stats(stack: np.ndarray) -> tuple[float, float]:
    """Mean (DN) and temporal variance (DN²) of a flat-field stack [L ≥ 2, H, W].

    The variance is each pixel's variance over the L frames (ddof = 1), averaged over pixels, after removing
    each frame's global mean drift (as the standard's two-frame formula does).
    """
    y = np.asarray(stack, dtype=np.float64)
    if y.ndim != 3 or y.shape[0] < 2:
        raise ValueError(f"a stack needs shape [L >= 2, H, W], got {y.shape}")
    frame_means = y.mean(axis=(1, 2))
    residual = y - frame_means[:, None, None]
    var = float(np.mean(np.var(residual, axis=0, ddof=1)))
    return float(frame_means.mean()), var


def spatial_variance(stack: np.ndarray) -> float:
    """Spatial variance s²_y (DN²) of a stack [L, H, W]: variance of the mean image minus σ²_y/L."""
    y = np.asarray(stack, dtype=np.float64)
    _, temporal = temporal_stats(y)
    mean_image = y.mean(axis=0)
    return float(np.var(mean_image, ddof=1) - temporal / y.shape[0])


def photon_transfer(bright: Sequence[np.ndarray], dark: np.ndarray | Sequence[np.ndarray],
                    photons_per_pixel: Sequence[float] | None = None) -> PhotonTransfer:
    """EMVA 1288 photon-transfer analysis.

    Parameters
    ----------
    bright : sequence of ndarray [L, H, W]
        Flat-field stacks (L ≥ 2) at increasing illumination, up to and beyond saturation.
    dark : ndarray [L, H, W] or sequence of them
        Dark stacks: one (varying irradiance at fixed exposure) or one per level (varying exposure).
        DSNU uses the first; more frames (L ≳ 50) are needed to resolve a DSNU well below the read noise.
    photons_per_pixel : sequence of float, optional
        Mean photons per pixel μ_p of each level, for the quantum efficiency.

    Returns
    -------
    PhotonTransfer
    """
    n = len(bright)
    if n < 3:
        raise ValueError("photon transfer needs at least 3 illumination levels")
    darks = [dark] if isinstance(dark, np.ndarray) and np.ndim(dark) == 3 else list(dark)
    if len(darks) not in (1, n):
        raise ValueError(f"need 1 or {n} dark stacks, got {len(darks)}")
    dark_stats = [temporal_stats(d) for d in darks]
    mu_dark = np.array([s[0] for s in dark_stats] * (n if len(darks) == 1 else 1))
    var_dark = np.array([s[1] for s in dark_stats] * (n if len(darks) == 1 else 1))
    stats = [temporal_stats(b) for b in bright]
    mu_y = np.array([s[0] for s in stats])
    var_y = np.array([s[1] for s in stats])

    isat = int(np.argmax(var_y))
    signal = mu_y - mu_dark
    linear = (signal >= 0) & (signal <= LINEAR_RANGE_FRACTION * signal[isat])
    linear[isat:] = False
    if linear.sum() < 2:
        raise ValueError("fewer than 2 levels in the linear range (0–70 % of saturation)")
    gain = float(np.polyfit(signal[linear], (var_y - var_dark)[linear], 1)[0])

    read_noise = float(np.sqrt(max(var_dark[0] - QUANTISATION_VARIANCE_DN2, 0.0)) / gain)
    saturation = float(signal[isat] / gain)
    s2_dark = spatial_variance(darks[0])
    dsnu = float(np.sqrt(max(s2_dark, 0.0)) / gain)
    i50 = int(np.argmin(np.abs(signal[: isat + 1] - 0.5 * signal[isat])))
    s2_50 = spatial_variance(bright[i50])
    prnu = float(np.sqrt(max(s2_50 - s2_dark, 0.0)) / signal[i50]) if signal[i50] > 0 else float("nan")

    qe = None
    if photons_per_pixel is not None:
        mu_p = np.asarray(photons_per_pixel, dtype=np.float64)
        if mu_p.shape != (n,):
            raise ValueError(f"photons_per_pixel must have {n} values, got shape {mu_p.shape}")
        responsivity = float(np.polyfit(mu_p[linear], signal[linear], 1)[0])
        qe = responsivity / gain
    return PhotonTransfer(gain_dn_per_e=gain, read_noise_e=read_noise, saturation_e=saturation, dsnu_e=dsnu,
                          prnu=prnu, qe=qe, mu_y=mu_y, var_y=var_y, mu_y_dark=mu_dark, var_y_dark=var_dark,
                          linear=linear, saturation_index=isat, prnu_index=i50)

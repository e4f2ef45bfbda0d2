r"""Analytic SNR versus photon flux of the three sensors (the reference paper's Section 3, Fig. "SNR").

The common abscissa is the photon irradiance at the sensor plane Φ (photons s⁻¹ m⁻²); each sensor turns it into
its own per-pixel rate with its pitch, fill factor and quantum efficiency (``simspad.sensors.presets``), exactly as
the simulator does (docs/sensors.md): a pixel detects λ = Φ·pitch²·fill_factor·qe. The top axis gives the scene
illuminance of a middle-grey scene at f/2 (docs/sensors.md lux convention, ``simspad.physics.radiometry.flux_scale``). All
sensors observe one exposure window T (default 10 ms, the frame camera's ``max_exposure_s``).

Conventional camera (EMVA 1288 Release 4.0, §2 linear model; Ingle et al. 2019 suppl. note 7)::

    μ_e = η·Φ_pix·T            (η = qe·fill_factor, Φ_pix = Φ·pitch²)
    σ²  = μ_e + σ_r² + i_d·T + 1/(12·K²)        (shot, read noise, dark-current shot noise, ADC quantisation:
                                                  one DN = 1/K electrons)
    SNR = 10·log10(μ_e² / σ²)  while μ_e + i_d·T < full well,  −∞ (undefined) beyond.

Free-running SPAD (Ingle, Velten, Gupta, CVPR 2019 "High flux passive imaging with single-photon sensors",
supplementary note 7; estimator Φ̂ = N / (q·(T − N·τ_d)))::

    SNR = −10·log10( B_rel² + (1 + qΦτ_d)/(qΦT) + (1 + qΦτ_d)⁴/(12·q²Φ²T²) )

with q = qe·fill_factor, Φ = Φ_pix, τ_d the dead time; the second term is the shot noise of the dead-time
corrected count (Var N = qΦT/(1+qΦτ_d)³), the third the quantisation of the integer count propagated through
the estimator. The bias B_rel is re-derived here: dark counts are not subtracted (r_d/(qΦ)), and a detection
causes an afterpulse with probability p_ap, released shortly after the dead time, which a true photon detection
pre-empts with probability 1 − e^{−qΦτ_d}: B_rel = r_d/(qΦ) + p_ap/(1 − p_ap)·e^{−qΦτ_d} (Ingle et al.'s public
code uses a bias of the same structure, r_d/Φ + q·(1+Φτ_d)·p_ap·e^{−qΦτ_d}, with q = 0.4, τ_d = 149.7 ns,
100 cps, 1 %; here the SwissSPAD2 preset values are used).

Gated binary SPAD, as simulated (docs/sensors.md): n = T/bin_s bins with gate τ_g (bin_s, or "auto": the variance-
optimal x_s = 1.594 clipped to [min_gate_s, bin_s], an ideal exposure control), x = (qΦ + r_d)·τ_g,
ML estimator with the dark rate subtracted; its relative variance (delta method, = Var ln Φ̂) and the bias of
afterpulsing and 4-neighbour crosstalk (which raise P(1) = p = 1 − e^{−x} by ≈ (p_ap + 4p_ct)·p·(1 − p), a
relative rate bias of (p_ap + 4p_ct)·p/x_s with x_s = qΦτ_g)::

    SNR = −10·log10( (e^{x} − 1)/(n·x_s²) + ((p_ap + 4·p_ct)·p/x_s)² )

Events (the paper's Eq. SNR_events = 10·log10( P_e·(ΔΦ/C) / N(Φ) ); the paper measures P_e and N empirically; here
they follow from the event-sensor model of the simulator, with the preset's parameters):

- photocurrent λ_e = η_ev·Φ_pix + i_dark (electrons s⁻¹); photoreceptor cutoff f_c = f_max·λ_e/(λ_e + λ_ref);
- log-intensity noise of the photoreceptor: shot noise (one-sided relative PSD 2/λ_e) through a first-order
  low-pass (equivalent noise bandwidth π·f_c/2): σ_log² = π·f_c/λ_e;
- a step of contrast c (ΔΦ/Φ = 0.3 or 1.0) is a log step Δ = ln(1 + c); within the window the photoreceptor
  reaches Δ_eff = Δ·(1 − e^{−2π f_c T});
- trigger probability P_e = Φ_N( (Δ_eff − C) / sqrt(σ_θ² + 2σ_log²) ) with C the nominal contrast threshold and
  σ_θ the threshold mismatch (noise on the reference and on the new level: 2σ_log²);
- signal = P_e·Δ_eff/C expected signal events; noise N = T·(r_shot + r_leak) expected noise events in the window,
  r_shot = r_1lx·sqrt(λ_1lx/λ_e) (the simulator's shot-noise event rate, Graça & Delbruck 2021 trend),
  r_leak the leak-event rate.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.special import ndtr

from simspad.io.atomic import atomic_path
from simspad.physics.photoreceptor import cutoff_hz
from simspad.physics.radiometry import detection_rate, flux_scale
from simspad.sensors.presets import EventParams, FrameParams, SpadParams, sensor_params

DEFAULT_EXPOSURE_S = 10e-3
#: x = qΦτ_g minimising the gated estimator's relative variance (eˣ − 1)/x² (root of x·eˣ = 2(eˣ − 1)).
OPTIMAL_GATED_X = 1.5936242600400401
CONTRASTS = (0.3, 1.0)


def _db(ratio) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return 10.0 * np.log10(ratio)


def _detections_per_s(flux_ph_s_m2, params) -> np.ndarray:
    """η·Φ_pix = q·Φ: detections (photo-electrons) s⁻¹ of one pixel, with the simulator's detection area."""
    return detection_rate(np.asarray(flux_ph_s_m2, np.float64), params.pixel_pitch_m, params.fill_factor, params.qe)


def snr_frame_db(flux_ph_s_m2, params: FrameParams | None = None, exposure_s: float = DEFAULT_EXPOSURE_S):
    """SNR (dB) of the conventional camera (EMVA 1288); −inf at and beyond full well."""
    p = params or sensor_params("frames")
    mu_e = _detections_per_s(flux_ph_s_m2, p) * exposure_s
    dark_e = p.dark_current_e_s * exposure_s
    var = mu_e + p.read_noise_e ** 2 + dark_e + 1.0 / (12.0 * p.gain_dn_per_e ** 2)
    snr = _db(mu_e ** 2 / var)
    return np.where(mu_e + dark_e < p.full_well_e, snr, -np.inf)


def snr_spad_free_running_db(flux_ph_s_m2, params: SpadParams | None = None,
                             exposure_s: float = DEFAULT_EXPOSURE_S):
    """SNR (dB) of a free-running SPAD pixel with dead time (Ingle et al. 2019, suppl. note 7; bias re-derived)."""
    p = params or sensor_params("spad")
    q_phi = _detections_per_s(flux_ph_s_m2, p)
    tau = p.dead_time_s
    ap = p.afterpulsing_probability
    with np.errstate(divide="ignore", invalid="ignore"):
        bias = p.dcr_median_cps / q_phi + ap / (1.0 - ap) * np.exp(-q_phi * tau)
        shot = (1.0 + q_phi * tau) / (q_phi * exposure_s)
        quant = (1.0 + q_phi * tau) ** 4 / (12.0 * q_phi ** 2 * exposure_s ** 2)
    return -_db(bias ** 2 + shot + quant)


def snr_spad_gated_db(flux_ph_s_m2, params: SpadParams | None = None, exposure_s: float = DEFAULT_EXPOSURE_S,
                      gate_s: float | None = None):
    """SNR (dB) of the gated binary SPAD of docs/sensors.md (n = T/bin_s bins, ML estimator, dark rate subtracted).

    ``gate_s``: seconds, None for the whole bin, or ``"auto"``: the gate that minimises the variance,
    x = qΦτ_g = OPTIMAL_GATED_X, clipped to [min_gate_s, bin_s] (an ideal per-flux exposure control).
    """
    p = params or sensor_params("spad")
    n = exposure_s / p.bin_s
    rate = _detections_per_s(flux_ph_s_m2, p)
    if gate_s == "auto":
        with np.errstate(divide="ignore"):
            gate = np.clip(OPTIMAL_GATED_X / rate, p.min_gate_s, p.bin_s)
    else:
        gate = float(p.bin_s if gate_s is None else gate_s)
    xs = rate * gate
    x = xs + p.dcr_median_cps * gate
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        var = np.expm1(x) / (n * xs ** 2)
        bias = (p.afterpulsing_probability + 4 * p.crosstalk_probability) * (-np.expm1(-x)) / xs
    return -_db(var + bias ** 2)


def reference_flux_1lx() -> float:
    """Sensor-plane photon irradiance of a middle-grey scene at 1 lx (docs/sensors.md defaults), ph s⁻¹ m⁻²."""
    return float(flux_scale(1.0, 1.0))


def snr_events_db(flux_ph_s_m2, contrast: float, params: EventParams | None = None,
                  window_s: float = DEFAULT_EXPOSURE_S, flux_1lx: float | None = None):
    """SNR (dB) of the event camera for a step of relative contrast ``contrast`` (ΔΦ/Φ) within ``window_s``."""
    p = params or sensor_params("events")
    lam = _detections_per_s(flux_ph_s_m2, p) + p.dark_current_e_s
    f_c = cutoff_hz(lam, p.photoreceptor_cutoff_hz_max, p.photoreceptor_cutoff_ref_rate_e_s)
    var_log = np.pi * f_c / lam
    delta = math.log1p(contrast) * (1.0 - np.exp(-2 * np.pi * f_c * window_s))
    threshold = 0.5 * (p.threshold_on + p.threshold_off)
    p_e = ndtr((delta - threshold) / np.sqrt(p.threshold_sigma ** 2 + 2 * var_log))
    signal = p_e * delta / threshold
    flux_1lx = reference_flux_1lx() if flux_1lx is None else flux_1lx
    lam_1lx = _detections_per_s(flux_1lx, p) + p.dark_current_e_s
    noise = window_s * (p.shot_noise_rate_hz_at_1lux * np.sqrt(lam_1lx / lam) + p.leak_rate_hz)
    return _db(signal / noise)


def snr_curves(flux_ph_s_m2, exposure_s: float = DEFAULT_EXPOSURE_S) -> dict[str, np.ndarray]:
    """All curves of the SNR figure, keyed by their legend labels."""
    flux = np.asarray(flux_ph_s_m2, np.float64)
    f1 = reference_flux_1lx()
    curves = {
        "frame camera (Blackfly S, EMVA 1288)": snr_frame_db(flux, exposure_s=exposure_s),
        "SPAD free-running (Ingle et al. 2019)": snr_spad_free_running_db(flux, exposure_s=exposure_s),
        "SPAD gated 1-bit (SwissSPAD2, gate = bin)": snr_spad_gated_db(flux, exposure_s=exposure_s),
        "SPAD gated 1-bit (SwissSPAD2, auto gate)": snr_spad_gated_db(flux, exposure_s=exposure_s, gate_s="auto"),
    }
    for c in CONTRASTS:
        curves[f"events, {c:.0%} contrast change"] = snr_events_db(flux, c, window_s=exposure_s, flux_1lx=f1)
    return curves


def plot_snr(out_path: Path, exposure_s: float = DEFAULT_EXPOSURE_S) -> Path:
    """Draw the SNR-versus-flux figure to ``out_path`` (PNG), written atomically."""
    import matplotlib  # deferred: matplotlib is slow to import and only this figure needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after choosing the non-interactive backend

    f1 = reference_flux_1lx()
    flux = np.geomspace(1e-3 * f1, 1e6 * f1, 400)
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    styles = ["-", "-", "--", "-", ":", "-."]
    for (label, snr), ls in zip(snr_curves(flux, exposure_s).items(), styles):
        ax.plot(flux, np.where(np.isfinite(snr), snr, np.nan), ls, lw=2, label=label)
    ax.set_xscale("log")
    ax.set_ylim(-20, 60)
    ax.set_xlabel("photon irradiance at the sensor (photons s$^{-1}$ m$^{-2}$)")
    ax.set_ylabel("SNR (dB)")
    ax.set_title(f"Analytic SNR, exposure window {exposure_s * 1e3:g} ms")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    top = ax.secondary_xaxis("top", functions=(lambda x: x / f1, lambda lx: lx * f1))
    top.set_xlabel("scene illuminance of a middle-grey scene at f/2 (lx)")
    out_path = Path(out_path)
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    return out_path


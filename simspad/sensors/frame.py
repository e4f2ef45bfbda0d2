"""Conventional frame camera (DESIGN §4, preset ``blackfly_s``): the EMVA 1288 linear camera model.

Chain, per pixel and frame (after the EMVA 1288 reference code ``emva1288/camera/camera.py``)::

    photons  = ∫ Φ(t) dt over the pixel's exposure window · pitch² · fill_factor      (motion blur)
    e⁻       = Poisson(η · photons · PRNU map) + Poisson(dark_current · t_exp) + DSNU map
    e⁻       = min(e⁻, full_well)
    e⁻      += N(0, read_noise²)
    DN       = clip(round(K · e⁻ + black_level), 0, 2^bits − 1)            uint16

The fixed-pattern maps (PRNU: relative gain ``1 + prnu·z``; DSNU: ``dsnu_e·z`` electrons, z standard normal)
are drawn once per recording from the sensor's random stream, before any frame (:func:`draw_fixed_pattern`).

Exposure windows: frame ``k`` starts at ``t0 + k / frame_rate_hz``. With a rolling shutter row ``r`` starts
``r · rolling_shutter_line_s`` later than row 0; ``/frames/t_start`` and ``/frames/t_end`` hold row 0's window.
The integral over each window is exact for the piecewise-linear timeline.

RGB (``rgb = true``): an RGGB Bayer mosaic. The timeline's linear sRGB keyframes (× its flux scale, so that a
grey surface gives every channel the luminance flux) feed each pixel's own channel; the colour filters'
transmission is folded into ``qe``. A luminance-only render feeds the same flux to every channel (recorded as
``rgb_source = "luminance"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simspad.errors import SimSpadError
from simspad.sensors.presets import FrameParams, params_to_attrs

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
    return np.asarray(fluence_ph_m2, dtype=np.float64) * (params.pixel_pitch_m ** 2 * params.fill_factor)


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
    """The exposure in seconds: the fixed value (validated against the frame period) or :func:`auto_exposure`."""
    period_s = 1.0 / params.frame_rate_hz
    if params.exposure_s == "auto":
        return auto_exposure(first_flux_ph_s_m2, params)
    exposure_s = float(params.exposure_s)
    if not exposure_s > 0:
        raise SimSpadError(f"must be > 0 s or 'auto', got {exposure_s!r}", field=f"{_FIELD}.exposure_s")
    if exposure_s > period_s * (1 + 1e-9):
        raise SimSpadError(f"{exposure_s!r} s is longer than the frame period 1/frame_rate_hz = {period_s!r} s",
                           field=f"{_FIELD}.exposure_s")
    return exposure_s


def validate_params(params: FrameParams, height: int) -> None:
    """Raise :class:`SimSpadError` naming the field for values the model cannot use."""
    checks = [
        ("frame_rate_hz", params.frame_rate_hz > 0, "must be > 0"),
        ("max_exposure_s", params.max_exposure_s > 0, "must be > 0"),
        ("bit_depth", 1 <= params.bit_depth <= 16, "must be between 1 and 16 (uint16 output)"),
        ("gain_dn_per_e", params.gain_dn_per_e > 0, "must be > 0"),
        ("full_well_e", params.full_well_e > 0, "must be > 0"),
        ("qe", 0 < params.qe <= 1, "must be in (0, 1]"),
        ("fill_factor", 0 < params.fill_factor <= 1, "must be in (0, 1]"),
        ("pixel_pitch_m", params.pixel_pitch_m > 0, "must be > 0"),
        ("auto_max_fill", 0 < params.auto_max_fill <= 1, "must be in (0, 1]"),
    ]
    for name, ok, message in checks:
        if not ok:
            raise SimSpadError(f"{message}, got {getattr(params, name)!r}", field=f"{_FIELD}.{name}")
    if params.exposure_s != "auto":
        resolve_exposure(params, np.zeros((1, 1)))  # a fixed exposure must be > 0 and fit in the frame period
    readout_s = (height - 1) * params.rolling_shutter_line_s
    if readout_s >= 1.0 / params.frame_rate_hz:
        raise SimSpadError(f"rolling-shutter readout {readout_s!r} s ({height} rows) exceeds the frame period",
                           field=f"{_FIELD}.rolling_shutter_line_s")


def frame_windows(t0: float, t1: float, frame_rate_hz: float, exposure_s: float,
                  readout_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Row 0's exposure windows of every frame that fits (with its readout skew) inside [t0, t1].

    Returns
    -------
    t_start, t_end : ndarray [K] float64
        Seconds; frame ``k`` starts at ``t0 + k / frame_rate_hz``.
    """
    span = (t1 - t0) - exposure_s - readout_s
    n = int(math.floor(span * frame_rate_hz + 1e-9)) + 1 if span >= -1e-12 else 0
    t_start = t0 + np.arange(n, dtype=np.float64) / frame_rate_hz
    return t_start, t_start + exposure_s


# ----------------------------------------------------------------------------------------------- exposure integral
def bayer_channel_map(height: int, width: int, pattern: np.ndarray = BAYER_RGGB) -> np.ndarray:
    """Channel index (0 R, 1 G, 2 B) of every pixel of a Bayer mosaic, [H, W] intp."""
    rows = np.arange(height)[:, None] % 2
    cols = np.arange(width)[None, :] % 2
    return pattern[rows, cols]


def _keyframe_source(flux_tl, rgb: bool):
    """A function ``i -> [H, W]`` giving keyframe ``i``'s flux (the mosaic channel per pixel when ``rgb``)."""
    if not rgb:
        return flux_tl.keyframe
    channels = bayer_channel_map(flux_tl.height, flux_tl.width)[..., None]

    def mosaic(i: int) -> np.ndarray:
        return np.take_along_axis(flux_tl.rgb_keyframe(i), channels, axis=2)[..., 0]

    return mosaic


def window_fluence(flux_tl, row_start_s: np.ndarray, exposure_s: float, source=None) -> np.ndarray:
    """Exact ∫Φ dt over each row's window ``[row_start_s[r], row_start_s[r] + exposure_s]``.

    The timeline is linear between keyframes, so each piece contributes ``a_r·Y_i + b_r·Y_{i+1}`` with
    weights from the overlap of the row's window and the piece.

    Parameters
    ----------
    flux_tl : Timeline
        Photon irradiance, photons s⁻¹ m⁻².
    row_start_s : ndarray [H]
        Start of each row's exposure, s.
    exposure_s : float
    source : callable, optional
        ``i -> [H, W]`` keyframe values (default ``flux_tl.keyframe``).

    Returns
    -------
    ndarray [H, W] float64
        Fluence, photons m⁻².
    """
    source = source or flux_tl.keyframe
    times = flux_tl.times_s
    row_start = np.asarray(row_start_s, dtype=np.float64)
    row_end = row_start + exposure_s
    if times.size == 1:
        return source(0).astype(np.float64) * exposure_s
    lo, hi = float(row_start.min()), float(row_end.max())
    i0 = max(0, int(np.searchsorted(times, lo, side="right")) - 1)
    i1 = min(times.size - 1, int(np.searchsorted(times, hi, side="left")))
    out = np.zeros((flux_tl.height, flux_tl.width), dtype=np.float64)
    for i in range(i0, max(i1, i0 + 1)):
        ta, tb = times[i], times[i + 1]
        u0 = np.clip(row_start, ta, tb)
        u1 = np.clip(row_end, ta, tb)
        if not np.any(u1 > u0):
            continue
        duration = tb - ta
        w_b = ((u1 - ta) ** 2 - (u0 - ta) ** 2) / (2.0 * duration)
        w_a = (u1 - u0) - w_b
        out += w_a[:, None] * source(i) + w_b[:, None] * source(i + 1)
    return out


# ----------------------------------------------------------------------------------------------- recording
def simulate_frames(writer, flux_tl, t0: float, t1: float, params: FrameParams, rng: np.random.Generator,
                    progress: bool = False) -> dict:
    """Simulate the frame camera over [t0, t1] and write ``/frames`` (DESIGN §5).

    Parameters
    ----------
    writer : RecordingWriter
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Recording interval, s (timeline time base).
    params : FrameParams
    rng : numpy.random.Generator
        The sensor's own stream; the fixed pattern is drawn first, then frames in order.

    Notes
    -----
    ``exposure_s = "auto"`` is resolved from the flux at ``t0`` (the first keyframe unless the recording starts
    later) and recorded in the attrs with ``exposure_mode``.
    progress : bool
        Show a progress bar.

    Returns
    -------
    dict
        The attrs written on ``/frames`` (exposure resolved).
    """
    height, width = flux_tl.height, flux_tl.width
    validate_params(params, height)
    source = _keyframe_source(flux_tl, bool(params.rgb))
    first_flux = _sample(flux_tl, t0, source)
    exposure_s = resolve_exposure(params, first_flux)
    readout_s = (height - 1) * params.rolling_shutter_line_s
    t_start, t_end = frame_windows(t0, t1, params.frame_rate_hz, exposure_s, readout_s)
    pattern = draw_fixed_pattern(params, (height, width), rng)

    attrs = params_to_attrs(params)
    has_rgb = bool(params.rgb) and _has_rgb(flux_tl)
    attrs.update(
        exposure_s=exposure_s, exposure_mode="auto" if params.exposure_s == "auto" else "fixed",
        pixel_area_m2=params.pixel_pitch_m ** 2, frame_period_s=1.0 / params.frame_rate_hz,
        n_frames=int(t_start.size), dn_max=dn_max(params), readout_s=readout_s,
        shutter="rolling" if params.rolling_shutter_line_s > 0 else "global",
        bayer_pattern="RGGB" if params.rgb else "none",
        rgb_source=("rgb" if has_rgb else "luminance") if params.rgb else "none",
        time_origin_s=0.0, t_start_s=float(t0), t_end_s=float(t1),
        window_note="t_start/t_end are row 0's window; row r is shifted by r·rolling_shutter_line_s",
        model="EMVA 1288: e=Poisson(qe*photons*PRNU)+Poisson(dark*t)+DSNU; min(e, full_well); +N(0,read^2); "
              "DN=clip(round(K*e+black),0,2^bits-1)")
    dn = writer.append_dataset("frames/dn", (height, width), np.uint16, chunk_rows=1)
    row_offset_s = np.arange(height, dtype=np.float64) * params.rolling_shutter_line_s
    frames = range(t_start.size)
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc="frames", unit="frame")
    for k in frames:
        fluence = window_fluence(flux_tl, t_start[k] + row_offset_s, exposure_s, source)
        dn.append(expose(photons_per_pixel(fluence, params), exposure_s, pattern, params, rng)[None])
    writer.write_dataset("frames/t_start", t_start)
    writer.write_dataset("frames/t_end", t_end)
    writer.set_attrs("frames", **attrs)
    return attrs


def _has_rgb(flux_tl) -> bool:
    """Whether the timeline carries colour (a luminance-only render repeats Y in R, G and B)."""
    rgb = flux_tl.rgb_keyframe(0)
    return not (np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 1], rgb[..., 2]))


def _sample(flux_tl, t: float, source) -> np.ndarray:
    """The (mosaic) flux at instant ``t``, from keyframes through ``source``."""
    i, w = flux_tl.locate(t)
    value = source(i).astype(np.float64)
    if w > 0:
        value = (1.0 - w) * value + w * source(i + 1)
    return value

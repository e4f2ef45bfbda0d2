"""Frame camera simulation: exposure windows, the exact exposure integral, and the ``/frames`` writer (docs/format.md).

Exposure windows: frame ``k`` starts at ``t0 + k / frame_rate_hz``. With a rolling shutter row ``r`` starts
``r · rolling_shutter_line_s`` later than row 0; ``/frames/t_start`` and ``/frames/t_end`` hold row 0's window.
The integral over each window is exact for the piecewise-linear timeline.

RGB (``rgb = true``): an RGGB Bayer mosaic. The timeline's linear sRGB keyframes (× its flux scale, so that a
grey surface gives every channel the luminance flux) feed each pixel's own channel; the colour filters'
transmission is folded into ``qe``. A luminance-only render feeds the same flux to every channel (recorded as
``rgb_source = "luminance"``).

The per-frame camera model (EMVA 1288 chain, fixed pattern, exposure control) is in
:mod:`simspad.sensors.frames.model`.
"""

from __future__ import annotations

import math

import numpy as np
from tqdm import tqdm

from simspad.sensors.frames.model import (
    bayer_channel_map,
    dn_max,
    draw_fixed_pattern,
    expose,
    photons_per_pixel,
    resolve_exposure,
)
from simspad.sensors.presets import FrameParams, params_to_attrs


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


def simulate_frames(writer, flux_tl, t0: float, t1: float, params: FrameParams, rng: np.random.Generator,
                    progress: bool = False) -> dict:
    """Simulate the frame camera over [t0, t1] and write ``/frames`` (docs/format.md).

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
    progress : bool
        Show a progress bar.

    Returns
    -------
    dict
        The attrs written on ``/frames`` (exposure resolved).

    Notes
    -----
    ``exposure_s = "auto"`` is resolved from the flux at ``t0`` (the first keyframe unless the recording starts
    later) and recorded in the attrs with ``exposure_mode``.
    """
    height, width = flux_tl.height, flux_tl.width
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

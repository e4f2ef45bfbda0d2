"""EDI (F+E): event double integral deblurring of conventional frames (Pan et al., CVPR 2019; docs/methods.md).

A frame exposed over [t_s, t_e] records B = (1/T)∫Φ(t)dt (in irradiance units after the EMVA inversion of
:class:`simspad.methods.spad_response.FrameResponse`). With Φ(t) = Φ(f)·exp(ℓ(t) − ℓ(f)) from events,
``Φ(f) = B / ((1/T)∫exp(ℓ(t) − ℓ(f))dt)``. The contrast threshold c is fixed at the sensor's nominal one (the
recording attrs), not searched: docs/methods.md fixes c to the nominal threshold for every method.

Each output instant takes the frame whose exposure centre is nearest (windows split at mid-points between
centres) and is propagated from f by events. Var(ln Φ̂) is the EMVA shot + read + quantisation noise.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np
from scipy import ndimage

from simspad.errors import InputError
from simspad.methods.event_batches import (
    EventCursor,
    PixelEvents,
    group_by_pixel,
    mean_exp_level,
)
from simspad.methods.method import BandwidthTally, Method
from simspad.methods.spad_response import FrameResponse
from simspad.methods.windows import Measurement, open_loop_frames


def edi_deblur(flux_blur: np.ndarray, events, t0_s: float, t1_s: float, t_ref_s: float):
    """Latent Φ(f) from a blurred irradiance image and the events of its window.

    Returns ``(flux_ref [H,W], level_ref [H,W])``; ℓ is counted from the start of ``events``' window.
    """
    shape = flux_blur.shape
    n_pix = flux_blur.size
    mean = np.empty(n_pix)
    lref = np.empty(n_pix)
    order, offsets = group_by_pixel(events.pix, n_pix)
    mean_exp_level(PixelEvents(order, offsets, events.t_s, events.dl), float(t0_s), float(t1_s), float(t_ref_s),
                   mean, lref)
    return (flux_blur.reshape(-1) / mean).reshape(shape), lref.reshape(shape)


def frame_measurements(rec, *, use_events: bool, until_s: float, tally: BandwidthTally) -> Iterator[Measurement]:
    """Conventional frames in order, EDI-deblurred (or plainly inverted without events).

    Frame k's window runs between the mid-points of neighbouring exposure centres (the first from its exposure
    start, the last to ``until_s``); ``duration_s`` is the frame period.
    """
    resp = FrameResponse.from_recording(rec)
    ts = np.asarray(rec.frames.t_start, dtype=np.float64)
    te = np.asarray(rec.frames.t_end, dtype=np.float64)
    K = ts.size
    if K == 0:
        raise InputError("recording holds no frames", path=rec.path, field="/frames/dn")
    centres = 0.5 * (ts + te)
    bounds = np.concatenate([[ts[0]], 0.5 * (centres[1:] + centres[:-1]), [max(te[-1], until_s)]])
    periods = np.diff(centres) if K > 1 else np.array([te[0] - ts[0]])
    cursor = EventCursor(rec) if use_events else None
    n_pix = int(rec.width) * int(rec.height)
    bayer = bool(rec.frames.attrs.get("rgb", False)) and str(rec.frames.attrs.get("rgb")).lower() not in ("false", "0")
    for k in range(K):
        a, b = bounds[k], bounds[k + 1]
        exposure = te[k] - ts[k]
        dn = rec.frames.dn(k)
        if dn.ndim != 2:
            raise InputError("frames must be monochrome [H, W] for the frame methods", path=rec.path,
                             field="/frames/dn")
        if bayer:
            # RGGB mosaic: a 2×2 box over (DN − black) gives (R + 2G + B)/4 at every pixel, a luminance proxy
            # (the per-channel QE is not in the attrs); documented approximation.
            dn = resp.black_level_dn + ndimage.uniform_filter(dn.astype(np.float64) - resp.black_level_dn, 2,
                                                              mode="nearest")
        blur = resp.flux(dn, exposure)
        if cursor is not None:
            events = cursor.take(a, b)
            flux, lref = edi_deblur(blur, events, max(ts[k], a), min(te[k], b), centres[k])
            tally.add(len(events) / n_pix, 32.0 * len(events) / n_pix)
        else:
            events, flux, lref = None, blur, np.zeros_like(blur)
        tally.cover(a, min(b, max(te[-1], until_s)))
        period = periods[min(k, periods.size - 1)]
        sat = resp.saturated(dn).reshape(-1)

        def var_model(flux, exposure=exposure, sat=sat):
            return resp.log_variance_at_flux(flux, exposure, sat)

        yield Measurement(a, b, centres[k], flux.reshape(-1), resp.floor_flux(exposure),
                          resp.log_variance(dn).reshape(-1), lref.reshape(-1), events, float(resp.bit_depth),
                          float(period), var_model)


class EDI(Method):
    """EDI (F+E): each frame deblurred with events at the nominal threshold, propagated to the instants."""

    name = "edi"
    label = "EDI (F+E)"
    full_name = "Event double integral: conventional frames deblurred by events"
    citation = "Pan et al., CVPR 2019"
    sensors = "F+E"
    requires = ("frames", "events")
    absolute_scale = True

    def _run(self, rec, times_s, tally):
        until = float(times_s[-1]) + 1e-9 if times_s.size else 0.0
        meas = frame_measurements(rec, use_events=True, until_s=until, tally=tally)
        yield from open_loop_frames(meas, times_s, (int(rec.height), int(rec.width)), tally)

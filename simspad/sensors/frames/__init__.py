"""Conventional frame camera (docs/sensors.md, preset ``blackfly_s``): the EMVA 1288 linear camera model.

- :mod:`~simspad.sensors.frames.model`: the per-frame camera model (fixed pattern, EMVA chain, exposure control,
  Bayer mosaic);
- :mod:`~simspad.sensors.frames.simulator`: exposure windows, the exact exposure integral and the ``/frames``
  writer.
"""

from simspad.sensors.frames.model import (
    BAYER_RGGB,
    FixedPattern,
    auto_exposure,
    bayer_channel_map,
    dn_max,
    draw_fixed_pattern,
    expose,
    photons_per_pixel,
    resolve_exposure,
    validate_params,
)
from simspad.sensors.frames.simulator import frame_windows, simulate_frames, window_fluence

__all__ = ["BAYER_RGGB", "FixedPattern", "auto_exposure", "bayer_channel_map", "dn_max", "draw_fixed_pattern",
           "expose", "frame_windows", "photons_per_pixel", "resolve_exposure", "simulate_frames", "validate_params",
           "window_fluence"]

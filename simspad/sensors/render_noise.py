"""A recording's render-noise budget: the render's figures (``timeline.json``'s ``render_noise``), and the
spurious-event fraction at the recording's own lux level and event-sensor thresholds.

The render states its noise in bright light (the log of luminance). What an event pixel sees is the log of its
photocurrent, dark current included, so in dim light the same relative noise moves it less: the recording
recomputes the fraction from the render's keyframe 0 and its noise probe scaled to this recording's photon flux,
with the photocurrent and nominal thresholds of its event sensor (the default event sensor where the recording has
none), noise-free and settled (:mod:`simspad.radiance.noise_budget` says what the figure means).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.exr import read_exr
from simspad.io.render_dir import TIMELINE_FILE
from simspad.physics.photoreceptor import MIN_CURRENT_E_S
from simspad.physics.radiometry import luminance_from_planes
from simspad.radiance.noise_budget import spurious_event_fraction
from simspad.sensors.events.model import sensor_photocurrent_e_s
from simspad.sensors.presets import EventParams


def render_noise_attrs(flux_tl, render_dir, event_params: EventParams | None) -> dict:
    """Root attributes of a recording that state its render-noise budget (docs/format.md section 3).

    Parameters
    ----------
    flux_tl : Timeline
        The render's timeline scaled to this recording's photon flux (photons s⁻¹ m⁻²).
    render_dir : str or Path
        The render directory (holds the noise probe named in ``timeline.json``).
    event_params : EventParams or None
        The recording's event sensor; None: the default one.

    Returns
    -------
    dict
        ``render_noise`` (JSON str: the render's figures plus this recording's), ``render_noise_relative`` and
        ``render_noise_spurious_event_fraction`` (float64; NaN when the render has no noise probe).
    """
    budget = flux_tl.meta.get("render_noise")
    if budget is None:  # a render from before every render had a noise probe, or another renderer's
        return {"render_noise": json.dumps(None), "render_noise_relative": math.nan,
                "render_noise_spurious_event_fraction": math.nan}
    timeline = Path(render_dir) / TIMELINE_FILE
    probe = budget.get("probe_file") if isinstance(budget, dict) else None
    if not isinstance(probe, str):
        raise InputError("must be an object with a probe_file (a noise-probe EXR in the render directory)",
                         path=timeline, field="render_noise")
    root = Path(render_dir).resolve()
    probe_path = (root / probe).resolve()
    if not probe_path.is_relative_to(root):
        raise InputError(f"{probe!r} is outside the render directory", path=timeline,
                         field="render_noise.probe_file")
    params = event_params if event_params is not None else EventParams()
    flux0 = flux_tl.keyframe(0)
    planes = read_exr(probe_path, rgb_planes=True)
    if "r" not in planes or planes["r"].shape != flux0.shape:
        raise InputError(f"the noise probe must be an RGB image of the keyframes' size {flux0.shape[1]}×"
                         f"{flux0.shape[0]}", path=probe_path, field="render_noise.probe_file")
    flux1 = luminance_from_planes(planes["r"], planes["g"], planes["b"]) * np.float32(flux_tl.scale)
    current0 = np.maximum(sensor_photocurrent_e_s(flux0, params), MIN_CURRENT_E_S)
    current1 = np.maximum(sensor_photocurrent_e_s(flux1, params), MIN_CURRENT_E_S)
    fraction = spurious_event_fraction(current0, current1, params.threshold_on, params.threshold_off)
    doc = dict(budget, recording={
        "spurious_event_fraction": fraction, "event_sensor": "recording" if event_params is not None else "default",
        "threshold_on": float(params.threshold_on), "threshold_off": float(params.threshold_off),
        "dark_current_e_s": float(params.dark_current_e_s)})
    return {"render_noise": json.dumps(doc, sort_keys=True),
            "render_noise_relative": float(budget.get("relative_noise_median", math.nan)),
            "render_noise_spurious_event_fraction": fraction}

"""What one recording simulates (:class:`RecordingSettings`), and the one check of a light level (:func:`lux_problem`).

The record checks its light level, seed, duration and ground-truth rate when it is built, so :func:`simspad.sensors.simulate.simulate_recording` and
the dataset pipeline that builds one per recording (:mod:`simspad.dataset.plan`) trust it; a dataset spec's
``lux`` and ``simspad simulate --lux`` are checked by :func:`lux_problem` too, so every lux level meets one rule
with one message, whichever way it came in.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.physics.radiometry import Optics


def lux_problem(lux) -> str | None:
    """What is wrong with a scene illuminance, or None.

    Parameters
    ----------
    lux : object
        Illuminance, lx: a finite number inside :data:`simspad.defaults.LUX_RANGE` (outside it the images are NaN
        or all zero).
    """
    if not isinstance(lux, numbers.Real) or isinstance(lux, bool):
        kind = {bool: "boolean", str: "string"}.get(type(lux), type(lux).__name__)
        return f"got {kind} {lux!r} (expected an illuminance in lux > 0)"
    if not (math.isfinite(lux) and lux > 0):
        return f"must be a finite number > 0, got {lux!r} (expected an illuminance in lux > 0)"
    lo, hi = defaults.LUX_RANGE
    if not lo <= lux <= hi:
        return (f"{lux:g} lx is outside {lo:g}–{hi:g} lx (starlight is ~1e-3 lx, direct sunlight ~1e5 lx): such a "
                "level gives NaN or all-zero images")
    return None


@dataclass(frozen=True)
class RecordingSettings:
    """What one recording simulates: light level, sensors, interval, random stream, ground truth and optics.

    Attributes
    ----------
    lux : float
        Scene illuminance, lx, checked on construction (:func:`lux_problem`; SimSpadError naming ``lux``).
    sensors : dict
        ``{kind: params}`` with kind a row of the sensor table (``"spad"``, ``"frames"``, ``"events"``, …) and
        the parameter dataclass of :func:`simspad.sensors.presets.sensor_params`.
    start_s, duration_s : float, optional
        Interval to simulate, s; default from the first to the last keyframe. A duration is checked on
        construction (:func:`simspad.defaults.duration_problem`); both against the render's span by the
        simulation, which has the render.
    seed : int or SeedSequence
        Dataset seed; each sensor draws from ``child_rng(seed, *stream_key, kind)``. An integer is checked on
        construction (:func:`simspad.defaults.seed_problem`).
    stream_key : tuple
        Stable key of this recording (e.g. ``(sequence, lux)``).
    gt_rate_hz : float
        Ground-truth frame rate, Hz, checked on construction (:func:`simspad.defaults.gt_rate_problem`).
    optics : Optics, optional
        Lens and illuminant (None: ``Optics()``, filled in on construction).
    """

    lux: float
    sensors: dict
    start_s: float | None = None
    duration_s: float | None = None
    seed: int | np.random.SeedSequence = 0
    stream_key: tuple = ()
    gt_rate_hz: float = defaults.GT_RATE_HZ
    optics: Optics | None = None

    def __post_init__(self):
        problem = lux_problem(self.lux)
        if problem:
            raise SimSpadError(problem, field="lux")
        if not isinstance(self.seed, np.random.SeedSequence) and (problem := defaults.seed_problem(self.seed)):
            raise SimSpadError(problem, field="seed")
        if problem := defaults.gt_rate_problem(self.gt_rate_hz):
            raise SimSpadError(problem, field="gt_rate_hz")
        if self.duration_s is not None and (problem := defaults.duration_problem(self.duration_s)):
            raise SimSpadError(problem, field="duration_s")
        if self.optics is None:
            object.__setattr__(self, "optics", Optics())

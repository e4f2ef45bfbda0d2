"""Simulate sensors on a render directory and write one recording (docs/internals.md, docs/format.md, README.md ``simspad simulate``).

Flow: open the render directory as a :class:`~simspad.radiance.timeline.Timeline`; scale it to sensor-plane photon
irradiance so that the first keyframe's mean luminance corresponds to the lux level (docs/sensors.md); run each
requested sensor on ``[start_s, start_s + duration_s]``, in the order of the sensor table
(:mod:`simspad.sensors.registry`, whose rows give each kind's checks and simulator), with its own random stream
``child_rng(seed, *stream_key, kind)``; write the ground truth; all inside one
:class:`~simspad.io.recording.RecordingWriter`, so a failure anywhere leaves no file behind. What to simulate comes
as one :class:`~simspad.sensors.recording_settings.RecordingSettings` (re-exported here), whose lux level was
checked when it was built.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from simspad import __version__
from simspad.errors import SimSpadError
from simspad.io.provenance import created_utc
from simspad.io.recording import RecordingWriter
from simspad.physics.seeding import child_rng
from simspad.radiance.timeline import Timeline
from simspad.sensors.ground_truth import write_ground_truth
from simspad.sensors.presets import params_to_attrs
from simspad.sensors.recording_settings import RecordingSettings
from simspad.sensors.registry import ordered
from simspad.sensors.render_noise import render_noise_attrs
from simspad.sensors.recording_size import check_recording_size

__all__ = ["RecordingSettings", "simulate_recording"]

#: Instants this close beyond the render's last keyframe are accepted (round-off of start + duration).
_TIME_TOLERANCE_S = 1e-9


def simulate_recording(render_dir, out_path, settings: RecordingSettings, *, metadata: dict | None = None,
                       progress: bool = False, motion_attrs=None) -> Path:
    """Simulate ``settings.sensors`` on a render directory at ``settings.lux`` and write the recording ``out_path``.

    Parameters
    ----------
    render_dir : str or Path
        Render directory (docs/format.md).
    out_path : str or Path
        Recording to write (``.h5``); written to a temporary name and renamed when complete.
    settings : RecordingSettings
        Lux, sensors and their parameters, interval, seed and stream key, ground-truth rate, optics.
    metadata : dict, optional
        Root attributes to add or override (``scene``, ``trajectory``, ``sequence``, ``spec`` (dict or JSON
        text), ``created_utc`` — pass a fixed value for byte-identical files).
    progress : bool
        Show progress bars.
    motion_attrs : callable, optional
        ``motion_attrs(frame_exposure_s) -> dict``: root attributes stating the image motion the recording
        contains, given the frame camera's resolved exposure in seconds (None without a frame camera); called
        once the sensors have run. The caller measures the motion (this layer does not read renders' geometry).

    Returns
    -------
    Path
        ``out_path``.

    Raises
    ------
    SimSpadError
        Bad interval, sensor kind or parameter (the lux level was checked by ``settings``); InputError for a
        malformed render directory.
    """
    lux, sensors, seed, stream_key = settings.lux, settings.sensors, settings.seed, settings.stream_key
    rows = ordered(sensors)  # unknown kinds refused here
    optics = settings.optics
    out_path = Path(out_path)
    tl = Timeline.open(render_dir)
    for row, params in rows:  # every model check before anything is written (one message naming the field)
        row.validate(params, tl.height)
    t0, t1 = _interval(tl, settings.start_s, settings.duration_s, render_dir)
    check_recording_size(sensors, t1 - t0, tl.width, tl.height, settings.gt_rate_hz, out_path)  # before any write
    flux_tl = tl.photon_flux(lux, optics)
    for row, params in rows:
        if row.precheck is not None:  # e.g. hours of event-noise draws: refused now
            row.precheck(flux_tl, t0, t1, params, lux)
    attrs = _root_attrs(tl, render_dir, settings, t0=t0, t1=t1, flux_scale=flux_tl.scale, metadata=metadata)
    attrs.update(render_noise_attrs(flux_tl, render_dir, sensors.get("events")))
    common = {"lux": float(lux), "flux_scale": float(flux_tl.scale),
              **{f"optics_{k}": v for k, v in optics.to_attrs().items()}}
    with RecordingWriter(out_path, attrs) as writer:
        frame_exposure_s = None
        for row, params in rows:
            written = row.simulate(writer, flux_tl, t0, t1, params, child_rng(seed, *stream_key, row.name),
                                   lux=lux, progress=progress)
            if row.name == "frames" and isinstance(written, dict):  # the frame camera's exposure sets its blur
                frame_exposure_s = written.get("exposure_s")
            writer.set_attrs(row.name, **common)
        write_ground_truth(writer, flux_tl, t0, t1, settings.gt_rate_hz)
        writer.set_attrs("gt", **common)
        if motion_attrs is not None:
            writer.set_attrs("/", **motion_attrs(frame_exposure_s))
    return out_path


def _interval(tl: Timeline, start_s, duration_s, render_dir) -> tuple[float, float]:
    """Resolve and check the simulated interval against the render's time span."""
    t0 = tl.t_start if start_s is None else float(start_s)
    if not (math.isfinite(t0) and tl.t_start - _TIME_TOLERANCE_S <= t0 < tl.t_end):
        raise SimSpadError(f"start {t0!r} s lies outside the render's span [{tl.t_start!r}, {tl.t_end!r}) s",
                           path=render_dir, field="start_s")
    t0 = max(t0, tl.t_start)
    if duration_s is None:
        return t0, tl.t_end
    d = float(duration_s)  # finite and > 0: the recording settings checked it
    if t0 + d > tl.t_end + _TIME_TOLERANCE_S:
        raise SimSpadError(f"start {t0!r} s + duration {d!r} s goes past the render's last keyframe at "
                           f"{tl.t_end!r} s", path=render_dir, field="duration_s")
    return t0, min(t0 + d, tl.t_end)


def _root_attrs(tl: Timeline, render_dir, settings: RecordingSettings, *, t0, t1, flux_scale, metadata) -> dict:
    """Root attributes of the recording."""
    lux, sensors, seed, stream_key = settings.lux, settings.sensors, settings.seed, settings.stream_key
    gt_rate_hz, optics = settings.gt_rate_hz, settings.optics
    meta = dict(metadata or {})
    scene = tl.meta.get("scene", "")
    trajectory = tl.meta.get("trajectory", "")
    spec = meta.pop("spec", None)
    if spec is None:
        spec = {"render_dir": str(Path(render_dir)), "lux": float(lux), "start_s": t0, "duration_s": t1 - t0,
                "seed": _seed_value(seed), "stream_key": [str(k) for k in stream_key], "gt_rate_hz": gt_rate_hz,
                "optics": optics.to_attrs(),
                "sensors": {k: params_to_attrs(p) for k, p in sensors.items()}}
    if not isinstance(spec, str):
        spec = json.dumps(spec, sort_keys=True, default=str)
    attrs = {
        "simspad_version": __version__,
        "scene": scene if isinstance(scene, str) else json.dumps(scene, sort_keys=True, default=str),
        "trajectory": trajectory if isinstance(trajectory, str) else json.dumps(trajectory, sort_keys=True,
                                                                                default=str),
        "sequence": meta.pop("sequence", None) or (scene if isinstance(scene, str) else "") or Path(render_dir).name,
        "lux": float(lux),
        "seed": _seed_value(seed),
        "stream_key": json.dumps([str(k) for k in stream_key]),
        "width": int(tl.width),
        "height": int(tl.height),
        "duration_s": float(t1 - t0),
        "t_start_s": float(t0),
        "t_end_s": float(t1),
        "time_origin_s": 0.0,
        "gt_rate_hz": float(gt_rate_hz),
        "sensors": ",".join(row.name for row, _ in ordered(sensors)),
        "flux_scale": float(flux_scale),
        "optics": optics.to_attrs(),
        "spec": spec,
        "created_utc": created_utc(),
    }
    convergence = tl.meta.get("renderer", {}).get("convergence")
    if convergence:  # a converged render states its mode and knobs (a path-traced one's attributes stay as they were)
        attrs["render_convergence"] = json.dumps(convergence, sort_keys=True)
    attrs.update(meta)
    return attrs


def _seed_value(seed):
    if isinstance(seed, np.random.SeedSequence):
        return str(seed.entropy) if seed.spawn_key == () else f"{seed.entropy}/{list(seed.spawn_key)}"
    seed = int(seed)
    return seed if -(2**63) <= seed < 2**63 else str(seed)

"""Ground truth (docs/sensors.md, docs/format.md): sharp sensor-plane photon irradiance at requested instants, poses and depth.

``/gt/flux`` holds the *instantaneous* irradiance Φ(t) (no exposure blur) of the piecewise-linear timeline at
``/gt/t``; ``/gt/depth`` the depth in metres where the render has it; ``/poses`` the camera-to-world matrices of
the keyframes that cover the interval (interpolate between them as rigid motions, not element-wise).
"""

from __future__ import annotations

import math

import numpy as np

from simspad import defaults

#: Ground-truth frames written per HDF5 chunk (and held in memory at once).
GT_CHUNK_FRAMES = 16


def gt_times(t0: float, t1: float, rate_hz: float) -> np.ndarray:
    """Instants ``t0 + i/rate_hz`` inside ``[t0, t1]``, s (float64; the end is included when it falls on the grid)."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise ValueError(f"gt rate must be a finite number > 0, got {rate_hz!r}")
    n = int(math.floor((t1 - t0) * rate_hz * (1 + 1e-12) + 1e-9)) + 1
    return t0 + np.arange(max(n, 0)) / rate_hz


def pose_indices(times_s: np.ndarray, t0: float, t1: float) -> slice:
    """Keyframes whose instants lie in ``[t0, t1]`` plus the one on each side, so poses bracket the interval."""
    i0 = max(int(np.searchsorted(times_s, t0, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(times_s, t1, side="left")) + 1, len(times_s))
    return slice(i0, i1)


def write_ground_truth(writer, flux_tl, t0: float, t1: float, rate_hz: float = defaults.GT_RATE_HZ) -> np.ndarray:
    """Write ``/gt/t``, ``/gt/flux``, ``/gt/depth`` (if any) and ``/poses`` (if any), streaming the frames.

    Parameters
    ----------
    writer : simspad.io.recording.RecordingWriter
        Open writer.
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Interval, s.
    rate_hz : float
        Ground-truth frame rate.

    Returns
    -------
    ndarray
        The ground-truth instants, s.
    """
    H, W = flux_tl.height, flux_tl.width
    t = gt_times(t0, t1, rate_hz)
    writer.write_dataset("gt/t", t, attrs={"units": "s"})
    writer.set_attrs("gt", rate_hz=float(rate_hz), flux_units="photons s-1 m-2", kind="instantaneous")
    rows = min(GT_CHUNK_FRAMES, max(len(t), 1))
    flux = writer.append_dataset("gt/flux", (H, W), np.float32, chunk_rows=rows,
                                 attrs={"units": "photons s-1 m-2"})
    depth = None
    if flux_tl.has_depth:
        depth = writer.append_dataset("gt/depth", (H, W), np.float32, chunk_rows=rows, attrs={"units": "m"})
    for i in range(0, len(t), rows):
        ts = t[i : i + rows]
        # flux and depth of an instant together: both come from the same two keyframes, which the timeline's
        # small cache still holds (a pass of flux over a chunk and then one of depth decoded every keyframe twice)
        flux_rows, depth_rows = [], []
        for ti in ts:
            flux_rows.append(flux_tl.sample(ti))
            if depth is not None:
                depth_rows.append(flux_tl.depth(ti))
        flux.append(np.stack(flux_rows))
        if depth is not None:
            depth.append(np.stack(depth_rows))
    if flux_tl.poses is not None:
        sel = pose_indices(flux_tl.times_s, t0, t1)
        writer.write_dataset("poses/t", np.asarray(flux_tl.times_s[sel], np.float64), attrs={"units": "s"})
        writer.write_dataset("poses/camera_to_world", np.asarray(flux_tl.poses[sel], np.float64),
                             attrs={"convention": "mitsuba: camera looks along +Z, up +Y"})
    return t

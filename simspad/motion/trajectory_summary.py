"""Summary figures of a trajectory: duration, path length, peak speed and peak angular rate.

The trajectory is sampled uniformly at ``rate_hz`` (at most 200 000 samples); the path length is the length
of the polyline through the sampled body origins.
"""

from __future__ import annotations

import math

import numpy as np

from simspad.motion.trajectory import Trajectory


def motion_summary(tr: Trajectory, *, rate_hz: float = 2000.0) -> dict[str, float]:
    """Duration (s), path length (m), max speed (m/s) and max angular rate (rad/s) sampled at ``rate_hz``."""
    if len(tr.times_s) == 1:
        return {"duration_s": 0.0, "path_length_m": 0.0, "max_speed_m_s": 0.0, "max_angular_rate_rad_s": 0.0,
                "keyframes": 1}
    n = max(2, min(200_000, int(math.ceil((tr.t_end - tr.t_start) * rate_hz)) + 1))
    t = np.linspace(tr.t_start, tr.t_end, n)
    p = tr.position(t)
    v, w = tr.velocity(t)
    return {"duration_s": tr.t_end - tr.t_start,
            "path_length_m": float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()),
            "max_speed_m_s": float(np.linalg.norm(v, axis=1).max()),
            "max_angular_rate_rad_s": float(np.linalg.norm(w, axis=1).max()),
            "keyframes": len(tr.times_s)}

"""``simspad info`` on a trajectory file: per body duration, path length, max speed and max angular rate."""

from __future__ import annotations

import numpy as np

from simspad.io.trajectory_files import load_trajectory
from simspad.motion.trajectory_summary import motion_summary


def describe_trajectory(path) -> str:
    """A readable summary of a trajectory file: per body duration, path length, max speed, max angular rate."""
    ts = load_trajectory(path)
    lines = [f"trajectory {ts.source}"]
    if ts.time_offset_s:
        lines.append(f"  time offset    {ts.time_offset_s:.6f} s subtracted (timestamps rebased to start at 0)")
    lines.append(f"  common span    {ts.t_start:.6g} – {ts.t_end:.6g} s")
    for name, tr in ts.bodies().items():
        s = motion_summary(tr)
        lines.append(f"  {name}:")
        lines.append(f"    keyframes        {s['keyframes']}  ({tr.t_start:.6g} – {tr.t_end:.6g} s)")
        lines.append(f"    duration         {s['duration_s']:.6g} s")
        lines.append(f"    path length      {s['path_length_m']:.6g} m (of the body origin)")
        lines.append(f"    max speed        {s['max_speed_m_s']:.6g} m/s")
        lines.append(f"    max angular rate {s['max_angular_rate_rad_s']:.6g} rad/s "
                     f"({np.rad2deg(s['max_angular_rate_rad_s']):.4g} deg/s)")
    return "\n".join(lines)

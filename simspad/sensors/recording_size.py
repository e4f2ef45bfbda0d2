"""How big a recording will be, checked before simulating: a unit slip (keyframe times in µs written as seconds)
must be refused with the figure, not discovered after gigabytes are written.

The estimate counts what is known from the interval and the parameters alone, by each sensor-table row's size
model (``rows``, ``row_bytes``): SPAD bit planes (one bit per pixel per bin), frames (uint16 per pixel), and the
ground truth (float32 flux and depth per instant); events depend on the scene and are not counted, nor is the
ground truth's geometry (instances, flow, validity, velocity: stored compressed, measured by
``simspad generate --estimate``). Compressed layouts only make the file smaller.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.sensors.registry import SENSORS, ordered


def recording_samples(sensors: dict, duration_s: float, gt_rate_hz: float) -> dict[str, float]:
    """Rows per stream of a recording of ``duration_s``: ground-truth instants, then each sensor's rows by its
    table row's size model (SPAD bins, frames; none for events)."""
    out = {"gt": duration_s * gt_rate_hz}
    for row, params in ordered(sensors):
        if row.rows is not None:
            out[row.name] = row.rows(params, duration_s)
    return out


def recording_bytes(samples: dict[str, float], width: int, height: int) -> float:
    """Bytes of the counted streams (events excluded)."""
    per_row = {"gt": 8 * width * height}
    per_row.update({k: SENSORS[k].row_bytes(width, height) for k in samples if k != "gt"})
    return sum(n * per_row[k] for k, n in samples.items())


def check_recording_size(sensors: dict, duration_s: float, width: int, height: int, gt_rate_hz: float,
                         out_path: str | Path) -> None:
    """Refuse a recording with more rows than :data:`~simspad.defaults.MAX_SAMPLES_PER_RECORDING` in one stream,
    or larger than the free space of ``out_path``'s disk; ``SIMSPAD_IGNORE_LIMITS=1`` lifts both."""
    if os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1":
        return
    samples = recording_samples(sensors, duration_s, gt_rate_hz)
    kind, n = max(samples.items(), key=lambda kv: kv[1])
    lift = "set SIMSPAD_IGNORE_LIMITS=1 to try anyway"
    if n > defaults.MAX_SAMPLES_PER_RECORDING:
        raise SimSpadError(f"{duration_s:g} s gives {n:.3g} {kind} rows, above the limit of "
                           f"{defaults.MAX_SAMPLES_PER_RECORDING:.3g} (keyframe times in µs written as seconds? "
                           f"pass --duration, or {lift})", field="duration_s")
    need = recording_bytes(samples, width, height)
    folder = Path(out_path).parent
    try:
        free = shutil.disk_usage(folder if folder.exists() else Path.cwd()).free
    except OSError:
        return
    if need > free:
        raise SimSpadError(f"the recording needs about {need / 2**30:.2f} GiB (SPAD, frames and ground truth alone) "
                           f"but its disk has {free / 2**30:.2f} GiB free; shorten it or free space ({lift})",
                           path=out_path)

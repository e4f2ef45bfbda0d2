"""``simspad simulate``: parse ``--sensors`` and ``--set`` overrides, then simulate one recording.

The ``--set SENSOR.FIELD=VALUE`` values are typed here (:func:`parse_value`); the parameter records of
:mod:`simspad.sensors.presets` check them (the same rule and message as a dataset spec's ``[sensors.*]``), and
the options ``--lux``, ``--seed`` and ``--gt-rate`` meet the recording settings' rules, all before anything is
written. The simulation itself is
:func:`simspad.sensors.simulate.simulate_recording`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.io.atomic import check_output_file
from simspad.io.recording.layout import FORMAT as RECORDING_FORMAT
from simspad.io.render_dir import TIMELINE_FILE
from simspad.sensors.presets import SENSOR_KINDS, sensor_params
from simspad.sensors.recording_settings import lux_problem
from simspad.sensors.registry import BUILTIN_SENSORS
from simspad.sensors.simulate import RecordingSettings, simulate_recording


def parse_value(text: str):
    """A ``--set`` value: ``auto``, ``true``/``false``, an integer, a float, or the text itself."""
    low = text.strip().lower()
    if low == "auto":
        return "auto"
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    try:
        return int(low)
    except ValueError:
        pass
    try:
        return float(low)
    except ValueError:
        return text.strip()


def parse_sensor_list(text: str) -> list[str]:
    """``"spad,frames"`` → ``["spad", "frames"]``; SimSpadError naming ``--sensors`` on unknown or empty."""
    kinds = []
    for part in (text or "").split(","):
        part = part.strip()
        if not part:
            continue
        if part not in SENSOR_KINDS:
            raise SimSpadError(f"unknown sensor {part!r} (expected one of {', '.join(SENSOR_KINDS)})",
                               field="--sensors")
        if part not in kinds:
            kinds.append(part)
    if not kinds:
        raise SimSpadError(f"no sensor given (expected some of {', '.join(SENSOR_KINDS)})", field="--sensors")
    return kinds


def parse_overrides(items, kinds: list[str]) -> dict[str, dict]:
    """``["spad.gate_s=1e-6", ...]`` → ``{"spad": {"gate_s": 1e-6}}``; SimSpadError naming ``--set``."""
    out: dict[str, dict] = {k: {} for k in kinds}
    for item in items or ():
        key, sep, value = item.partition("=")
        kind, dot, name = key.strip().partition(".")
        if not sep or not dot or not name:
            raise SimSpadError(f"expected SENSOR.FIELD=VALUE, got {item!r}", field="--set")
        if kind not in SENSOR_KINDS:
            raise SimSpadError(f"unknown sensor {kind!r} in {item!r} (expected one of {', '.join(SENSOR_KINDS)})",
                               field="--set")
        if kind not in kinds:
            raise SimSpadError(f"{item!r} sets a parameter of {kind!r}, which is not in --sensors "
                               f"({','.join(kinds)})", field="--set")
        out[kind][name.strip()] = parse_value(value)
    return out


def _is_recording(path: Path) -> bool:
    """An HDF5 file whose root ``format`` attribute names a SimSPAD recording: what ``simulate`` may replace."""
    import h5py  # deferred: h5py is loaded by the simulation right after

    if not h5py.is_hdf5(path):
        return False
    with h5py.File(path, "r") as h5:
        fmt = h5.attrs.get("format")
    return (fmt.decode(errors="replace") if isinstance(fmt, bytes) else fmt) == RECORDING_FORMAT


def simulate_from_cli(render_dir, *, lux: float, sensors: str | None, start_s: float | None, duration_s: float | None,
                      seed: int, overrides, out_path, gt_rate_hz: float | None = None) -> Path:
    """The ``simspad simulate`` command: parse ``--sensors`` (None: the built-in sensors) and ``--set``, then
    :func:`simulate_recording` (ground truth at ``gt_rate_hz``; None: the render's geometry-pass rate, else the
    default)."""
    if problem := lux_problem(lux):  # the recording settings' rule, reported under the option's name
        raise SimSpadError(problem, field="--lux")
    kinds = parse_sensor_list(sensors) if sensors is not None else [row.name for row in BUILTIN_SENSORS]
    per_kind = parse_overrides(overrides, kinds)
    params = {}
    for kind in kinds:
        try:
            params[kind] = sensor_params(kind, None, per_kind[kind])
        except ValueError as exc:
            raise SimSpadError(str(exc), field=f"--set {kind}") from None
        # a value the parameter record refuses raises its own error, naming sensors.<kind>.<field>
    # the recording settings' rules, reported under the options' names before the output is touched
    if problem := defaults.seed_problem(seed):
        raise SimSpadError(problem, field="--seed")
    if gt_rate_hz is not None and (problem := defaults.gt_rate_problem(gt_rate_hz)):
        raise SimSpadError(problem, field="--gt-rate")
    if duration_s is not None and (problem := defaults.duration_problem(duration_s)):
        raise SimSpadError(problem, field="--duration")
    check_output_file(out_path, recognise=_is_recording, what="a SimSPAD recording")
    if gt_rate_hz is None:
        gt_rate_hz = _render_gt_rate(render_dir)
    settings = RecordingSettings(lux=lux, sensors=params, start_s=start_s, duration_s=duration_s, seed=seed,
                                 gt_rate_hz=gt_rate_hz)
    return simulate_recording(render_dir, out_path, settings, progress=sys.stderr.isatty())


def _render_gt_rate(render_dir) -> float:
    """The rate of the render's geometry passes (``timeline.json``'s ``geometry.rate_hz``), else the default."""
    try:
        rate = json.loads((Path(render_dir) / TIMELINE_FILE).read_text()).get("geometry", {}).get("rate_hz")
    except (OSError, ValueError, AttributeError):
        rate = None  # a missing or broken render directory is reported by the simulation, naming the file
    return float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) and rate > 0 \
        else defaults.GT_RATE_HZ

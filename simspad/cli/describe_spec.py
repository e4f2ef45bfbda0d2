"""``simspad info SPEC``: a readable summary of a dataset spec (sequences, lux levels, sensors, evaluation)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from simspad.bundled import bundled_relative
from simspad.dataset.spec_hashing import spec_hash
from simspad.dataset.spec_validation import load_spec
from simspad.scenes.library import resolve_scene
from simspad.sensors.registry import SENSORS


def describe_spec(path) -> str:
    """A readable summary of a spec: sequences, lux levels, sensors with key parameters, evaluation."""
    spec = load_spec(path)
    lines = [f"dataset spec {path}", f"  name        {spec.name}", f"  seed        {spec.seed}",
             f"  output      {spec.output}", f"  spec hash   {spec_hash(spec)[:16]}",
             f"  lux         {', '.join(f'{x:g}' for x in spec.lux)}",
             f"  speed       {', '.join(f'×{k:g}' for k in spec.speed)} (trajectories retimed: pose(t) = base(k·t))",
             f"  sequences   {len(spec.sequences)} (× {len(spec.speed)} speed × {len(spec.lux)} lux = "
             f"{len(spec.sequences) * len(spec.speed) * len(spec.lux)} recordings)"]
    for s in spec.sequences:
        traj = _short(s.trajectory) if s.trajectory is not None else _default_trajectory_text(s.scene)
        lines.append(f"    {s.name}: scene {_short(s.scene)}, {s.resolution[0]}×{s.resolution[1]} px, "
                     f"{s.spp} {'spp' if s.convergence == 'off' else 'camera rays per pixel'}, "
                     f"{s.start_s:g}–{s.start_s + s.duration_s:g} s, trajectory {traj}"
                     + (f", {s.interpolation} interpolation" if s.interpolation != "linear" else "")
                     + (f", convergence {s.convergence} ({s.cache_samples} estimates per cache point)"
                        if s.convergence != "off" else ""))
    lines.append("  sensors")
    for kind, sensor in spec.sensors.items():
        lines.append(f"    {kind}: preset {sensor.preset}{_overrides_text(sensor.overrides)}")
        lines.append(f"      {_key_params(sensor.params)}")
    methods = ", ".join(spec.evaluation.methods) or "all applicable"
    lines.append(f"  evaluation  {spec.evaluation.rate_hz:g} Hz, methods: {methods}")
    return "\n".join(lines)


def _short(path) -> str:
    """``path`` relative to the current directory when inside it, else a bundled file as ``trajectories/<file>``."""
    p = Path(path)
    try:
        return str(p.relative_to(Path.cwd()))
    except ValueError:
        return bundled_relative(p) or str(p)


def _default_trajectory_text(scene: str) -> str:
    default = resolve_scene(scene).default_trajectory
    return "scene default (static camera)" if default is None else f"scene default ({_short(default)})"


def _overrides_text(overrides: dict) -> str:
    if not overrides:
        return ""
    return " (overrides: " + ", ".join(f"{k}={v!r}" for k, v in overrides.items()) + ")"


def _key_params(p) -> str:
    """The sensor's parameter line: its table row's ``summarize``, else every field."""
    row = SENSORS.get(getattr(p, "kind", ""))
    if row is not None and row.summarize is not None:
        return row.summarize(p)
    return ", ".join(f"{f.name} {getattr(p, f.name)!r}" for f in dataclasses.fields(p))

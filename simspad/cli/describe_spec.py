"""``simspad info SPEC``: a readable summary of a dataset spec (sequences, lux levels, sensors, evaluation)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from simspad.bundled import bundled_relative
from simspad.cli.text import format_duration_s
from simspad.dataset.spec_hashing import spec_hash
from simspad.dataset.spec_validation import load_spec
from simspad.scenes.library import resolve_scene


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
        lines.append(f"    {s.name}: scene {_short(s.scene)}, {s.resolution[0]}×{s.resolution[1]} px, {s.spp} spp, "
                     f"{s.start_s:g}–{s.start_s + s.duration_s:g} s, trajectory {traj}")
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
    kind = getattr(p, "kind", "")
    if not all(hasattr(p, k) for k in ("pixel_pitch_m", "fill_factor", "qe")):  # a sensor without pixels
        return ", ".join(f"{f.name} {getattr(p, f.name)!r}" for f in dataclasses.fields(p))
    pitch = f"pitch {p.pixel_pitch_m * 1e6:.4g} µm, fill {p.fill_factor:.3g}, QE {p.qe:.3g}"
    if kind == "spad":
        return (f"{pitch}, bin {format_duration_s(p.bin_s)} ({1 / p.bin_s / 1e3:.4g} kHz), gate {format_duration_s(p.gate_s)}, "
                f"DCR median {p.dcr_median_cps:g} cps, dead time {format_duration_s(p.dead_time_s)}")
    if kind == "frames":
        return (f"{pitch}, {p.frame_rate_hz:g} fps, exposure {format_duration_s(p.exposure_s)}, K {p.gain_dn_per_e:g} DN/e⁻, "
                f"read noise {p.read_noise_e:g} e⁻, full well {p.full_well_e:g} e⁻, {p.bit_depth} bit")
    if kind == "events":
        return (f"{pitch}, thresholds +{p.threshold_on:g}/−{p.threshold_off:g} (σ {p.threshold_sigma:g}), "
                f"refractory {format_duration_s(p.refractory_s)}, latency {format_duration_s(p.latency_s)}")
    return pitch

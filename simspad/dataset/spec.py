"""Dataset specs: TOML files loaded into frozen, validated dataclasses.

A spec names the dataset, its seed and output folder, the sequences to render (scene, trajectory, duration,
resolution, samples per pixel), the lux levels, the sensors (preset + overrides) and the evaluation settings::

    name = "mini"
    seed = 1
    output = "output/mini"          # relative to the current directory
    lux = [1, 10, 100]
    speed = [1.0, 8.0]              # optional speed factors (default [1.0]): trajectories played k× faster

    [[sequences]]
    scene = "office"                # built-in name, or a scene folder / .xml (relative to this file)
    trajectory = "orbit.toml"       # optional (default: the scene's own); relative to this file, then trajectories/
    duration_s = 0.03
    resolution = [64, 48]           # [W, H]
    spp = 8

    [sensors.spad]
    preset = "swissspad2"
    gate_s = 1e-6                   # any other field overrides the preset

    [evaluation]
    rate_hz = 1000
    methods = []                    # empty: all that apply

This module holds the spec's model. :func:`simspad.dataset.spec_validation.load_spec` reads a file and checks
everything, raising one :class:`~simspad.errors.SpecError` that lists every problem, one line each:
``FILE: field.path: what is wrong (expected ...)``; :mod:`simspad.dataset.spec_hashing` gives the content hashes
that decide what must be regenerated.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simspad import defaults
from simspad.bundled import DATASETS_DIR, builtin_spec_path
from simspad.render.settings import DEFAULT_CACHE_SAMPLES, DEFAULT_CONVERGENCE, DEFAULT_INTERPOLATION, RenderSettings
from simspad.sensors.presets import params_to_attrs


@dataclass(frozen=True)
class SequenceSpec:
    """One rendered sequence.

    Attributes
    ----------
    name : str
        Unique within the spec (defaults to the scene name).
    scene : str
        Built-in scene name or the absolute path of a scene folder / ``.xml``.
    trajectory : str or None
        Absolute path of the trajectory file, or None for the scene's default trajectory.
    duration_s, start_s : float
        Simulated span [start_s, start_s + duration_s] in trajectory time, seconds.
    resolution : tuple of int
        (W, H) pixels of the common simulation grid.
    spp : int
        Mitsuba samples per pixel.
    max_flow_px : float
        Largest image motion between render keyframes, pixels.
    min_rate_hz : float
        Lowest keyframe rate, Hz.
    interpolation : str
        ``"linear"``: render every keyframe; ``"warp"``: render sparse keyframes and synthesize those between by
        reprojection, rendering for real where the warps disagree (:mod:`simspad.render.warp.schedule`).
    convergence : str
        ``"off"``: path-trace every keyframe at ``spp``; ``"cache"``: converge the diffuse light once per render
        into an irradiance cache (:attr:`simspad.render.settings.RenderSettings.convergence`).
    cache_samples : int
        With ``"cache"``: irradiance estimates per point of the cache's probe views.
    """

    name: str
    scene: str
    trajectory: str | None
    duration_s: float
    start_s: float = 0.0
    resolution: tuple[int, int] = defaults.RESOLUTION_PX
    spp: int = defaults.SPP
    max_flow_px: float = defaults.MAX_FLOW_PX
    min_rate_hz: float = defaults.MIN_KEYFRAME_RATE_HZ
    interpolation: str = DEFAULT_INTERPOLATION
    convergence: str = DEFAULT_CONVERGENCE
    cache_samples: int = DEFAULT_CACHE_SAMPLES

    def render_settings(self, seed: int, gt_rate_hz: float | None = defaults.GT_RATE_HZ) -> RenderSettings:
        """The sequence's render settings: the one mapping of its fields onto :class:`RenderSettings`.

        Parameters
        ----------
        seed : int
            Render seed (frozen Monte Carlo noise), from the plan.
        gt_rate_hz : float or None
            Ground-truth rate, Hz: a geometry pass at each instant (the spec's ``evaluation.rate_hz``).
        """
        return RenderSettings(duration_s=self.duration_s, start_s=self.start_s, resolution=tuple(self.resolution),
                              spp=self.spp, max_flow_px=self.max_flow_px, min_rate_hz=self.min_rate_hz, seed=seed,
                              interpolation=self.interpolation, gt_rate_hz=gt_rate_hz,
                              convergence=self.convergence, cache_samples=self.cache_samples)

    def to_dict(self) -> dict:
        """Plain JSON-able dict of the fields (``interpolation`` only when it is not linear, ``convergence`` and
        ``cache_samples`` only when convergence is not off: the hashes of specs written before the fields existed
        stay as they were)."""
        d = dataclasses.asdict(self)
        d["resolution"] = list(self.resolution)
        if self.interpolation == "linear":
            del d["interpolation"]
        if self.convergence == "off":  # (cache_samples then changes nothing rendered)
            del d["convergence"], d["cache_samples"]
        return d


@dataclass(frozen=True)
class SensorSpec:
    """One sensor: its kind (``spad``, ``frames``, ``events``), preset, resolved parameters and the overrides."""

    kind: str
    preset: str
    params: Any
    overrides: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "preset": self.preset, "overrides": dict(self.overrides),
                "params": params_to_attrs(self.params)}


@dataclass(frozen=True)
class EvaluationSpec:
    """Evaluation settings: ground-truth / scoring rate (Hz) and method names (empty: all that apply)."""

    rate_hz: float = defaults.GT_RATE_HZ
    methods: tuple[str, ...] = ()
    params: dict = field(default_factory=dict)
    """Method name → parameters (``[evaluation.params.METHOD]``), validated against the method table."""

    def to_dict(self) -> dict:
        # `params` only when set: the dict is hashed into the spec hash, which must not change for specs without it
        return {"rate_hz": self.rate_hz, "methods": list(self.methods),
                **({"params": {m: dict(p) for m, p in sorted(self.params.items())}} if self.params else {})}


@dataclass(frozen=True)
class DatasetSpec:
    """A validated dataset spec (see the module docstring).

    ``output`` is absolute (relative paths are taken from the current directory at load time); ``raw`` is the
    parsed TOML document as written; ``source_path`` the file it came from (None when built in code).
    """

    name: str
    seed: int
    output: Path
    sequences: tuple[SequenceSpec, ...]
    lux: tuple[float, ...]
    sensors: dict[str, SensorSpec]
    evaluation: EvaluationSpec = EvaluationSpec()
    source_path: Path | None = None
    #: Speed factors k: every sequence is produced with its trajectory retimed, pose(t) = base pose(k·t).
    speed: tuple[float, ...] = (1.0,)
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def to_dict(self) -> dict:
        """The validated spec as plain JSON-able data (for the manifest and recording attrs)."""
        return {"name": self.name, "seed": self.seed, "output": str(self.output),
                "sequences": [s.to_dict() for s in self.sequences], "lux": list(self.lux),
                "speed": list(self.speed),
                "sensors": {k: s.to_dict() for k, s in self.sensors.items()},
                "evaluation": self.evaluation.to_dict()}

    def sequence(self, name: str) -> SequenceSpec:
        """The sequence called ``name`` (KeyError if none)."""
        for s in self.sequences:
            if s.name == name:
                return s
        raise KeyError(name)


def default_spec_path() -> Path:
    """The embedded default spec, the bundled ``mini`` (``datasets/mini.toml``, :mod:`simspad.bundled`)."""
    return DATASETS_DIR / "mini.toml"


def find_spec(name_or_path) -> Path:
    """The spec file a command-line argument names: an existing file, else a bundled spec's name (``mini``).

    A path that exists neither as a file nor as a bundled name is returned unchanged, so that reading it reports
    the missing file by its path.
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    bundled = builtin_spec_path(str(name_or_path)) if path.name == str(name_or_path) and not path.suffix else None
    return bundled if bundled is not None else path

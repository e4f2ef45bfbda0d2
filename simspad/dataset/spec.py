"""Dataset specs: TOML files loaded into frozen, validated dataclasses.

A spec names the dataset, its seed and output folder, the sequences to render (scene, trajectory, duration,
resolution, samples per pixel), the lux levels, the sensors (preset + overrides) and the evaluation settings::

    name = "mini"
    seed = 1
    output = "output/mini"          # relative to the current directory
    lux = [1, 10, 100]

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

:func:`load_spec` checks everything and raises one :class:`~simspad.errors.SpecError` listing every problem,
one line each: ``FILE: field.path: what is wrong (expected ...)``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simspad import defaults
from simspad.errors import SimSpadError, SpecError
from simspad.io.bundled import DATASETS_DIR, REPO_ROOT, SCENES_DIR, TRAJECTORIES_DIR
from simspad.io.hashing import file_sha256

KNOWN_METHODS = ("ni", "nedi", "nedi_akf", "adaptive_nedi_akf", "akf_fe", "cf", "edi", "qbp")
"""Method names of docs/internals.md; the method registry, once importable, adds any others."""


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

    def to_dict(self) -> dict:
        """Plain JSON-able dict of the fields."""
        d = dataclasses.asdict(self)
        d["resolution"] = list(self.resolution)
        return d


@dataclass(frozen=True)
class SensorSpec:
    """One sensor: its kind (``spad``, ``frames``, ``events``), preset, resolved parameters and the overrides."""

    kind: str
    preset: str
    params: Any
    overrides: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        from simspad.sensors.presets import params_to_attrs

        return {"kind": self.kind, "preset": self.preset, "overrides": dict(self.overrides),
                "params": params_to_attrs(self.params)}


@dataclass(frozen=True)
class EvaluationSpec:
    """Evaluation settings: ground-truth / scoring rate (Hz) and method names (empty: all that apply)."""

    rate_hz: float = defaults.GT_RATE_HZ
    methods: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"rate_hz": self.rate_hz, "methods": list(self.methods)}


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
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def to_dict(self) -> dict:
        """The validated spec as plain JSON-able data (for the manifest and recording attrs)."""
        return {"name": self.name, "seed": self.seed, "output": str(self.output),
                "sequences": [s.to_dict() for s in self.sequences], "lux": list(self.lux),
                "sensors": {k: s.to_dict() for k, s in self.sensors.items()},
                "evaluation": self.evaluation.to_dict()}

    def sequence(self, name: str) -> SequenceSpec:
        """The sequence called ``name`` (KeyError if none)."""
        for s in self.sequences:
            if s.name == name:
                return s
        raise KeyError(name)


# --------------------------------------------------------------------------------------------------------------
# Hashing


def _jsonable(obj):
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_dict"):
            return obj.to_dict()
        return dataclasses.asdict(obj)
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover - numpy is a dependency
        pass
    raise TypeError(f"cannot hash object of type {type(obj).__name__}")


def canonical_json(obj) -> str:
    """Canonical JSON text: sorted keys, no whitespace, dataclasses/Paths/numpy values converted."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False,
                      default=_jsonable)


def spec_hash(obj) -> str:
    """SHA-256 (hex) of the canonical JSON of ``obj``.

    For a :class:`DatasetSpec` the hash covers what decides the data: ``to_dict()`` without ``output``, with each
    sequence's scene and trajectory paths replaced by their contents (:func:`sequence_hash`), so the same spec
    checked out elsewhere or writing to another folder has the same hash.
    """
    if isinstance(obj, DatasetSpec):
        d = {k: v for k, v in obj.to_dict().items() if k != "output"}
        d["sequences"] = [{"name": s.name, "content": sequence_hash(s)} for s in obj.sequences]
        obj = d
    return hashlib.sha256(canonical_json(obj).encode("utf-8")).hexdigest()


def sequence_hash(seq: SequenceSpec, spec: DatasetSpec | None = None) -> str:
    """Content hash of what a sequence's data depends on.

    Without ``spec``: what the *render* depends on — the sequence fields (but not its name), the trajectory
    file's bytes instead of its path, and the scene's content hash (:func:`simspad.scenes.content_hash`).
    With ``spec``: additionally the dataset seed, every sensor's resolved parameters and the evaluation rate
    (the ground-truth rate), i.e. what a recording of the sequence depends on apart from its lux level.
    """
    from simspad.scenes.library import content_hash, resolve_scene

    d = seq.to_dict()
    d.pop("name")
    info = resolve_scene(seq.scene)
    d["scene"] = {"name": info.name, "content": content_hash(info)}
    trajectory = seq.trajectory if seq.trajectory is not None else info.default_trajectory
    d["trajectory"] = None if trajectory is None else file_sha256(trajectory)
    if spec is not None:
        d["dataset"] = {"seed": spec.seed, "sensors": {k: s.to_dict() for k, s in spec.sensors.items()},
                        "gt_rate_hz": spec.evaluation.rate_hz}
    return spec_hash(d)


def default_spec_path() -> Path:
    """The embedded default spec, ``datasets/mini.toml`` of the repository."""
    return DATASETS_DIR / "mini.toml"


# --------------------------------------------------------------------------------------------------------------
# Loading and validation


_TOP_KEYS = ("name", "description", "seed", "output", "sequences", "lux", "sensors", "evaluation")
_SEQ_KEYS = ("name", "scene", "trajectory", "duration_s", "start_s", "resolution", "spp", "max_flow_px",
             "min_rate_hz")
_EVAL_KEYS = ("rate_hz", "methods")
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


class _Errors:
    """Collects one line per problem: ``FILE: field: message``."""

    def __init__(self, path: str):
        self.path = path
        self.lines: list[str] = []

    def add(self, field_path: str, message: str) -> None:
        self.lines.append(f"{self.path}: {field_path}: {message}" if field_path else f"{self.path}: {message}")


def _type_name(v) -> str:
    return {bool: "boolean", int: "integer", float: "number", str: "string", list: "list",
            dict: "table"}.get(type(v), type(v).__name__)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(err: _Errors, where: str, v, *, positive=False, non_negative=False, what="a number"):
    """Return float(v) if valid, else record an error and return None."""
    if not _is_number(v):
        err.add(where, f"got {_type_name(v)} {v!r} (expected {what})")
        return None
    if not math.isfinite(v):
        err.add(where, f"got {v!r} (expected a finite number)")
        return None
    if positive and not v > 0:
        err.add(where, f"must be > 0, got {v!r} (expected {what})")
        return None
    if non_negative and v < 0:
        err.add(where, f"must be ≥ 0, got {v!r} (expected {what})")
        return None
    return float(v)


def load_spec(path) -> DatasetSpec:
    """Read and validate a dataset spec.

    Raises
    ------
    SpecError
        Listing every problem found, one line each, naming the file and the field.
    SimSpadError
        When the file cannot be read.
    """
    path = Path(path)
    display = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SimSpadError("spec file not found", path=display) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SimSpadError(f"cannot read spec file ({exc})", path=display) from None
    err = _Errors(display)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        where = f"line {m.group(1)}" if m else ""
        err.add(where, f"TOML syntax error: {msg} (expected valid TOML)")
        raise SpecError(err.lines, path=display) from None
    spec = _validate(raw, path, err)
    if err.lines:
        raise SpecError(err.lines, path=display)
    return spec


def spec_from_dict(raw: dict, *, source_path=None) -> DatasetSpec:
    """Validate an already-parsed spec document (paths relative to ``source_path``'s folder or the cwd)."""
    path = Path(source_path) if source_path is not None else Path.cwd() / "dataset"
    err = _Errors(str(source_path) if source_path is not None else "<spec>")
    spec = _validate(raw, path, err, source_path is not None)
    if err.lines:
        raise SpecError(err.lines, path=err.path)
    return spec


def _validate(raw: dict, path: Path, err: _Errors, has_file: bool = True) -> DatasetSpec | None:
    base = path.resolve().parent
    for key in raw:
        if key not in _TOP_KEYS:
            err.add(key, f"unknown top-level key (expected one of {', '.join(_TOP_KEYS)})")

    name = raw.get("name", path.stem)
    if not isinstance(name, str) or not name.strip():
        err.add("name", f"got {_type_name(name)} {name!r} (expected a non-empty string)")
        name = path.stem
    description = raw.get("description", "")
    if not isinstance(description, str):
        err.add("description", f"got {_type_name(description)} (expected a string)")

    seed = raw.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        err.add("seed", f"got {_type_name(seed)} {seed!r} (expected an integer ≥ 0)")
        seed = 0

    output = raw.get("output", f"output/{name}")
    if not isinstance(output, str) or not output.strip():
        err.add("output", f"got {_type_name(output)} {output!r} (expected a folder path string)")
        output = f"output/{name}"
    output_path = Path(output).expanduser()
    if not output_path.is_absolute():
        output_path = Path.cwd() / output_path

    lux = _validate_lux(raw, err)
    sequences = _validate_sequences(raw, base, err)
    sensors = _validate_sensors(raw, err)
    evaluation = _validate_evaluation(raw, err)
    if err.lines:
        return None
    return DatasetSpec(name=name, seed=seed, output=output_path, sequences=tuple(sequences), lux=tuple(lux),
                       sensors=sensors, evaluation=evaluation, source_path=path.resolve() if has_file else None,
                       raw=raw)


def _validate_lux(raw: dict, err: _Errors) -> list[float]:
    if "lux" not in raw:
        err.add("lux", "missing (expected a list of illuminances in lux, each > 0)")
        return []
    value = raw["lux"]
    if _is_number(value):
        value = [value]
    if not isinstance(value, list) or not value:
        err.add("lux", f"got {_type_name(value)} {value!r} (expected a non-empty list of numbers > 0)")
        return []
    out = []
    for i, v in enumerate(value):
        x = _number(err, f"lux[{i}]", v, positive=True, what="an illuminance in lux > 0")
        if x is not None:
            if x in out:
                err.add(f"lux[{i}]", f"duplicate lux level {v!r} (expected distinct levels)")
            out.append(x)
    return out


def _validate_sequences(raw: dict, base: Path, err: _Errors) -> list[SequenceSpec]:
    if "sequences" not in raw:
        err.add("sequences", "missing (expected one or more [[sequences]] tables)")
        return []
    value = raw["sequences"]
    if not isinstance(value, list) or not value or not all(isinstance(s, dict) for s in value):
        err.add("sequences", f"got {_type_name(value)} (expected one or more [[sequences]] tables)")
        return []
    out, seen = [], {}
    for i, table in enumerate(value):
        name, seq = _validate_sequence(table, f"sequences[{i}]", base, err)
        if name is not None and name in seen:
            err.add(f"sequences[{i}].name", f"duplicate sequence name {name!r} (also sequences[{seen[name]}]; "
                    "expected unique names: set name = \"...\")")
        elif name is not None:
            seen[name] = i
        if seq is not None:
            out.append(seq)
    return out


def _validate_sequence(t: dict, where: str, base: Path, err: _Errors) -> tuple[str | None, SequenceSpec | None]:
    """(name, spec) of one [[sequences]] table; spec is None after an error (the name still serves to find
    duplicates)."""
    n_errors = len(err.lines)
    for key in t:
        if key not in _SEQ_KEYS:
            err.add(f"{where}.{key}", f"unknown key (expected one of {', '.join(_SEQ_KEYS)})")

    scene = t.get("scene")
    if scene is None:
        err.add(f"{where}.scene", "missing (expected a built-in scene name or a scene folder path)")
    elif not isinstance(scene, str) or not scene.strip():
        err.add(f"{where}.scene", f"got {_type_name(scene)} {scene!r} (expected a scene name string)")
        scene = None
    else:
        scene = _check_scene(scene, base, f"{where}.scene", err)

    name = t.get("name", None)
    if name is None:
        name = Path(scene).name if scene else None
        if name is not None and name.lower().endswith(".xml"):
            name = name[:-4]
        if name is not None:
            name = re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-.") or "sequence"
    elif not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        err.add(f"{where}.name", f"got {_type_name(name)} {name!r} (expected letters, digits, '.', '_' or '-'; it "
                "names files)")
        name = None

    trajectory = t.get("trajectory")
    if trajectory is not None:
        if not isinstance(trajectory, str) or not trajectory.strip():
            err.add(f"{where}.trajectory", f"got {_type_name(trajectory)} {trajectory!r} (expected a file path)")
            trajectory = None
        else:
            found = _find_trajectory(trajectory, base)
            if found is None:
                err.add(f"{where}.trajectory", f"trajectory file {trajectory!r} not found (looked in {base} and "
                        f"{TRAJECTORIES_DIR}; expected an existing .toml, .json, .csv, .txt or .tum file)")
                trajectory = None
            else:
                trajectory = str(found)

    duration = None
    if "duration_s" not in t:
        err.add(f"{where}.duration_s", "missing (expected a duration in seconds > 0)")
    else:
        duration = _number(err, f"{where}.duration_s", t["duration_s"], positive=True,
                           what="a duration in seconds > 0")
    start = _number(err, f"{where}.start_s", t.get("start_s", 0.0), non_negative=True,
                    what="a start time in seconds ≥ 0")

    resolution = t.get("resolution", list(defaults.RESOLUTION_PX))
    if (not isinstance(resolution, list) or len(resolution) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in resolution)):
        err.add(f"{where}.resolution", f"got {resolution!r} (expected two positive integers [W, H])")
        resolution = None

    spp = t.get("spp", defaults.SPP)
    if not isinstance(spp, int) or isinstance(spp, bool) or spp <= 0:
        err.add(f"{where}.spp", f"got {_type_name(spp)} {spp!r} (expected an integer > 0 samples per pixel)")
        spp = None
    max_flow = _number(err, f"{where}.max_flow_px", t.get("max_flow_px", defaults.MAX_FLOW_PX), positive=True,
                       what="pixels > 0")
    min_rate = _number(err, f"{where}.min_rate_hz", t.get("min_rate_hz", defaults.MIN_KEYFRAME_RATE_HZ), positive=True,
                       what="a rate in Hz > 0")
    if len(err.lines) > n_errors or name is None:
        return name, None
    _check_trajectory(trajectory, scene, start, duration, where, err)
    if len(err.lines) > n_errors:
        return name, None
    return name, SequenceSpec(name=name, scene=scene, trajectory=trajectory, duration_s=duration, start_s=start,
                              resolution=(resolution[0], resolution[1]), spp=spp, max_flow_px=max_flow,
                              min_rate_hz=min_rate)


def _check_scene(scene: str, base: Path, where: str, err: _Errors) -> str | None:
    """The scene as the renderer should get it (built-in name or absolute path), or None after an error."""
    local = base / scene
    candidate = str(local.resolve()) if local.exists() else scene
    try:
        from simspad.scenes.library import resolve_scene
    except ImportError:
        # Scene library not importable (partial checkout): accept built-in folders and existing paths.
        if (SCENES_DIR / scene).is_dir() or Path(candidate).exists():
            return candidate
        err.add(where, f"unknown scene {scene!r} (expected a built-in scene name or an existing scene folder)")
        return None
    try:
        resolve_scene(candidate)
    except SimSpadError as exc:
        detail = exc.message
        if exc.path and exc.path not in detail:
            detail = f"{detail} ({exc.path})"
        err.add(where, detail)
        return None
    return candidate


def _check_trajectory(trajectory: str | None, scene: str, start_s: float, duration_s: float, where: str,
                      err: _Errors) -> None:
    """Read the sequence's trajectory (its own or the scene's default) and check it spans the sequence."""
    from simspad.io.trajectory_files import load_trajectory

    field_name = f"{where}.trajectory"
    if trajectory is None:
        try:
            from simspad.scenes.library import resolve_scene

            default = resolve_scene(scene).default_trajectory
        except (ImportError, SimSpadError):
            return
        if default is None:
            return
        trajectory, field_name = str(default), f"{where}.scene (default trajectory)"
    try:
        ts = load_trajectory(trajectory)
    except SimSpadError as exc:
        err.add(field_name, exc.format())
        return
    if not ts.bodies() or ts.is_static:  # a still scene is covered at any time
        return
    t0, t1 = ts.t_start, ts.t_end
    eps = 1e-9 * max(1.0, abs(t1))
    if start_s < t0 - eps or start_s + duration_s > t1 + eps:
        err.add(f"{where}.duration_s", f"the sequence spans {start_s:g}–{start_s + duration_s:g} s but its trajectory "
                f"{Path(trajectory).name} covers {t0:g}–{t1:g} s (expected start_s ≥ {t0:g} and "
                f"start_s + duration_s ≤ {t1:g})")


def _find_trajectory(name: str, base: Path) -> Path | None:
    p = Path(name).expanduser()
    # The spec's folder first, then the repository's trajectories/ (and its root, for "trajectories/x.toml").
    candidates = [p] if p.is_absolute() else [base / p, TRAJECTORIES_DIR / p, REPO_ROOT / p]
    for c in candidates:
        if c.is_file():
            return c.resolve()
    return None


def _validate_sensors(raw: dict, err: _Errors) -> dict[str, SensorSpec]:
    from simspad.sensors.presets import (
        DEFAULT_PRESET,
        PRESETS,
        SENSOR_KINDS,
        sensor_params,
    )

    value = raw.get("sensors")
    if value is None:
        return {k: SensorSpec(k, DEFAULT_PRESET[k], sensor_params(k)) for k in SENSOR_KINDS}
    if not isinstance(value, dict) or not value:
        err.add("sensors", f"got {_type_name(value)} (expected [sensors.spad], [sensors.frames] and/or "
                "[sensors.events] tables)")
        return {}
    out = {}
    for kind, table in value.items():
        where = f"sensors.{kind}"
        if kind not in SENSOR_KINDS:
            err.add(where, f"unknown sensor kind {kind!r} (expected one of {', '.join(SENSOR_KINDS)})")
            continue
        if not isinstance(table, dict):
            err.add(where, f"got {_type_name(table)} (expected a table with preset = \"...\" and overrides)")
            continue
        preset = table.get("preset", DEFAULT_PRESET[kind])
        if not isinstance(preset, str) or preset not in PRESETS[kind]:
            err.add(f"{where}.preset", f"unknown {kind} preset {preset!r} (expected one of "
                    f"{', '.join(PRESETS[kind])})")
            continue
        overrides = {k: v for k, v in table.items() if k != "preset"}
        ok = True
        for field_name, v in overrides.items():
            try:
                sensor_params(kind, preset, {field_name: v})
            except ValueError as exc:
                err.add(f"{where}.{field_name}", str(exc))
                ok = False
        if not ok:
            continue
        try:
            params = sensor_params(kind, preset, overrides)
        except ValueError as exc:
            err.add(where, str(exc))
            continue
        out[kind] = SensorSpec(kind, preset, params, overrides)
    return out


def _validate_evaluation(raw: dict, err: _Errors) -> EvaluationSpec:
    value = raw.get("evaluation", {})
    if not isinstance(value, dict):
        err.add("evaluation", f"got {_type_name(value)} (expected an [evaluation] table)")
        return EvaluationSpec()
    for key in value:
        if key not in _EVAL_KEYS:
            err.add(f"evaluation.{key}", f"unknown key (expected one of {', '.join(_EVAL_KEYS)})")
    rate = _number(err, "evaluation.rate_hz", value.get("rate_hz", defaults.GT_RATE_HZ), positive=True, what="a rate in Hz > 0")
    methods = value.get("methods", [])
    if isinstance(methods, str):
        methods = [methods]
    if not isinstance(methods, list) or not all(isinstance(m, str) for m in methods):
        err.add("evaluation.methods", f"got {methods!r} (expected a list of method names)")
        methods = []
    known = set(KNOWN_METHODS)
    try:  # methods registered beyond the built-in ones (a partial install may lack the registry's modules)
        from simspad.methods.registry import available_methods

        known.update(available_methods())
    except ImportError:
        pass
    for i, m in enumerate(methods):
        if m not in known:
            err.add(f"evaluation.methods[{i}]", f"unknown method {m!r} (expected one of {', '.join(sorted(known))})")
    return EvaluationSpec(rate_hz=rate if rate is not None else defaults.GT_RATE_HZ, methods=tuple(methods))


# --------------------------------------------------------------------------------------------------------------
# Summary


def describe_spec(path) -> str:
    """A readable summary of a spec: sequences, lux levels, sensors with key parameters, evaluation."""
    spec = load_spec(path)
    lines = [f"dataset spec {path}", f"  name        {spec.name}", f"  seed        {spec.seed}",
             f"  output      {spec.output}", f"  spec hash   {spec_hash(spec)[:16]}",
             f"  lux         {', '.join(f'{x:g}' for x in spec.lux)}",
             f"  sequences   {len(spec.sequences)} (× {len(spec.lux)} lux = {len(spec.sequences) * len(spec.lux)} "
             "recordings)"]
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
    """``path`` relative to the current directory or the repository when inside them."""
    p = Path(path)
    for root in (Path.cwd(), REPO_ROOT):
        try:
            return str(p.relative_to(root))
        except ValueError:
            continue
    return str(p)


def _default_trajectory_text(scene: str) -> str:
    from simspad.scenes.library import resolve_scene

    default = resolve_scene(scene).default_trajectory
    return "scene default (static camera)" if default is None else f"scene default ({_short(default)})"


def _overrides_text(overrides: dict) -> str:
    if not overrides:
        return ""
    return " (overrides: " + ", ".join(f"{k}={v!r}" for k, v in overrides.items()) + ")"


def _fmt_time(x) -> str:
    if x == "auto":
        return "auto"
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if abs(x) >= scale:
            return f"{x / scale:.4g} {unit}"
    return f"{x:g} s"


def _key_params(p) -> str:
    kind = getattr(p, "kind", "")
    pitch = f"pitch {p.pixel_pitch_m * 1e6:.4g} µm, fill {p.fill_factor:.3g}, QE {p.qe:.3g}"
    if kind == "spad":
        return (f"{pitch}, bin {_fmt_time(p.bin_s)} ({1 / p.bin_s / 1e3:.4g} kHz), gate {_fmt_time(p.gate_s)}, "
                f"DCR median {p.dcr_median_cps:g} cps, dead time {_fmt_time(p.dead_time_s)}")
    if kind == "frames":
        return (f"{pitch}, {p.frame_rate_hz:g} fps, exposure {_fmt_time(p.exposure_s)}, K {p.gain_dn_per_e:g} DN/e⁻, "
                f"read noise {p.read_noise_e:g} e⁻, full well {p.full_well_e:g} e⁻, {p.bit_depth} bit")
    if kind == "events":
        return (f"{pitch}, thresholds +{p.threshold_on:g}/−{p.threshold_off:g} (σ {p.threshold_sigma:g}), "
                f"refractory {_fmt_time(p.refractory_s)}, latency {_fmt_time(p.latency_s)}")
    return pitch

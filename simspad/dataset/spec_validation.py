"""Loading a dataset spec: TOML in, a validated :class:`~simspad.dataset.spec.DatasetSpec` out.

Every field is checked before any work starts, and every problem is reported, not only the first: one
:class:`~simspad.errors.SpecError` lists them one per line as ``FILE: field.path: what is wrong (expected ...)``.
Scene names are resolved against the scene library, trajectory files are looked up beside the spec and then in
the bundled ``trajectories/``, and each sequence's span must lie within its trajectory's coverage. A field that
a record downstream carries is checked by that record's rule, so it has one message wherever it comes from: a
sequence's render fields by :meth:`simspad.render.settings.RenderSettings.problems`, each lux level by
:func:`simspad.sensors.recording_settings.lux_problem`.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

from simspad import defaults
from simspad.bundled import TRAJECTORIES_DIR, bundled_trajectory_file
from simspad.dataset.limits import spec_limit_problems
from simspad.dataset.spec import DatasetSpec, EvaluationSpec, SensorSpec, SequenceSpec
from simspad.dataset.speed import DEFAULT_SPEEDS, coverage_problem
from simspad.errors import SimSpadError, SpecError
from simspad.render.settings import DEFAULT_CACHE_SAMPLES, DEFAULT_CONVERGENCE, DEFAULT_INTERPOLATION, RenderSettings
from simspad.io.trajectory_files import load_trajectory
from simspad.methods.registry import available_methods, check_method_params
from simspad.scenes.library import resolve_scene
from simspad.sensors.presets import DEFAULT_PRESET, PRESETS, SENSOR_KINDS, override_problem, sensor_params
from simspad.sensors.recording_settings import lux_problem

_TOP_KEYS = ("name", "description", "seed", "output", "sequences", "lux", "sensors", "evaluation", "speed")
_SEQ_KEYS = ("name", "scene", "trajectory", "duration_s", "start_s", "resolution", "spp", "max_flow_px",
             "min_rate_hz", "interpolation", "convergence", "cache_samples")
_EVAL_KEYS = ("rate_hz", "methods", "params")
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_MAX_NAME_CHARS = 100  # names become file names (255 bytes at most, with suffixes)
#: RenderSettings' names of the sequence fields it calls otherwise
_SETTINGS_FIELD = {"duration": "duration_s", "start": "start_s"}


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

    name = raw.get("name", re.sub(r"[^A-Za-z0-9._-]+", "-", path.stem).strip("-.") or "dataset")
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name) or len(name) > _MAX_NAME_CHARS:
        err.add("name", f"got {_type_name(name)} {str(name)[:80]!r} (expected up to {_MAX_NAME_CHARS} letters, digits, "
                "'.', '_' or '-', not starting with '.' or '-'; it names the output folder)")
        name = re.sub(r"[^A-Za-z0-9._-]+", "-", path.stem).strip("-.") or "dataset"
    description = raw.get("description", "")
    if not isinstance(description, str):
        err.add("description", f"got {_type_name(description)} (expected a string)")

    seed = raw.get("seed", defaults.SEED)
    if problem := defaults.seed_problem(seed):  # the render and recording settings' rule
        err.add("seed", problem)
        seed = defaults.SEED

    output = raw.get("output", f"output/{name}")
    if not isinstance(output, str) or not output.strip():
        err.add("output", f"got {_type_name(output)} {output!r} (expected a folder path string)")
        output = f"output/{name}"
    output_path = Path(output).expanduser()
    if not output_path.is_absolute():
        if ".." in output_path.parts:
            # A relative output stays below the current directory: a spec (perhaps someone else's) must not walk
            # out of it; a folder elsewhere is named explicitly, by an absolute `output` or by --out.
            err.add("output", f"{output!r} leaves the current directory (a relative output may not contain '..'; "
                              "give an absolute path or --out to write elsewhere)")
        output_path = Path.cwd() / output_path

    lux = _validate_lux(raw, err)
    speed = _validate_speed(raw, err)
    sequences = _validate_sequences(raw, base, err)
    _check_speed_coverage(sequences, speed, err)
    sensors = _validate_sensors(raw, err)
    evaluation = _validate_evaluation(raw, err)
    if err.lines:
        return None
    spec = DatasetSpec(name=name, seed=seed, output=output_path, sequences=tuple(sequences), lux=tuple(lux),
                       sensors=sensors, evaluation=evaluation, source_path=path.resolve() if has_file else None,
                       raw=raw, speed=tuple(speed))
    for field_path, message in spec_limit_problems(spec):  # bounds and cross-field rules, before any work
        err.add(field_path, message)
    return spec


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
        problem = lux_problem(v)  # the recording settings' own rule and message
        if problem:
            err.add(f"lux[{i}]", problem)
            continue
        if float(v) in out:
            err.add(f"lux[{i}]", f"duplicate lux level {v!r} (expected distinct levels)")
        out.append(float(v))
    return out


def _validate_speed(raw: dict, err: _Errors) -> list[float]:
    """The speed factors (default [1.0]), checked like ``lux``: a number or a non-empty list of distinct
    numbers > 0."""
    value = raw.get("speed", list(DEFAULT_SPEEDS))
    if _is_number(value):
        value = [value]
    if not isinstance(value, list) or not value:
        err.add("speed", f"got {_type_name(value)} {value!r} (expected a non-empty list of speed factors > 0)")
        return []
    out = []
    for i, v in enumerate(value):
        x = _number(err, f"speed[{i}]", v, positive=True, what="a speed factor > 0 (1: the trajectory as written)")
        if x is not None:
            if x in out:
                err.add(f"speed[{i}]", f"duplicate speed factor {v!r} (expected distinct factors)")
            out.append(x)
    return out


def _check_speed_coverage(sequences: list[SequenceSpec], speeds: list[float], err: _Errors) -> None:
    """Every sequence played at every speed factor must stay within its trajectory's coverage."""
    for seq in sequences:
        for k in speeds:
            problem = coverage_problem(seq.scene, seq.trajectory, seq.start_s, seq.duration_s, k)
            if problem is not None:
                err.add("speed", f"sequence {seq.name!r}: {problem}")


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
    elif not isinstance(name, str) or not _NAME_RE.fullmatch(name) or len(name) > _MAX_NAME_CHARS:
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

    if "duration_s" not in t:
        err.add(f"{where}.duration_s", "missing (expected a duration in seconds > 0)")
    start = t.get("start_s", 0.0)
    if _is_number(start) and math.isfinite(start) and start < 0:  # the spec's own rule: trajectory time ≥ 0
        err.add(f"{where}.start_s", f"must be ≥ 0, got {start!r} (expected a start time in seconds ≥ 0)")
    values = {"duration_s": t.get("duration_s"), "start_s": start,
              "resolution": t.get("resolution", list(defaults.RESOLUTION_PX)), "spp": t.get("spp", defaults.SPP),
              "max_flow_px": t.get("max_flow_px", defaults.MAX_FLOW_PX),
              "min_rate_hz": t.get("min_rate_hz", defaults.MIN_KEYFRAME_RATE_HZ),
              "interpolation": t.get("interpolation", DEFAULT_INTERPOLATION),
              "convergence": t.get("convergence", DEFAULT_CONVERGENCE),
              "cache_samples": t.get("cache_samples", DEFAULT_CACHE_SAMPLES)}
    # The render settings' own checks, bounds included: one rule and one message per field, for a spec as for
    # `simspad render` (a missing duration is reported above).
    for field_name, message in RenderSettings(**values, gt_rate_hz=None).problems():
        field_name = _SETTINGS_FIELD.get(field_name, field_name)
        if field_name in values and not (field_name == "duration_s" and "duration_s" not in t):
            err.add(f"{where}.{field_name}", message)
    if len(err.lines) > n_errors or name is None:
        return name, None
    duration, start = float(values["duration_s"]), float(start)
    _check_trajectory(trajectory, scene, start, duration, where, err)
    if len(err.lines) > n_errors:
        return name, None
    w, h = values["resolution"]
    return name, SequenceSpec(name=name, scene=scene, trajectory=trajectory, duration_s=duration, start_s=start,
                              resolution=(w, h), spp=values["spp"], max_flow_px=float(values["max_flow_px"]),
                              min_rate_hz=float(values["min_rate_hz"]), interpolation=values["interpolation"],
                              convergence=values["convergence"], cache_samples=values["cache_samples"])


def _check_scene(scene: str, base: Path, where: str, err: _Errors) -> str | None:
    """The scene as the renderer should get it (built-in name or absolute path), or None after an error."""
    local = base / scene
    candidate = str(local.resolve()) if local.exists() else scene
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
    field_name = f"{where}.trajectory"
    if trajectory is None:
        try:
            default = resolve_scene(scene).default_trajectory
        except SimSpadError:
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
    # The spec's folder first, then the bundled trajectories/ ("x.toml" or "trajectories/x.toml").
    if p.is_absolute():
        return p.resolve() if p.is_file() else None
    if (base / p).is_file():
        return (base / p).resolve()
    bundled = bundled_trajectory_file(p)
    return bundled.resolve() if bundled is not None else None


def _validate_sensors(raw: dict, err: _Errors) -> dict[str, SensorSpec]:
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
        for field_name, v in overrides.items():  # each field by the parameter record's own rule
            if problem := override_problem(kind, field_name, v):
                err.add(f"{where}.{field_name}", problem)
                ok = False
        if not ok:
            continue
        try:  # then the rules between fields (a gate within [min_gate_s, bin_s], …)
            params = sensor_params(kind, preset, overrides)
        except SimSpadError as exc:
            err.add(exc.field, exc.message)
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
    rate = value.get("rate_hz", defaults.GT_RATE_HZ)
    if problem := defaults.gt_rate_problem(rate):  # the render and recording settings' rule
        err.add("evaluation.rate_hz", problem)
        rate = None
    methods = value.get("methods", [])
    if isinstance(methods, str):
        methods = [methods]
    if not isinstance(methods, list) or not all(isinstance(m, str) for m in methods):
        err.add("evaluation.methods", f"got {methods!r} (expected a list of method names)")
        methods = []
    known = set(available_methods())
    for i, m in enumerate(methods):
        if m not in known:
            err.add(f"evaluation.methods[{i}]", f"unknown method {m!r} (expected one of {', '.join(sorted(known))})")
    params = {}
    raw_params = value.get("params", {})
    if not isinstance(raw_params, dict):
        err.add("evaluation.params", f"got {_type_name(raw_params)} (expected [evaluation.params.METHOD] tables)")
        raw_params = {}
    for m, p in raw_params.items():
        if m not in known:
            err.add(f"evaluation.params.{m}", f"unknown method (expected one of {', '.join(sorted(known))})")
            continue
        try:
            checked = check_method_params(m, p, field="evaluation.params")
        except SimSpadError as exc:
            err.add(exc.field or f"evaluation.params.{m}", exc.message)
            continue
        if checked:
            params[m] = checked
    return EvaluationSpec(rate_hz=float(rate) if rate is not None else defaults.GT_RATE_HZ, methods=tuple(methods),
                          params=params)

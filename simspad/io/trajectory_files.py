"""Trajectory files: reading and writing a :class:`~simspad.motion.trajectory.TrajectorySet`.

Formats (chosen by the file suffix):

- ``.toml`` / ``.json`` — ``[camera]`` and ``[objects.<id>]`` tables, each either ``keyframes = [{t, position,
  quaternion_xyzw} | {t, look_at = {origin, target, up}}, ...]`` or ``generator = "<name>"`` plus the
  generator's parameters (see :data:`simspad.io.trajectory_tables.GENERATORS`).
- ``.csv`` — header ``t,tx,ty,tz,qx,qy,qz,qw`` with an optional ``body`` column (``camera`` or an object id).
- ``.txt`` / ``.tum`` — the TUM RGB-D format ``t tx ty tz qx qy qz qw`` (whitespace separated, ``#`` comments);
  its absolute (epoch) timestamps are rebased to start at 0 and the offset is kept in
  :attr:`~simspad.motion.trajectory.TrajectorySet.time_offset_s`.
"""

from __future__ import annotations

import csv
import io
import json
import tomllib
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.atomic import atomic_path
from simspad.io.trajectory_tables import trajectory_set_from_document
from simspad.motion.trajectory import CAMERA_BODY, Trajectory, TrajectorySet, check_keyframes

TUM_SUFFIXES = (".txt", ".tum")
_CSV_COLUMNS = ("t", "tx", "ty", "tz", "qx", "qy", "qz", "qw")


# --------------------------------------------------------------------------------------------------------------
# Loading


def load_trajectory(path, *, rebase: bool | None = None) -> TrajectorySet:
    """Read a trajectory file (format from the suffix; see the module docstring).

    Parameters
    ----------
    path : str or Path
    rebase : bool, optional
        Shift times so the earliest keyframe is at t = 0 (the shift is kept in ``time_offset_s``). Default:
        True for TUM files (their timestamps are epoch seconds), False otherwise.

    Raises
    ------
    InputError
        Unreadable or malformed file; the message names the file and the line or field.
    """
    path = Path(path)
    source = str(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json", ".csv") + TUM_SUFFIXES:
        raise InputError(f"unknown trajectory format {path.suffix!r} (expected .toml, .json, .csv, .txt or .tum)",
                         path=source)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("trajectory file not found", path=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read trajectory file ({exc})", path=source) from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"invalid TOML: {exc}", path=source) from None
        ts = trajectory_set_from_document(doc, source)
    elif suffix == ".json":
        try:
            doc = json.loads(text)
        except RecursionError:
            raise InputError("JSON nested too deeply (expected camera/objects tables)", path=source) from None
        except json.JSONDecodeError as exc:
            raise InputError(f"invalid JSON: {exc.msg}", path=source, field=f"line {exc.lineno}") from None
        if not isinstance(doc, dict):
            raise InputError("expected a JSON object with 'camera' and/or 'objects'", path=source)
        ts = trajectory_set_from_document(doc, source)
    elif suffix == ".csv":
        ts = _from_csv(text, source)
    else:
        ts = _from_tum(text, source)
    if rebase is None:
        rebase = suffix in TUM_SUFFIXES
    return _rebased(ts) if rebase else ts


def _rebased(ts: TrajectorySet) -> TrajectorySet:
    bodies = ts.bodies()
    if not bodies:
        return ts
    offset = min(tr.t_start for tr in bodies.values())
    if offset == 0.0:
        return ts

    def shift(tr: Trajectory) -> Trajectory:
        return Trajectory(tr.times_s - offset, tr.positions_m, tr.quaternions_xyzw, source=tr.source)

    return TrajectorySet(None if ts.camera is None else shift(ts.camera),
                         {k: shift(v) for k, v in ts.objects.items()}, ts.source, ts.time_offset_s + offset)


def _from_csv(text: str, source: str) -> TrajectorySet:
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty CSV (expected a header t,tx,ty,tz,qx,qy,qz,qw and rows)", path=source)
    header_lineno, header_line = lines[0]
    header = [h.strip() for h in next(csv.reader([header_line]))]
    missing = [c for c in _CSV_COLUMNS if c not in header]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)} (expected header t,tx,ty,tz,qx,qy,qz,qw "
                         "[,body])", path=source, field=f"line {header_lineno}")
    unknown = [c for c in header if c not in _CSV_COLUMNS + ("body",)]
    if unknown:
        raise InputError(f"unknown column(s) {', '.join(unknown)} (expected t,tx,ty,tz,qx,qy,qz,qw [,body])",
                         path=source, field=f"line {header_lineno}")
    index = {c: header.index(c) for c in header}
    per_body: dict[str, list[tuple[int, list[float]]]] = {}
    for lineno, line in lines[1:]:
        cells = [c.strip() for c in next(csv.reader([line]))]
        if len(cells) != len(header):
            raise InputError(f"{len(cells)} values (expected {len(header)}: {','.join(header)})", path=source,
                             field=f"line {lineno}")
        body = cells[index["body"]] if "body" in index else CAMERA_BODY
        if not body:
            raise InputError("empty body name", path=source, field=f"line {lineno}")
        values = []
        for c in _CSV_COLUMNS:
            try:
                values.append(_strict_float(cells[index[c]]))
            except ValueError:
                raise InputError(f"column {c}: {cells[index[c]]!r} is not a number", path=source,
                                 field=f"line {lineno}") from None
        per_body.setdefault(body, []).append((lineno, values))
    if not per_body:
        raise InputError("no data rows (expected at least 2 per body)", path=source)
    bodies = {name: _body_from_rows(rows, source, name) for name, rows in per_body.items()}
    camera = bodies.pop(CAMERA_BODY, None)
    return TrajectorySet(camera, bodies, source)


def _from_tum(text: str, source: str) -> TrajectorySet:
    rows = []
    for i, line in enumerate(text.splitlines()):
        stripped = line.split("#", 1)[0].strip()
        if not stripped:
            continue
        cells = stripped.replace(",", " ").split()
        if len(cells) != 8:
            raise InputError(f"{len(cells)} values (expected 8: t tx ty tz qx qy qz qw)", path=source,
                             field=f"line {i + 1}")
        try:
            rows.append((i + 1, [_strict_float(c) for c in cells]))
        except ValueError:
            bad = next(c for c in cells if not _is_float(c))
            raise InputError(f"{bad!r} is not a number (expected t tx ty tz qx qy qz qw)", path=source,
                             field=f"line {i + 1}") from None
    if not rows:
        raise InputError("no poses (expected lines 't tx ty tz qx qy qz qw')", path=source)
    return TrajectorySet(_body_from_rows(rows, source, CAMERA_BODY), {}, source)


def _strict_float(s: str) -> float:
    """``float(s)`` without Python's digit separators: ``1_0`` is a typo in a data file, not 10."""
    if "_" in s:
        raise ValueError(s)
    return float(s)


def _is_float(s: str) -> bool:
    try:
        _strict_float(s)
    except ValueError:
        return False
    return True


def _body_from_rows(rows: list[tuple[int, list[float]]], source: str, body: str) -> Trajectory:
    if len(rows) < 2:
        raise InputError(f"{len(rows)} pose(s) for body {body!r} (expected at least 2)", path=source,
                         field=f"line {rows[0][0]}")
    data = np.array([v for _, v in rows], dtype=np.float64)
    labels = [f"line {n}" for n, _ in rows]
    check_keyframes(data[:, 0], data[:, 1:4], data[:, 4:8], source, labels)
    return Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8], source=f"{source}:{body}")


# --------------------------------------------------------------------------------------------------------------
# Saving


def save_trajectory(ts: TrajectorySet, path) -> Path:
    """Write ``ts`` as TOML or JSON keyframes, CSV or TUM, chosen by the suffix of ``path``.

    The file is written atomically. TUM holds only a camera; its times are written with ``time_offset_s``
    added back. Numbers are written with full float64 precision (``repr``), so reading back is exact.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        text = _to_toml(ts)
    elif suffix == ".json":
        text = json.dumps(_to_document(ts), indent=1) + "\n"
    elif suffix == ".csv":
        text = _to_csv(ts)
    elif suffix in TUM_SUFFIXES:
        if ts.camera is None or ts.objects:
            raise InputError("the TUM format holds exactly one (camera) trajectory (use .toml, .json or .csv for "
                             "objects)", path=path)
        text = "# timestamp tx ty tz qx qy qz qw\n" + "".join(
            f"{_f(t + ts.time_offset_s)} {' '.join(_f(v) for v in p)} {' '.join(_f(v) for v in q)}\n"
            for t, p, q in zip(ts.camera.times_s, ts.camera.positions_m, ts.camera.quaternions_xyzw))
    else:
        raise InputError(f"unknown trajectory format {path.suffix!r} (expected .toml, .json, .csv, .txt or .tum)",
                         path=path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def _f(x: float) -> str:
    return repr(float(x))


def _keyframes(tr: Trajectory) -> list[dict]:
    return [{"t": float(t), "position": [float(v) for v in p], "quaternion_xyzw": [float(v) for v in q]}
            for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw)]


def _to_document(ts: TrajectorySet) -> dict:
    doc: dict = {"format": "simspad-trajectory"}
    if ts.time_offset_s:
        doc["time_offset_s"] = ts.time_offset_s
    if ts.camera is not None:
        doc["camera"] = {"keyframes": _keyframes(ts.camera)}
    if ts.objects:
        doc["objects"] = {k: {"keyframes": _keyframes(v)} for k, v in ts.objects.items()}
    return doc


def _to_toml(ts: TrajectorySet) -> str:
    out = ['format = "simspad-trajectory"']
    if ts.time_offset_s:
        out.append(f"time_offset_s = {_f(ts.time_offset_s)}")

    def table(header: str, tr: Trajectory) -> None:
        out.append(f"\n[{header}]\nkeyframes = [")
        for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            out.append(f"  {{ t = {_f(t)}, position = [{', '.join(map(_f, p))}], "
                       f"quaternion_xyzw = [{', '.join(map(_f, q))}] }},")
        out.append("]")

    if ts.camera is not None:
        table("camera", ts.camera)
    for name, tr in ts.objects.items():
        table(f"objects.{json.dumps(name)}", tr)
    return "\n".join(out) + "\n"


def _to_csv(ts: TrajectorySet) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")  # quotes body names that hold commas
    writer.writerow(_CSV_COLUMNS + ("body",))
    for name, tr in ts.bodies().items():
        for t, p, q in zip(tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            writer.writerow([_f(t), *map(_f, p), *map(_f, q), name])
    return buf.getvalue()

"""The recordings to evaluate: a recording file, a dataset directory (``manifest.json``) or a directory of
``.h5`` files, each named by a key (``<sequence>_<lux>lx``) in results and submissions.

The manifest is read by :func:`simspad.io.manifest.read_manifest` (the one reader, as ``generate`` uses), every
path in it is confined to the dataset folder, and each complete recording's size and sha256 are verified
against the manifest before it is scored. A recording the manifest lists twice is refused before any hash is
computed, two recordings with one key (their results would overwrite each other) once their attributes are read,
and a folder's ``.h5`` linked out of the folder is not read. Reading many recordings shows a progress bar on
stderr after 2 s (:class:`QuietBar`: no monitor thread, so evaluate's workers can still be forked).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from simspad.errors import SimSpadError
from simspad.io.manifest import MANIFEST_NAME, recording_mismatch
from simspad.io.manifest import read_manifest as read_dataset_manifest
from simspad.io.names import recording_key
from simspad.io.recording import open_recording
from simspad.io.safe_paths import confined_path


class QuietBar(tqdm):
    """A progress bar without tqdm's monitor thread: bars shown before evaluate's pool starts must not make
    forking its workers unsafe (:func:`simspad.evaluate.evaluate._start_method`)."""

    monitor_interval = 0


@dataclass
class RecordingEntry:
    """A recording to evaluate: its path and the key naming it in results and submissions."""

    path: Path
    rel: str
    sequence: str = ""
    scene: str = ""
    lux: float = float("nan")
    key: str = ""
    extra: dict = field(default_factory=dict)
    speed_factor: float = 1.0
    """The recording's ``speed_factor`` root attribute (1 for recordings made before the speed axis)."""
    image_speed_px_s: float = float("nan")
    """The recording's ``image_speed_px_s_p50`` root attribute: median image motion (px/s); NaN when absent."""
    about: dict = field(default_factory=dict)
    """What the recording is, for the leaderboard's description of itself (:func:`recording_about`)."""

    def summary(self, **extra) -> dict:
        """The recording's entry in ``results.json``'s ``recordings`` list (``simspad evaluate`` and ``simspad
        score`` alike): key, sequence, scene, lux, speed, what it is (:attr:`about`), then ``extra`` (evaluate's
        ``ground_truth`` and ``preview``)."""
        return {"recording": self.rel, "key": self.key, "sequence": self.sequence, "scene": self.scene,
                "lux": self.lux, "speed_factor": self.speed_factor, "image_speed_px_s": self.image_speed_px_s,
                **self.about, **extra}


def read_manifest(dataset_dir: Path) -> dict | None:
    """The dataset's ``manifest.json`` checked by the one manifest reader (:func:`simspad.io.manifest.read_manifest`:
    format, version, relative paths); None when the folder has none."""
    if not (dataset_dir / MANIFEST_NAME).is_file():
        return None
    return read_dataset_manifest(dataset_dir)


def list_recordings(target: Path, progress: bool = True) -> tuple[list[RecordingEntry], dict | None]:
    """The recordings of ``target`` (a ``.h5`` file, a dataset directory with ``manifest.json``, or a
    directory of ``.h5`` files) and the manifest (or None). Manifest entries whose status is not
    ``complete`` are skipped; one listed twice is refused. ``progress``: a bar on stderr while the manifest's
    hashes are checked, once that takes more than 2 s."""
    target = Path(target)
    if target.is_file():
        return [RecordingEntry(target, target.name)], None
    if not target.is_dir():
        raise SimSpadError("no such recording file or dataset directory", path=target)
    manifest = read_manifest(target)
    entries = _manifest_entries(target, manifest, progress) if manifest is not None else _found_entries(target)
    if not entries:
        raise SimSpadError("no complete recordings to evaluate", path=target)
    return entries, manifest


def _manifest_entries(target: Path, manifest: dict, progress: bool = False) -> list[RecordingEntry]:
    listed: list[tuple[int, dict, Path]] = []
    seen: dict[Path, int] = {}
    for i, r in enumerate(manifest["recordings"]):  # every path checked, and duplicates refused, before hashing
        if not isinstance(r, dict) or not isinstance(r.get("path"), str):
            raise SimSpadError("each recording needs a 'path' string", path=target / MANIFEST_NAME,
                               field=f"recordings[{i}].path")
        if r.get("status", "complete") != "complete":
            continue
        path = confined_path(target, r["path"], source=target / MANIFEST_NAME, field=f"recordings[{i}].path")
        first = seen.setdefault(path.resolve(), i)
        if first != i:
            raise SimSpadError(f"{r['path']!r} is the recording recordings[{first}] already lists (each recording "
                               "is listed once)", path=target / MANIFEST_NAME, field=f"recordings[{i}].path")
        listed.append((i, r, path))
    entries = []
    for i, r, path in QuietBar(listed, desc="checking hashes", unit="rec", file=sys.stderr, delay=2.0,
                           disable=not progress, leave=False):
        problem = recording_mismatch(target, r)
        if problem:
            raise SimSpadError(f"{problem}: changed or corrupt since it was generated (re-run simspad generate to "
                               "redo it)", path=path, field=f"manifest recordings[{i}]")
        entries.append(RecordingEntry(path, r["path"], extra=r))
    return entries


def _found_entries(target: Path) -> list[RecordingEntry]:
    """Every ``.h5`` below ``target`` except temporary files, saved reconstructions and render caches."""
    entries = []
    results_dirs = {d.parent for d in target.rglob("results.json")}
    for p in sorted(target.rglob("*.h5")):
        parts = p.relative_to(target).parts
        if any(part.startswith(".") for part in parts):
            continue  # temporary files of atomic writes
        if any(parent in results_dirs for parent in p.parents) or "renders" in parts[:-1]:
            continue  # saved reconstructions of an earlier evaluation, render caches
        rel = p.relative_to(target).as_posix()
        confined_path(target, rel, source=target, field="recording")  # a link out of the folder is not read
        entries.append(RecordingEntry(p, rel))
    return entries


def _attr_float(attrs, name: str, default: float, path: Path) -> float:
    """A numeric root attribute, ``default`` when absent; SimSpadError naming it when it is not a number."""
    if name not in attrs:
        return default
    try:
        return float(attrs[name])
    except (TypeError, ValueError):
        raise SimSpadError(f"expected a number, got {attrs[name]!r}", path=path, field=f"/ (attribute {name})") \
            from None


def fill_entries(entries: list[RecordingEntry], progress: bool = True) -> list[RecordingEntry]:
    """:func:`fill_entry` each (a bar on stderr once that takes more than 2 s), then :func:`check_unique_keys`."""
    entries = [fill_entry(e) for e in QuietBar(entries, desc="reading recordings", unit="rec", file=sys.stderr,
                                               delay=2.0, disable=not progress, leave=False)]
    check_unique_keys(entries)
    return entries


def check_unique_keys(entries: list[RecordingEntry]) -> None:
    """Refuse two recordings with one key (sequence, lux, speed): their images and reconstructions would
    overwrite each other in the results directory."""
    seen: dict[str, RecordingEntry] = {}
    for e in entries:
        other = seen.setdefault(e.key, e)
        if other is not e:
            raise SimSpadError(f"has the key {e.key!r} (sequence, lux, speed) of {other.path} too: their results "
                               "would overwrite each other (evaluate them separately)", path=e.path)


def fill_entry(entry: RecordingEntry) -> RecordingEntry:
    """Read sequence, scene, lux and the speed attributes from the recording's attributes (validating the file)."""
    with open_recording(entry.path) as rec:
        if rec.has("events"):
            rec.events.check_time_order()  # methods find event windows by binary search on the timestamps
        entry.sequence = str(rec.attrs.get("sequence") or entry.extra.get("sequence") or rec.scene
                             or Path(entry.rel).stem)
        entry.scene = str(rec.scene or entry.extra.get("scene") or entry.sequence)
        entry.lux = float(rec.lux)
        entry.speed_factor = _attr_float(rec.attrs, "speed_factor", 1.0, entry.path)
        entry.image_speed_px_s = _attr_float(rec.attrs, "image_speed_px_s_p50", float("nan"), entry.path)
        entry.about = recording_about(rec)
    entry.key = recording_key(entry.sequence, entry.lux, entry.speed_factor)
    return entry


def recording_about(rec) -> dict:
    """Resolution, duration, seed, dataset name and render settings (spp, keyframe spacing) of a recording, from
    its root attributes and spec; keys whose value the recording does not state are left out."""
    attrs = rec.attrs
    out = {"width": int(rec.width), "height": int(rec.height)}
    for name, kind in (("duration_s", float), ("seed", int), ("dataset", str), ("gt_rate_hz", float)):
        try:
            if name in attrs:
                out[name] = kind(attrs[name])
        except (TypeError, ValueError):
            pass
    spec = rec.spec if isinstance(rec.spec, dict) else {}
    seq = spec.get("sequence") if isinstance(spec.get("sequence"), dict) else {}
    for name in ("spp", "max_flow_px", "min_rate_hz", "interpolation"):
        v = seq.get(name)
        if isinstance(v, (int, float, str)) and not isinstance(v, bool):
            out[name] = v
    # the radiance's convergence: how it was rendered, and the render noise its budget measured (docs/format.md)
    convergence = seq.get("convergence", "off" if "spp" in out else None)
    if isinstance(convergence, str):
        out["convergence"] = convergence
    try:
        noise = float(attrs["render_noise_relative"]) if "render_noise_relative" in attrs else None
    except (TypeError, ValueError):
        noise = None
    if noise is not None and noise == noise:
        out["render_noise_relative"] = noise
    return out


def spec_evaluation(manifest: dict | None, entry: RecordingEntry | None) -> dict:
    """The ``evaluation`` table of the dataset spec (from the manifest, else from the recording; {} if none)."""
    spec = (manifest or {}).get("spec")
    if not isinstance(spec, dict) and entry is not None:
        with open_recording(entry.path) as rec:
            spec = rec.spec
    ev = (spec or {}).get("evaluation", {}) if isinstance(spec, dict) else {}
    return ev if isinstance(ev, dict) else {}

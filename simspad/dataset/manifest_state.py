"""The manifest of a run in progress: one entry per render and recording, rewritten atomically on every change.

The driver process is the only writer of ``manifest.json``. Entries of the previous manifest whose hash is unchanged
keep their status, size and sha256, so a resumed run knows what is already done; the ``created_utc`` of a dataset is
kept across runs (or pinned by ``$SOURCE_DATE_EPOCH``) so re-running or resuming changes no file's bytes.
"""

from __future__ import annotations

from pathlib import Path

from simspad import __version__
from simspad.dataset.plan import DatasetPlan, scene_name
from simspad.dataset.spec_hashing import spec_hash
from simspad.io.manifest import (
    FORMAT,
    VERSION,
    manifest_path,
    read_manifest,
    write_manifest,
)
from simspad.io.provenance import source_date_epoch, utc_now


def dataset_created_utc(previous: dict | None, override: str | None) -> str:
    if override:
        return override
    pinned = source_date_epoch()
    if pinned:
        return pinned
    if previous and isinstance(previous.get("created_utc"), str):
        return previous["created_utc"]
    return utc_now()


def load_previous_manifest(out_dir: Path) -> dict | None:
    if not manifest_path(out_dir).exists():
        return None
    return read_manifest(out_dir)  # InputError for a foreign or corrupt manifest: do not overwrite someone's data


class ManifestState:
    """The manifest being built: entries keyed by path, rewritten atomically on every change."""

    def __init__(self, out_dir: Path, spec, plan: DatasetPlan, created_utc: str, previous: dict | None):
        self.out_dir = out_dir
        old = {e["path"]: e for e in (previous or {}).get("recordings", [])}
        old_renders = {e.get("path"): e for e in (previous or {}).get("renders", []) if isinstance(e, dict)}
        self.data = {"format": FORMAT, "version": VERSION, "name": spec.name, "spec": spec.to_dict(),
                     "spec_hash": spec_hash(spec), "seed": spec.seed, "created_utc": created_utc,
                     "updated_utc": utc_now(), "simspad_version": __version__,
                     "source": str(spec.source_path) if spec.source_path else None,
                     "recordings": [], "renders": []}
        self.rec = {}
        for task in plan.recordings:
            entry = {"sequence": task.sequence_name, "scene": task.scene, "speed_factor": task.speed_factor,
                     "lux": task.lux, "path": task.rel_path,
                     "size": None, "sha256": None, "status": "pending", "recording_hash": task.recording_hash,
                     "render": task.render_rel_dir, "timings": {}}
            prev = old.get(task.rel_path)
            if prev and prev.get("recording_hash") == task.recording_hash and prev.get("status") == "complete":
                for key in ("size", "sha256", "status", "timings"):
                    entry[key] = prev.get(key)
                if "motion" in prev:  # the measured image motion (simspad.render.image_motion) of a kept file
                    entry["motion"] = prev["motion"]
            self.rec[task.rel_path] = entry
            self.data["recordings"].append(entry)
        self.ren = {}
        for task in plan.renders:
            prev = old_renders.get(task.rel_dir) or {}
            entry = {"sequence": task.sequence.name, "scene": scene_name(task.sequence.scene),
                     "speed_factor": task.speed_factor, "path": task.rel_dir,
                     "render_hash": task.render_hash, "status": prev.get("status", "pending"),
                     "n_keyframes": prev.get("n_keyframes"), "timings": prev.get("timings", {})}
            self.ren[task.rel_dir] = entry
            self.data["renders"].append(entry)
        self.obsolete_recordings = [p for p in old if p not in self.rec]
        self.obsolete_renders = [p for p in old_renders if p not in self.ren]

    def save(self) -> None:
        self.data["updated_utc"] = utc_now()
        write_manifest(self.out_dir, self.data)

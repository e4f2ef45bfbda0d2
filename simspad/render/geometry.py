"""Geometry passes at the ground-truth instants: depth and instance ids at the pixel centres, with the camera's and
every animated object's pose and velocity at each instant (docs/format.md, section 2, ``geometry``).

The ground-truth rate reaches the renderer as a render setting (:attr:`RenderSettings.gt_rate_hz`; the renderer
knows no sensor). :func:`plan_geometry` lists the instants (:func:`simspad.io.geometry.gt_times` over the
rendered span), their poses and cache-keyed file names; each instant belongs to the keyframe at or before it
(:func:`geometry_owners`), so whichever process renders a run of keyframes renders their instants too, and a
re-run re-uses every pass already on disk. A pass is one unjittered sample per pixel through the depth + shape
AOV integrator (its cost: docs/performance.md, "Where a dataset's time goes").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simspad.io.geometry import GEOMETRY_DIR, geometry_is_intact, geometry_names, gt_times, write_geometry
from simspad.motion.trajectory import TrajectorySet
from simspad.render.flow import camera_poses, object_poses
from simspad.render.mitsuba_scene import MitsubaScene

#: Bumped when a geometry pass's pixels for given inputs would change: part of every pass's cache key.
GEOMETRY_VERSION = 2  # 2: unnamed shapes numbered by what they are, not by bounding box alone


def _velocity(tr, t: float) -> list[float]:
    if tr is None:
        return [0.0] * 6
    v, w = tr.velocity(float(t))
    return [float(x) for x in (*np.ravel(v), *np.ravel(w))]


def plan_geometry(ts: TrajectorySet, ms: MitsubaScene, t0: float, t1: float, rate_hz: float,
                  base_key: dict) -> dict | None:
    """The ``geometry`` block of ``timeline.json``: instants on the ground-truth grid of ``[t0, t1]`` with their
    files, camera pose and velocity, and every animated object's pose and velocity; None when ``rate_hz`` is
    None or the variant cannot name shapes (no instance ids, so no motion of objects either)."""
    if rate_hz is None or not ms.names_instances:
        return None
    times = gt_times(t0, t1, float(rate_hz))
    key = dict(base_key, geometry=GEOMETRY_VERSION, rate_hz=float(rate_hz))
    names = geometry_names(key, times)
    cams = camera_poses(ts, ms.rest_camera_to_world, times)
    instants = []
    for t, name, cam in zip(times, names, cams):
        inst = {"t": float(t), "file": name, "camera_to_world": cam.tolist(),
                "camera_velocity": _velocity(ts.camera, t)}
        if ts.objects:
            inst["object_to_world"] = {k: m.tolist() for k, m in sorted(object_poses(ts, float(t)).items())}
            inst["object_velocity"] = {k: _velocity(tr, t) for k, tr in sorted(ts.objects.items())}
        instants.append(inst)
    return {"rate_hz": float(rate_hz), "instances": list(ms.instance_names), "objects": sorted(ts.objects),
            "sampling": "one unjittered sample at each pixel centre", "version": GEOMETRY_VERSION,
            "instants": instants}


def geometry_owners(keyframe_times, geometry: dict | None) -> np.ndarray:
    """Per geometry instant, the index of the keyframe at or before it (the first keyframe for instants before
    it): the keyframe whose render task also renders the instant's pass."""
    if not geometry:
        return np.zeros(0, dtype=np.int64)
    t = np.asarray([g["t"] for g in geometry["instants"]])
    idx = np.searchsorted(np.asarray(keyframe_times, dtype=np.float64), t, side="right") - 1
    return np.clip(idx, 0, len(keyframe_times) - 1)


def owned_instants(keyframe_times, geometry: dict | None, keyframe_indices) -> list[int]:
    """Indices of the geometry instants that the keyframes ``keyframe_indices`` own."""
    owners = geometry_owners(keyframe_times, geometry)
    mine = np.isin(owners, np.asarray(list(keyframe_indices), dtype=np.int64))
    return [int(i) for i in np.flatnonzero(mine)]


def missing_geometry(geometry: dict | None, instants, out_dir: Path, width: int, height: int) -> list[int]:
    """Those of ``instants`` whose pass is not in ``out_dir`` yet, or is damaged."""
    if not geometry:
        return []
    out = []
    for j in instants:
        path = Path(out_dir) / geometry["instants"][j]["file"]
        if not path.is_file() or not geometry_is_intact(path, width, height):
            out.append(j)
    return out


def render_geometry(ms: MitsubaScene, geometry: dict, instants, out_dir: Path) -> int:
    """Render and write the passes ``instants`` of ``geometry`` into ``out_dir``; returns how many."""
    (Path(out_dir) / GEOMETRY_DIR).mkdir(parents=True, exist_ok=True)
    n = 0
    for j in instants:
        inst = geometry["instants"][j]
        objects = {k: np.asarray(m, np.float64) for k, m in inst.get("object_to_world", {}).items()}
        ms.set_pose(np.asarray(inst["camera_to_world"], np.float64), objects)
        depth, instance = ms.render_geometry()
        write_geometry(Path(out_dir) / inst["file"], depth, instance)
        n += 1
    return n


def remove_stale_geometry(out_dir: Path, keep: set[str]) -> None:
    """Delete geometry passes of earlier renders into the same directory that the new timeline does not list."""
    for path in (Path(out_dir) / GEOMETRY_DIR).glob("[0-9][0-9][0-9][0-9][0-9][0-9]-*.npz"):
        if f"{GEOMETRY_DIR}/{path.name}" not in keep:
            path.unlink(missing_ok=True)

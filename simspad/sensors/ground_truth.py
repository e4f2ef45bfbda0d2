"""Ground truth (docs/sensors.md, docs/format.md): sharp sensor-plane photon irradiance at requested instants, poses,
depth, the camera model, instance masks and the motion field.

``/gt/flux`` holds the *instantaneous* irradiance Φ(t) (no exposure blur) of the piecewise-linear timeline at
``/gt/t``; ``/poses`` the camera-to-world matrices of the keyframes that cover the interval (interpolate between
them as rigid motions, not element-wise).

When the render directory carries geometry passes at the ground-truth instants (``timeline.json``'s ``geometry``,
:mod:`simspad.io.geometry`; SimSPAD's renderer draws them), the geometry is exact at every instant rather than
interpolated between keyframes: ``/gt/depth`` is the pass's depth at the pixel centres, ``/gt/instance`` its
instance ids, ``/gt/camera_to_world`` and ``/gt/object_to_world`` the poses, ``/camera`` the intrinsics, and
``/gt/flow`` (with ``/gt/flow_valid``) and ``/gt/velocity`` the motion field of :mod:`simspad.motion.motion_field`
over the next ground-truth interval and at the instant. Otherwise (an outside renderer's directory) ``/gt/depth``
is the keyframes' depth interpolated in time, and the geometry datasets are absent. Everything is streamed in
chunks of :data:`GT_CHUNK_FRAMES` instants: memory does not grow with the sequence's length.
"""

from __future__ import annotations

import json

import numpy as np

from simspad import defaults
from simspad.io.geometry import TIME_MATCH_S, GeometryIndex, gt_times, read_geometry, read_geometry_index
from simspad.io.render_dir import TIMELINE_FILE
from simspad.motion.motion_field import flow_validity, image_velocity, motion_field, relative_motion
from simspad.motion.pinhole import PinholeCamera

__all__ = ["GT_CHUNK_FRAMES", "GT_STORAGE", "gt_times", "pose_indices", "write_ground_truth"]

#: Ground-truth frames written per HDF5 chunk (and held in memory at once).
GT_CHUNK_FRAMES = 16
#: Storage of the geometry datasets (instances, flow, validity, velocity): byte shuffle + deflate level 1, which
#: every HDF5 reader decodes (no plugin), on smooth fields and few distinct ids.
GT_STORAGE = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
#: What ``/gt/flow`` is, stored with it.
FLOW_DEFINITION = ("motion field of surfaces (not brightness-constancy optical flow): forward displacement of the "
                   "surface point seen at each pixel centre from t to t + 1/rate_hz, px; [..., 0] x (columns, "
                   "right), [..., 1] y (rows, down); NaN where undefined (last instant, point behind the camera)")


def pose_indices(times_s: np.ndarray, t0: float, t1: float) -> slice:
    """Keyframes whose instants lie in ``[t0, t1]`` plus the one on each side, so poses bracket the interval."""
    i0 = max(int(np.searchsorted(times_s, t0, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(times_s, t1, side="left")) + 1, len(times_s))
    return slice(i0, i1)


def _geometry_for(flux_tl, t: np.ndarray) -> tuple[GeometryIndex, np.ndarray, PinholeCamera] | None:
    """The render's geometry passes and, per ground-truth instant, the index of its pass; None unless every
    instant has one and the render states its field of view."""
    if flux_tl.render_dir is None or "geometry" not in flux_tl.meta:
        return None
    geometry = read_geometry_index(flux_tl.meta, flux_tl.render_dir, flux_tl.render_dir / TIMELINE_FILE)
    x_fov = flux_tl.meta.get("renderer", {}).get("x_fov_deg")
    if geometry is None or x_fov is None or not len(t):
        return None
    j = np.clip(np.searchsorted(geometry.times_s, t - TIME_MATCH_S), 0, len(geometry.times_s) - 1)
    if np.any(np.abs(geometry.times_s[j] - t) > TIME_MATCH_S):
        return None
    return geometry, j, PinholeCamera.from_fov(float(x_fov), flux_tl.width, flux_tl.height)


def _camera_attrs(camera: PinholeCamera) -> dict:
    cx, cy = camera.principal_point_px
    return {"model": "pinhole", "width": int(camera.width), "height": int(camera.height),
            "focal_px": float(camera.focal_px), "fx_px": float(camera.focal_px), "fy_px": float(camera.focal_px),
            "cx_px": float(cx), "cy_px": float(cy), "x_fov_deg": float(2 * np.degrees(np.arctan(
                0.5 * camera.width / camera.focal_px))), "y_fov_deg": float(camera.y_fov_deg),
            "pixel_centre": "pixel [r, c] is centred on (x, y) = (c, r) and covers [c - 1/2, c + 1/2) x "
                            "[r - 1/2, r + 1/2)",
            "axes": "K maps OpenCV camera coordinates (x right, y down, z forward) to pixels (x, y, 1); "
                    "camera_to_world is Mitsuba's (x left, y up, z forward): p_cv = diag(-1, -1, 1) p_mitsuba",
            "distortion": "none"}


class _GeometryFrames:
    """Reads each geometry pass once while the instants are written in order (the next instant's pass is the
    current one's validity check, then its own source)."""

    def __init__(self, geometry: GeometryIndex, width: int, height: int):
        self.geometry, self.width, self.height = geometry, width, height
        self._cache: dict[int, tuple] = {}

    def get(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        if j not in self._cache:
            if len(self._cache) >= 3:  # this instant's pass, the next one's, and the one before (read in order)
                self._cache.pop(min(self._cache))
            self._cache[j] = read_geometry(self.geometry.files[j], self.width, self.height)
        return self._cache[j]


def _next_instants(geometry: GeometryIndex, match: np.ndarray, t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per ground-truth instant, the geometry pass one ground-truth interval later (-1 where the render has none):
    the next instant's, and for the last one the pass at ``t[-1] + 1/rate_hz`` if the render holds it."""
    nxt = np.full(len(match), -1, dtype=np.int64)
    nxt[:-1] = match[1:]
    after = t[-1] + 1.0 / rate_hz
    k = int(np.clip(np.searchsorted(geometry.times_s, after - TIME_MATCH_S), 0, len(geometry.times_s) - 1))
    if abs(geometry.times_s[k] - after) <= TIME_MATCH_S:
        nxt[-1] = k
    return nxt


def _geometry_rows(frames: _GeometryFrames, camera: PinholeCamera, j: int, j_next: int) -> dict:
    """Depth, instances, flow (to pass ``j_next``; -1: none), validity and velocity of geometry pass ``j``."""
    g = frames.geometry
    depth, inst = frames.get(j)
    ids = {name: g.instance_of(name) for name in g.objects}
    objects = {ids[name]: (g.object_to_world[j, k], g.object_velocity[j, k, :3], g.object_velocity[j, k, 3:])
               for k, name in enumerate(g.objects)}
    velocity = image_velocity(camera, depth, inst, g.camera_to_world[j],
                              (g.camera_velocity[j, :3], g.camera_velocity[j, 3:]), objects)
    if j_next >= 0:
        moves = {ids[name]: relative_motion(g.object_to_world[j, k], g.object_to_world[j_next, k])
                 for k, name in enumerate(g.objects)}
        flow, moved_depth = motion_field(camera, depth, inst, g.camera_to_world[j], g.camera_to_world[j_next], moves)
        depth_b, inst_b = frames.get(j_next)
        valid = flow_validity(camera, flow, moved_depth, inst, depth_b, inst_b)
    else:  # no next instant in the render: the last interval's motion is not known
        flow = np.full((camera.height, camera.width, 2), np.nan)
        valid = np.zeros((camera.height, camera.width), dtype=bool)
    return {"depth": depth, "instance": inst, "flow": flow.astype(np.float32), "flow_valid": valid.astype(np.uint8),
            "velocity": velocity.astype(np.float32)}


def write_ground_truth(writer, flux_tl, t0: float, t1: float, rate_hz: float = defaults.GT_RATE_HZ) -> np.ndarray:
    """Write ``/gt`` (flux, depth and, with geometry passes, instances, flow, validity, velocity and poses),
    ``/camera`` (with geometry passes) and ``/poses`` (if any), streaming the frames.

    Parameters
    ----------
    writer : simspad.io.recording.RecordingWriter
        Open writer.
    flux_tl : Timeline
        Sensor-plane photon irradiance, photons s⁻¹ m⁻².
    t0, t1 : float
        Interval, s.
    rate_hz : float
        Ground-truth frame rate.

    Returns
    -------
    ndarray
        The ground-truth instants, s.
    """
    H, W = flux_tl.height, flux_tl.width
    t = gt_times(t0, t1, rate_hz)
    writer.write_dataset("gt/t", t, attrs={"units": "s"})
    writer.set_attrs("gt", rate_hz=float(rate_hz), flux_units="photons s-1 m-2", kind="instantaneous")
    rows = min(GT_CHUNK_FRAMES, max(len(t), 1))
    found = _geometry_for(flux_tl, t)
    flux = writer.append_dataset("gt/flux", (H, W), np.float32, chunk_rows=rows,
                                 attrs={"units": "photons s-1 m-2"})
    depth = out = None
    if found is not None:
        geometry, match, camera = found
        frames = _GeometryFrames(geometry, W, H)
        following = _next_instants(geometry, match, t, rate_hz)
        writer.set_attrs("gt", geometry="exact at each instant: one unjittered sample per pixel centre")
        names = json.dumps([""] + list(geometry.instances))
        out = {
            "depth": writer.append_dataset("gt/depth", (H, W), np.float32, chunk_rows=rows,
                                           attrs={"units": "m", "definition": "depth along the optical axis at "
                                                  "the pixel centre (inf: no surface)"}),
            "instance": writer.append_dataset("gt/instance", (H, W), np.uint16, chunk_rows=rows, storage=GT_STORAGE,
                                              attrs={"names": names, "background": 0,
                                                     "definition": "scene object seen at the pixel centre: id k "
                                                                   "is names[k]; 0 nothing"}),
            "flow": writer.append_dataset("gt/flow", (H, W, 2), np.float32, chunk_rows=rows, storage=GT_STORAGE,
                                          attrs={"units": "px", "interval_s": 1.0 / float(rate_hz),
                                                 "direction": "forward", "components": "x right, y down",
                                                 "definition": FLOW_DEFINITION}),
            "flow_valid": writer.append_dataset("gt/flow_valid", (H, W), np.uint8, chunk_rows=rows,
                                                storage=GT_STORAGE,
                                                attrs={"definition": "1 where the moved point lands inside the image "
                                                       "and is the surface seen there at t + 1/rate_hz (same "
                                                       "instance, depth agrees); 0 where it leaves the image, is "
                                                       "occluded, or is undefined"}),
            "velocity": writer.append_dataset("gt/velocity", (H, W, 2), np.float32, chunk_rows=rows,
                                              storage=GT_STORAGE,
                                              attrs={"units": "px s-1", "components": "x right, y down",
                                                     "definition": "instantaneous image velocity of the surface "
                                                                   "point seen at each pixel centre"}),
        }
        writer.write_dataset("gt/camera_to_world", geometry.camera_to_world[match],
                             attrs={"convention": "mitsuba: camera looks along +Z, up +Y, +X left"})
        if geometry.objects:
            writer.write_dataset("gt/object_to_world", geometry.object_to_world[match],
                                 attrs={"objects": json.dumps(geometry.objects),
                                        "convention": "object_to_world of each animated object (axis 1 in the "
                                                      "order of the objects attribute)"})
        writer.set_attrs("camera", **_camera_attrs(camera))
        writer.write_dataset("camera/K", camera.K(), attrs={"units": "px"})
    else:
        if "geometry" in flux_tl.meta:  # passes at other instants (another rate or span): say why none is here
            rate = flux_tl.meta["geometry"].get("rate_hz") if isinstance(flux_tl.meta["geometry"], dict) else None
            writer.set_attrs("gt", geometry=f"absent: the render's geometry passes (at {rate} Hz) do not fall on "
                                            "these ground-truth instants")
        if flux_tl.has_depth:
            depth = writer.append_dataset("gt/depth", (H, W), np.float32, chunk_rows=rows, attrs={"units": "m"})
    for i in range(0, len(t), rows):
        ts = t[i : i + rows]
        # flux and depth of an instant together: both come from the same two keyframes, which the timeline's
        # small cache still holds (a pass of flux over a chunk and then one of depth decoded every keyframe twice)
        flux_rows, depth_rows, geo_rows = [], [], []
        for k, ti in enumerate(ts):
            flux_rows.append(flux_tl.sample(ti))
            if depth is not None:
                depth_rows.append(flux_tl.depth(ti))
            if out is not None:
                geo_rows.append(_geometry_rows(frames, camera, int(match[i + k]), int(following[i + k])))
        flux.append(np.stack(flux_rows))
        if depth is not None:
            depth.append(np.stack(depth_rows))
        if out is not None:
            for name, appender in out.items():
                appender.append(np.stack([r[name] for r in geo_rows]))
    if flux_tl.poses is not None:
        sel = pose_indices(flux_tl.times_s, t0, t1)
        writer.write_dataset("poses/t", np.asarray(flux_tl.times_s[sel], np.float64), attrs={"units": "s"})
        writer.write_dataset("poses/camera_to_world", np.asarray(flux_tl.poses[sel], np.float64),
                             attrs={"convention": "mitsuba: camera looks along +Z, up +Y"})
    return t

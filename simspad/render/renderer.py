"""Render linear radiance keyframes of a scene along a trajectory with Mitsuba 3 (DESIGN §1, §5, §6).

For each instant of the adaptive schedule (:mod:`simspad.render.schedule`) the camera is posed through
``mi.traverse`` (no recompilation: one ``params.update()`` before the first frame, then only values change),
animated objects get their vertices moved rigidly from the rest pose, and two passes are rendered with a fixed
seed so Monte Carlo noise stays frozen in screen space: radiance (the scene's integrator, ``spp`` samples) and
depth (an ``aov`` integrator at 1 spp). Each keyframe is one EXR (R, G, B, Z) written atomically, named by a hash
of everything that determines its pixels, so re-runs re-use frames and an interrupted render resumes;
``timeline.json`` is written last.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.radiance.timeline import TIMELINE_FILE, write_timeline_json
from simspad.render.mitsuba_env import select_variant
from simspad.render.schedule import (
    SPAD_BIN_S,
    brute_force_keyframes,
    camera_flow_bound,
    focal_length_px,
    keyframe_schedule,
    object_flow_bound,
)

__all__ = ["RenderSummary", "render_sequence", "select_variant"]

#: Bumped when the pixels a given (scene, pose, settings) produce would change: part of every frame's cache key.
RENDERER_VERSION = 5
#: Pixel reconstruction: box (pixel-area) samples, then a Gaussian blur of σ = 0.5 px, a mild lens-like PSF (MTF
#: ≈ 0.3 at Nyquist). Band-limiting the image this way lowers both Monte Carlo noise and the error of linear
#: interpolation in time (≈ 1.5 % → 0.95 % at a 0.45 px step on a textured pan, bench_render.py). The blur is
#: applied in numpy rather than as Mitsuba's Gaussian film filter, whose splatting into neighbouring pixels uses
#: atomic adds in thread order and is not bit-reproducible.
RECONSTRUCTION_FILTER = {"type": "box"}
PSF_SIGMA_PX = 0.5
#: Depth pass: samples per pixel and the scene-depth percentile that bounds image motion from camera translation.
DEPTH_SPP = 1
NEAR_DEPTH_PERCENTILE = 2.0
#: Depth probes (evenly spaced instants) used to predict image motion before rendering.
DEPTH_PROBES = 5
#: Slack (s) allowed between the requested span and the trajectory's span.
SPAN_TOLERANCE_S = 1e-9


def sampler_for(spp: int) -> str:
    """Low-discrepancy samples when ``spp`` is a power of four (≈ 4x lower noise than independent ones at 64 spp,
    and with a fixed seed the pattern stays put as the image moves, so interpolated keyframes track brute-force
    renders closely); independent samples otherwise (the low-discrepancy sampler would round ``spp`` up)."""
    return "ldsampler" if spp >= 1 and spp & (spp - 1) == 0 and (spp.bit_length() - 1) % 2 == 0 else "independent"


@dataclass
class RenderSummary:
    """What a render did.

    Attributes
    ----------
    out_dir : Path
    n_keyframes : int
        Keyframes in the timeline.
    n_rendered, n_reused : int
        Frames rendered now / taken from the cache.
    duration_s, start_s : float
    n_spad_bins : int
        Keyframes one render per 10.24 µs SPAD bin would need.
    render_s : float
        Wall time spent rendering frames (both passes), seconds.
    variant : str
    compiled_first_frame, compiled_after_first : int
        Dr.Jit kernels new to this process (compiled, or loaded from the disk cache) while rendering the first
        frame / all later frames; -1 where not applicable (scalar variant).
    max_predicted_flow_px : float
        Largest predicted image motion between consecutive keyframes.
    """

    out_dir: Path
    n_keyframes: int
    n_rendered: int
    n_reused: int
    duration_s: float
    start_s: float
    n_spad_bins: int
    render_s: float
    variant: str
    compiled_first_frame: int = -1
    compiled_after_first: int = -1
    max_predicted_flow_px: float = 0.0
    frame_times_s: list = field(default_factory=list, repr=False)

    @property
    def time_per_frame_s(self) -> float:
        """Median wall time of one rendered keyframe (radiance + depth), seconds; nan if none was rendered."""
        return float(np.median(self.frame_times_s)) if self.frame_times_s else float("nan")

    @property
    def reduction(self) -> float:
        """How many times fewer renders than one per SPAD bin."""
        return self.n_spad_bins / self.n_keyframes

    def describe(self) -> str:
        """A few lines for the CLI."""
        per_frame = (f"{self.time_per_frame_s * 1e3:.1f} ms per frame (median)" if self.frame_times_s
                     else "no frame rendered")
        lines = [
            f"render dir: {self.out_dir}",
            f"keyframes: {self.n_keyframes} over {self.duration_s:g} s from t = {self.start_s:g} s "
            f"({self.n_rendered} rendered, {self.n_reused} re-used from the cache)",
            f"versus one per 10.24 µs SPAD bin: {self.n_spad_bins} renders -> {self.reduction:.1f}x fewer; "
            f"largest predicted motion between keyframes {self.max_predicted_flow_px:.3f} px",
            f"variant: {self.variant}; {per_frame}; total {self.render_s:.2f} s",
        ]
        if self.compiled_first_frame >= 0:
            lines.append(f"kernel compilations: {self.compiled_first_frame} for the first frame, "
                         f"{self.compiled_after_first} after it")
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------- inputs
def _check_settings(duration_s, start_s, resolution, spp, max_flow_px, min_rate_hz, seed):
    def bad(field_name, message):
        raise SimSpadError(message, field=field_name)

    if not (isinstance(duration_s, numbers.Real) and math.isfinite(duration_s) and duration_s > 0):
        bad("duration", f"must be a number of seconds > 0, got {duration_s!r}")
    if not (isinstance(start_s, numbers.Real) and math.isfinite(start_s)):
        bad("start", f"must be a finite number of seconds, got {start_s!r}")
    try:
        width, height = (int(v) for v in resolution)
    except (TypeError, ValueError):
        bad("resolution", f"expected (width, height), got {resolution!r}")
    if width <= 0 or height <= 0:
        bad("resolution", f"width and height must be positive, got {resolution!r}")
    if not (isinstance(spp, numbers.Integral) and spp >= 1):
        bad("spp", f"must be an integer >= 1, got {spp!r}")
    if not (max_flow_px > 0):
        bad("max_flow_px", f"must be > 0 pixels, got {max_flow_px!r}")
    if not (min_rate_hz > 0):
        bad("min_rate_hz", f"must be > 0 Hz, got {min_rate_hz!r}")
    if not isinstance(seed, numbers.Integral) or seed < 0:
        bad("seed", f"must be an integer >= 0, got {seed!r}")
    return width, height


def _make_out_dir(out_dir: Path) -> list[Path]:
    """Create ``out_dir`` (and ``frames/``) now, so an unwritable output fails before any work; return what was
    created so it can be removed again if a later check fails."""
    created = []
    for d in reversed([out_dir / "frames", out_dir, *out_dir.parents]):
        if d.exists():
            if not d.is_dir():
                raise SimSpadError(f"{d} is a file, not a directory", path=out_dir, field="out")
            continue
        try:
            d.mkdir()
        except OSError as exc:
            _remove_created(created)
            raise SimSpadError(f"cannot create the output directory ({exc.strerror})", path=out_dir,
                               field="out") from None
        created.append(d)
    if not os.access(out_dir / "frames", os.W_OK | os.X_OK):
        _remove_created(created)
        raise SimSpadError("output directory is not writable", path=out_dir, field="out")
    return created


def _remove_created(created: list[Path]) -> None:
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            pass


def _load_trajectory(trajectory, scene_info):
    from simspad.motion.trajectory import TrajectorySet, load_trajectory

    if isinstance(trajectory, TrajectorySet):
        return trajectory, trajectory.source, _trajectory_set_hash(trajectory)
    path = trajectory if trajectory is not None else scene_info.default_trajectory
    if path is None:
        return TrajectorySet(camera=None, objects={}, source="<static>"), "<static>", "static"
    path = Path(path)
    ts = load_trajectory(path)
    return ts, str(path), hashlib.sha256(path.read_bytes()).hexdigest()


def _trajectory_set_hash(ts) -> str:
    digest = hashlib.sha256()
    for name, tr in sorted(ts.bodies().items()):
        digest.update(name.encode())
        for a in (tr.times_s, tr.positions_m, tr.quaternions_xyzw):
            digest.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _check_span(ts, source: str, start_s: float, end_s: float) -> None:
    for name, tr in ts.bodies().items():
        if tr.is_static:
            continue
        if tr.t_start > start_s + SPAN_TOLERANCE_S or tr.t_end < end_s - SPAN_TOLERANCE_S:
            raise SimSpadError(f"trajectory covers [{tr.t_start:g}, {tr.t_end:g}] s but the render needs "
                               f"[{start_s:g}, {end_s:g}] s", path=source, field=name)


# ---------------------------------------------------------------------------------------------------- Mitsuba
_MAX_SCENE_LOADS = 64


def _emitter_order(scene) -> list[str]:
    return [(e.get_shape().id() if e.get_shape() is not None else e.id()) for e in scene.emitters()]


def _load_canonical(mi, source, where):
    """Load a scene whose emitters are listed in a canonical order (sorted by id).

    Mitsuba 3.9 lists a scene's emitters (and shapes) in an order that varies from one load to the next, even
    with ``parallel=False``; emitter sampling picks by index, so a fixed render seed would then give different
    Monte Carlo noise in different processes and the dataset would not be bit-identical across runs. A load
    costs ~0.1 s, so reload until the order is the sorted one; warn once if that order never comes up.
    """
    for _ in range(_MAX_SCENE_LOADS):
        scene = mi.load_dict(source, parallel=False) if isinstance(source, dict) else mi.load_file(
            str(source), parallel=False)
        order = _emitter_order(scene)
        if order == sorted(order):
            return scene
    print(f"simspad: warning: {where}: Mitsuba did not list the scene's emitters in a stable order in "
          f"{_MAX_SCENE_LOADS} loads; renders of this scene may differ in Monte Carlo noise between runs",
          file=sys.stderr)
    return scene


class _MitsubaScene:
    """A loaded scene, our own sensor, and the parameters that move the camera and the objects."""

    def __init__(self, info, ts, width: int, height: int, spp: int):
        import mitsuba as mi

        from simspad.scenes.library import DEFAULT_CAMERA_ID, scene_dict_or_file

        self.mi = mi
        where = info.source or info.folder
        source = scene_dict_or_file(info)
        try:
            self.scene = _load_canonical(mi, source, where)
        except Exception as exc:  # Mitsuba reports malformed scenes as RuntimeError with its own message
            raise SimSpadError(f"Mitsuba cannot load the scene: {str(exc).splitlines()[0]}", path=where,
                               field="scene") from None
        sensors = {s.id(): s for s in self.scene.sensors()}
        camera = sensors.get(info.camera_id)
        if camera is None and info.camera_id == DEFAULT_CAMERA_ID and not info.builtin and len(sensors) >= 1:
            camera = self.scene.sensors()[0]  # a user's XML whose camera has no id
        if camera is None:
            raise SimSpadError(f"no sensor with id {info.camera_id!r} in the scene (sensors: "
                               f"{', '.join(sorted(sensors)) or 'none'})", path=where, field="camera_id")
        cam_params = mi.traverse(camera)
        self.x_fov_deg = float(np.asarray(cam_params["x_fov"]).ravel()[0])
        self.rest_camera_to_world = _matrix(cam_params["to_world"])
        near = float(np.asarray(cam_params["near_clip"]).ravel()[0])
        far = float(np.asarray(cam_params["far_clip"]).ravel()[0])
        self.sensor = mi.load_dict({
            "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f(self.rest_camera_to_world),
            "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                     "component_format": "float32", "rfilter": dict(RECONSTRUCTION_FILTER)},
            "sampler": {"type": sampler_for(spp), "sample_count": spp},
        })
        self.sensor_params = mi.traverse(self.sensor)
        self.depth_sensor = mi.load_dict({
            "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f(self.rest_camera_to_world),
            "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "luminance",
                     "component_format": "float32", "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": DEPTH_SPP},
        })
        self.depth_sensor_params = mi.traverse(self.depth_sensor)
        self.depth_integrator = mi.load_dict({"type": "aov", "aovs": "dd.y:depth"})
        self.params = mi.traverse(self.scene)
        shapes = {s.id(): s for s in self.scene.shapes()}
        self.objects = {}
        for name in ts.objects:
            if name not in shapes:
                raise SimSpadError(f"the trajectory moves object {name!r} but the scene has no shape with that id "
                                   f"(shapes: {', '.join(sorted(shapes))})", path=ts.source, field=name)
            self.objects[name] = self._rest_pose(name)
        self.focal_px = focal_length_px(self.x_fov_deg, width)
        self.width, self.height, self.spp = width, height, spp
        x = (np.arange(width) + 0.5 - 0.5 * width) / self.focal_px
        y = (np.arange(height) + 0.5 - 0.5 * height) / self.focal_px
        # Mitsuba's depth AOV is the distance along the ray; Z is the depth along the optical axis.
        self._ray_to_z = (1.0 / np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)).astype(np.float32)

    def _rest_pose(self, name: str) -> dict:
        key_v, key_n, key_w = f"{name}.vertex_positions", f"{name}.vertex_normals", f"{name}.to_world"
        if key_v in self.params:
            rest = {"vertices": np.asarray(self.params[key_v], dtype=np.float64).reshape(-1, 3)}
            if key_n in self.params and np.asarray(self.params[key_n]).size:
                rest["normals"] = np.asarray(self.params[key_n], dtype=np.float64).reshape(-1, 3)
            rest["points"] = rest["vertices"]
            return rest
        if key_w in self.params:
            to_world = _matrix(self.params[key_w])
            corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
            points = corners @ to_world[:3, :3].T + to_world[:3, 3]
            return {"to_world": to_world, "points": points}
        raise SimSpadError("only meshes or shapes with a to_world transform can be animated", field=name)

    def set_pose(self, camera_to_world: np.ndarray, object_poses: dict[str, np.ndarray]) -> None:
        mi = self.mi
        pose = mi.ScalarTransform4f(np.asarray(camera_to_world, dtype=np.float64))
        for params in (self.sensor_params, self.depth_sensor_params):
            params["to_world"] = pose
            params.update()
        if not object_poses:
            return
        for name, m in object_poses.items():
            rest = self.objects[name]
            if "vertices" in rest:
                moved = rest["vertices"] @ m[:3, :3].T + m[:3, 3]
                key = f"{name}.vertex_positions"
                self.params[key] = type(self.params[key])(moved.astype(np.float32).ravel())
                if "normals" in rest:
                    key_n = f"{name}.vertex_normals"
                    self.params[key_n] = type(self.params[key_n])((rest["normals"] @ m[:3, :3].T)
                                                                  .astype(np.float32).ravel())
            else:
                self.params[f"{name}.to_world"] = mi.ScalarTransform4f(m @ rest["to_world"])
        self.params.update()

    def render_radiance(self, seed: int) -> np.ndarray:
        img = self.mi.render(self.scene, self.params, sensor=self.sensor, seed=seed, spp=self.spp)
        rgb = np.array(img, dtype=np.float32)[..., :3]
        if PSF_SIGMA_PX > 0:
            rgb = gaussian_filter(rgb, sigma=(PSF_SIGMA_PX, PSF_SIGMA_PX, 0.0), mode="nearest", truncate=4.0)
        return np.maximum(rgb, 0.0, dtype=np.float32)

    def render_depth(self, seed: int) -> np.ndarray:
        img = self.mi.render(self.scene, self.params, sensor=self.depth_sensor, integrator=self.depth_integrator,
                             seed=seed, spp=DEPTH_SPP)
        ray = np.array(img, dtype=np.float32)[..., 0]
        return np.where(ray > 0, ray * self._ray_to_z, np.float32(np.inf)).astype(np.float32)


def _matrix(transform) -> np.ndarray:
    m = np.asarray(transform.matrix, dtype=np.float64)
    return m.reshape(4, 4) if m.size == 16 else m[..., 0]


class _CompileCounter:
    """Counts Dr.Jit kernels new to this process (compiled, or loaded from the on-disk kernel cache)."""

    def __init__(self, variant: str):
        self.enabled = variant.startswith("llvm") or variant.startswith("cuda")
        if self.enabled:
            import drjit as dr

            self.dr = dr
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            dr.kernel_history()  # clear what came before

    def take(self) -> int:
        if not self.enabled:
            return -1
        history = self.dr.kernel_history((self.dr.KernelType.JIT,))
        # A kernel new to this process is either compiled (no cache hit) or loaded from the disk cache.
        return sum(1 for k in history if not k.get("cache_hit", 0) or k.get("cache_disk", 0))


# ---------------------------------------------------------------------------------------------------- render
def _poses(ts, rest_camera: np.ndarray, times: np.ndarray):
    cam = ts.camera.pose(times) if ts.camera is not None else np.repeat(rest_camera[None], len(times), axis=0)
    return np.asarray(cam).reshape(len(times), 4, 4)


def _predicted_flow_fn(ts, ms: _MitsubaScene, near_depth_m: float):
    def max_flow(times):
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        cam = _poses(ts, ms.rest_camera_to_world, times)
        if ts.camera is not None:
            v, w = ts.camera.velocity(times)
            total = camera_flow_bound(cam, np.reshape(v, (-1, 3)), np.reshape(w, (-1, 3)), near_depth_m,
                                      ms.focal_px, ms.width, ms.height)
        else:
            total = np.zeros(len(times))
        for name, tr in ts.objects.items():
            v, w = tr.velocity(times)
            total = total + object_flow_bound(cam, np.asarray(tr.pose(times)).reshape(-1, 4, 4), np.reshape(v, (-1, 3)),
                                              np.reshape(w, (-1, 3)), ms.objects[name]["points"], ms.focal_px,
                                              ms.width, ms.height)
        return total

    return max_flow


def _near_depth(ts, ms: _MitsubaScene, t0: float, t1: float, seed: int) -> float:
    """A low percentile of scene depth over a few probe instants (depth pass only: cheap)."""
    near = np.inf
    for t in np.linspace(t0, t1, DEPTH_PROBES):
        ms.set_pose(_poses(ts, ms.rest_camera_to_world, np.array([t]))[0], _object_poses(ts, t))
        z = ms.render_depth(seed)
        finite = z[np.isfinite(z)]
        if finite.size:
            near = min(near, float(np.percentile(finite, NEAR_DEPTH_PERCENTILE)))
    return near if np.isfinite(near) else 1.0


def _object_poses(ts, t: float) -> dict[str, np.ndarray]:
    return {name: np.asarray(tr.pose(t)).reshape(4, 4) for name, tr in ts.objects.items()}


def _frame_key(base: dict, t: float) -> str:
    doc = dict(base, t=repr(float(t)))
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def render_sequence(scene, trajectory=None, *, duration_s: float, start_s: float = 0.0, resolution=defaults.RESOLUTION_PX,
                    spp: int = defaults.SPP, max_flow_px: float = defaults.MAX_FLOW_PX,
                    min_rate_hz: float = defaults.MIN_KEYFRAME_RATE_HZ, seed: int = defaults.SEED,
                    out_dir, progress: bool = True, variant: str | None = None) -> RenderSummary:
    """Render radiance keyframes of ``scene`` along ``trajectory`` into a render directory (DESIGN §5).

    Parameters
    ----------
    scene : str, Path or SceneInfo
        Built-in scene name, a user's Mitsuba scene folder or ``.xml``.
    trajectory : str, Path, TrajectorySet or None
        Trajectory file (or loaded set); None: the scene's default trajectory (static if it has none).
    duration_s, start_s : float
        The rendered span [start_s, start_s + duration_s], seconds.
    resolution : (int, int)
        Width, height in pixels.
    spp : int
        Samples per pixel of the radiance pass.
    max_flow_px : float
        Largest predicted image motion between consecutive keyframes, pixels.
    min_rate_hz : float
        Keyframes are at most ``1 / min_rate_hz`` apart.
    seed : int
        Render seed, the same for every frame (noise frozen in screen space).
    out_dir : str or Path
        Render directory; frames already there with the same cache key are re-used.
    progress : bool
        Show a progress bar on stderr.
    variant : str, optional
        Force a Mitsuba variant (default: :func:`select_variant`).

    Returns
    -------
    RenderSummary

    Raises
    ------
    SimSpadError
        Bad settings, unknown scene, missing camera id, trajectory not covering the span, unwritable output;
        raised before anything is written.
    """
    from simspad.scenes.library import content_hash, resolve_scene

    width, height = _check_settings(duration_s, start_s, resolution, spp, max_flow_px, min_rate_hz, seed)
    spp, seed, max_flow_px, min_rate_hz = int(spp), int(seed), float(max_flow_px), float(min_rate_hz)
    out_dir = Path(out_dir)
    created = _make_out_dir(out_dir)
    t0, t1 = float(start_s), float(start_s) + float(duration_s)
    try:
        info = resolve_scene(scene)
        ts, traj_source, traj_hash = _load_trajectory(trajectory, info)
        _check_span(ts, traj_source, t0, t1)
        variant = select_variant(variant)
        counter = _CompileCounter(variant)
        ms = _MitsubaScene(info, ts, width, height, spp)
        near_depth_m = _near_depth(ts, ms, t0, t1, seed)
        flow_fn = _predicted_flow_fn(ts, ms, near_depth_m)
        times = keyframe_schedule(t0, t1, flow_fn, max_flow_px, min_rate_hz)
    except BaseException:
        _remove_created(created)
        raise
    step_flow = _max_step_flow(flow_fn, times)
    cam_poses = _poses(ts, ms.rest_camera_to_world, times)

    import mitsuba as mi

    base_key = {"renderer": RENDERER_VERSION, "mitsuba": mi.__version__, "variant": variant,
                "scene": content_hash(info), "trajectory": traj_hash, "width": width, "height": height, "spp": spp,
                "seed": seed, "depth_spp": DEPTH_SPP, "sampler": sampler_for(spp),
                "psf_sigma_px": PSF_SIGMA_PX}
    names = [f"frames/{i:06d}-{_frame_key(base_key, t)}.exr" for i, t in enumerate(times)]

    counter.take()  # kernels of loading and depth probes belong to no frame
    frame_times, compiled, n_reused = [], [], 0
    bar = _progress(len(times), progress)
    t_render = time.perf_counter()
    try:
        for i, (t, name) in enumerate(zip(times, names)):
            if (out_dir / name).is_file():
                n_reused += 1
                bar.update(1)
                continue
            tic = time.perf_counter()
            ms.set_pose(cam_poses[i], _object_poses(ts, t))
            rgb = ms.render_radiance(seed)
            depth = ms.render_depth(seed)
            _write_frame(out_dir / name, rgb, depth)
            frame_times.append(time.perf_counter() - tic)
            compiled.append(counter.take())
            bar.update(1)
    finally:
        bar.close()
    render_s = time.perf_counter() - t_render

    keyframes = [{"t": float(t), "file": name, "camera_to_world": cam_poses[i].tolist()}
                 for i, (t, name) in enumerate(zip(times, names))]
    write_timeline_json(
        out_dir, width=width, height=height, keyframes=keyframes,
        scene=info.name, scene_hash=base_key["scene"], trajectory=traj_source, trajectory_hash=traj_hash,
        start_s=t0, duration_s=float(duration_s),
        renderer={"name": "mitsuba", "mitsuba_version": mi.__version__, "variant": variant, "spp": spp,
                  "seed": seed, "sampler": sampler_for(spp), "rfilter": RECONSTRUCTION_FILTER,
                  "psf_sigma_px": PSF_SIGMA_PX, "depth_spp": DEPTH_SPP,
                  "depth": "Z: distance along the optical axis, m (inf: no hit)",
                  "max_flow_px": max_flow_px, "min_rate_hz": min_rate_hz, "near_depth_m": near_depth_m,
                  "focal_px": ms.focal_px, "x_fov_deg": ms.x_fov_deg, "camera_id": info.camera_id,
                  "simspad_renderer_version": RENDERER_VERSION},
        schedule={"n_keyframes": len(times), "n_spad_bins": brute_force_keyframes(duration_s),
                  "max_predicted_flow_px": step_flow},
    )
    _remove_stale_frames(out_dir, set(names))
    return RenderSummary(out_dir=out_dir, n_keyframes=len(times), n_rendered=len(frame_times), n_reused=n_reused,
                         duration_s=float(duration_s), start_s=t0, n_spad_bins=brute_force_keyframes(duration_s),
                         render_s=render_s, variant=variant,
                         compiled_first_frame=compiled[0] if compiled else -1,
                         compiled_after_first=sum(compiled[1:]) if counter.enabled else -1,
                         max_predicted_flow_px=step_flow, frame_times_s=frame_times)


def _max_step_flow(flow_fn, times: np.ndarray, samples: int = 8) -> float:
    """Largest predicted image motion (px) between consecutive keyframes (speed integrated per step)."""
    u = (np.arange(samples) + 0.5) / samples
    inner = times[:-1, None] + np.diff(times)[:, None] * u[None, :]
    speed = np.asarray(flow_fn(inner.ravel())).reshape(inner.shape)
    return float(np.max(speed.mean(axis=1) * np.diff(times))) if len(times) > 1 else 0.0


def _write_frame(path: Path, rgb: np.ndarray, depth: np.ndarray) -> None:
    from simspad.io.exr import write_exr

    write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "Z": depth})


def _remove_stale_frames(out_dir: Path, keep: set[str]) -> None:
    """Delete frames of earlier renders into the same directory that the new timeline does not reference."""
    for path in (out_dir / "frames").glob("[0-9][0-9][0-9][0-9][0-9][0-9]-*.exr"):
        if f"frames/{path.name}" not in keep:
            path.unlink(missing_ok=True)


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="render", unit="frame", file=sys.stderr, dynamic_ncols=True)


def render_from_cli(scene, trajectory, **kwargs) -> RenderSummary:
    """``simspad render``: the same as :func:`render_sequence`."""
    return render_sequence(scene, trajectory, **kwargs)

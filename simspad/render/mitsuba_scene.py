"""A Mitsuba 3 scene loaded for keyframe rendering: our own sensors, and the parameters that pose the camera and
move the animated objects.

The camera is posed through ``mi.traverse`` (no recompilation: one ``params.update()`` before the first frame,
then only values change); animated objects get their vertices (or ``to_world``) moved rigidly from the rest
pose. Two passes are rendered with a fixed seed so Monte Carlo noise stays frozen in screen space: radiance
(the scene's integrator, ``spp`` samples) and depth (an ``aov`` integrator at :data:`DEPTH_SPP` spp). The warp
schedule adds a third, the directly visible emission (:meth:`MitsubaScene.render_emission`).

Mitsuba is imported inside :class:`MitsubaScene` (and Dr.Jit inside :class:`CompileCounter`): both are heavy,
and a variant must be chosen first (:func:`simspad.render.mitsuba_env.select_variant`).
"""

from __future__ import annotations

import re
import sys

import numpy as np
from scipy.ndimage import gaussian_filter

from simspad.errors import SimSpadError
from simspad.render.blocks import block_seed, block_size_px, block_window
from simspad.render.mitsuba_env import ANSI_ESCAPE
from simspad.render.schedule import focal_length_px
from simspad.scenes.library import DEFAULT_CAMERA_ID, scene_dict_or_file

#: Pixel reconstruction: box (pixel-area) samples, then a Gaussian blur of σ = 0.5 px, a mild lens-like PSF (MTF
#: ≈ 0.3 at Nyquist). Band-limiting the image this way lowers both Monte Carlo noise and the error of linear
#: interpolation in time (≈ 1.5 % → 0.95 % at a 0.45 px step on a textured pan, bench_render.py). The blur is
#: applied in numpy rather than as Mitsuba's Gaussian film filter, whose splatting into neighbouring pixels uses
#: atomic adds in thread order and is not bit-reproducible.
RECONSTRUCTION_FILTER = {"type": "box"}
PSF_SIGMA_PX = 0.5
#: The blur's reach, in σ (scipy's ``truncate``): it reaches round(PSF_TRUNCATE · σ) pixels.
PSF_TRUNCATE = 4.0
#: Pixels the blur reaches on each side (scipy's kernel radius).
PSF_REACH_PX = int(PSF_TRUNCATE * PSF_SIGMA_PX + 0.5)
#: Depth pass: samples per pixel and the scene-depth percentile that bounds image motion from camera translation.
DEPTH_SPP = 1


def sampler_for(spp: int) -> str:
    """Stratified (correlated multi-jittered) samples when ``spp`` is a power of four from 4 up, independent
    samples otherwise, which take any ``spp`` as it is; with a fixed seed either pattern stays put as the image
    moves, so interpolated keyframes track brute-force renders closely.

    Not Mitsuba's low-discrepancy sampler (``ldsampler``): in Mitsuba 3.9 it is biased where the light comes from
    deep bounces. On the office's dim half (48×36 px) it renders 2–3 % brighter than independent samples at 64,
    256 and 1024 spp (means over 4 seeds; every seed brighter from 256 spp), where multi-jittered ones agree with
    independent ones to 0.5 % (docs/rendering.md, "Samples per pixel"). The multi-jittered sampler has about its noise at
    64 spp and costs the same. Powers of four only, so the counts that had the low-discrepancy sampler keep a
    stratified one; both samplers render exactly ``spp`` samples (:func:`honoured_spp`)."""
    return "multijitter" if spp >= 4 and spp & (spp - 1) == 0 and (spp.bit_length() - 1) % 2 == 0 else "independent"


def honoured_spp(sensor) -> int:
    """The sample count the sensor's sampler will actually take (Mitsuba may round the one it was given)."""
    return int(sensor.sampler().sample_count())



_MAX_SCENE_LOADS = 64


def emitter_order(scene) -> list[str]:
    return [(e.get_shape().id() if e.get_shape() is not None else e.id()) for e in scene.emitters()]


def load_canonical(mi, source, where):
    """Load a scene whose emitters are listed in a canonical order (sorted by id).

    Mitsuba 3.9 lists a scene's emitters (and shapes) in an order that varies from one load to the next, even
    with ``parallel=False``; emitter sampling picks by index, so a fixed render seed would then give different
    Monte Carlo noise in different processes and the dataset would not be bit-identical across runs. A load
    costs ~0.1 s, so reload until the order is the sorted one; warn once if that order never comes up.
    """
    for _ in range(_MAX_SCENE_LOADS):
        scene = mi.load_dict(source, parallel=False) if isinstance(source, dict) else mi.load_file(
            str(source), parallel=False)
        order = emitter_order(scene)
        if order == sorted(order):
            return scene
    print(f"simspad: warning: {where}: Mitsuba did not list the scene's emitters in a stable order in "
          f"{_MAX_SCENE_LOADS} loads; renders of this scene may differ in Monte Carlo noise between runs",
          file=sys.stderr)
    return scene


#: The source location Mitsuba prefixes to each line of its messages ("[parser.cpp:451] ").
_MITSUBA_SOURCE_TAG = re.compile(r"^\[[\w.]+:\d+\]\s*")


def mitsuba_error_text(exc: BaseException) -> str:
    """Mitsuba's message as one line, its cause included.

    A nested error (an ``<include>`` of a missing file) is reported over several lines, outermost first: "Error
    while loading scene.xml (line 2, col 4): while processing <include>:" then the cause; every line is kept
    (joined by a space), without the C++ source locations and without repeating the file/line context.
    """
    parts, seen_context = [], set()
    for line in str(exc).splitlines():
        line = _MITSUBA_SOURCE_TAG.sub("", ANSI_ESCAPE.sub("", line).strip())
        context, sep, rest = line.partition("): ")
        if sep and context.startswith("Error while loading"):
            if context in seen_context:
                line = rest
            seen_context.add(context)
        if line:
            parts.append(line)
    return " ".join(parts) or type(exc).__name__


class MitsubaScene:
    """A loaded scene, our own sensor, and the parameters that move the camera and the objects."""

    def __init__(self, info, ts, width: int, height: int, spp: int):
        import mitsuba as mi  # deferred: heavy, and the variant must be set first (select_variant)

        self.mi = mi
        where = info.source or info.folder
        source = scene_dict_or_file(info)
        try:
            self.scene = load_canonical(mi, source, where)
        except Exception as exc:  # Mitsuba reports malformed scenes as RuntimeError with its own message
            raise SimSpadError(f"Mitsuba cannot load the scene: {mitsuba_error_text(exc)}", path=where,
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
        self.near_clip_m = near
        far = float(np.asarray(cam_params["far_clip"]).ravel()[0])
        self.far_clip_m = far
        self.sensor = mi.load_dict({
            "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f(self.rest_camera_to_world),
            "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                     "component_format": "float32", "rfilter": dict(RECONSTRUCTION_FILTER)},
            "sampler": {"type": sampler_for(spp), "sample_count": spp},
        })
        if honoured_spp(self.sensor) != spp:  # the sampler would render another count than the one recorded
            raise SimSpadError(f"Mitsuba's {sampler_for(spp)} sampler renders {honoured_spp(self.sensor)} samples "
                               f"per pixel when asked for {spp}", field="spp")
        self.sensor_params = mi.traverse(self.sensor)
        self._block_sensor = None  # made on the first render_radiance_block()
        self._pose = self.rest_camera_to_world
        self.depth_sensor = mi.load_dict({
            "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f(self.rest_camera_to_world),
            "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "luminance",
                     "component_format": "float32", "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": DEPTH_SPP},
        })
        self.depth_sensor_params = mi.traverse(self.depth_sensor)
        # Geometry passes (ground-truth depth, instances, motion field): one sample at each pixel's centre, so a
        # pixel's depth is that of the ray the pinhole model assigns it (stratified, unjittered: no seed).
        self.geometry_sensor = mi.load_dict({
            "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": near, "far_clip": far,
            "to_world": mi.ScalarTransform4f(self.rest_camera_to_world),
            "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "luminance",
                     "component_format": "float32", "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
        })
        self.geometry_sensor_params = mi.traverse(self.geometry_sensor)
        self.depth_integrator = mi.load_dict({"type": "aov", "aovs": "dd.y:depth"})
        self.depth_id_integrator = mi.load_dict({"type": "aov", "aovs": "dd.y:depth,sh:shape_index"})
        self.emission_integrator = None  # made on the first render_emission()
        self.params = mi.traverse(self.scene)
        shapes = {s.id(): s for s in self.scene.shapes()}
        self.objects = {}
        for name in ts.objects:
            if name not in shapes:
                raise SimSpadError(f"the trajectory moves object {name!r} but the scene has no shape with that id "
                                   f"(shapes: {', '.join(sorted(shapes))})", path=ts.source, field=name)
            self.objects[name] = self._rest_pose(name)
        self.object_names = sorted(self.objects)
        self._object_id_of_shape = self._object_id_lookup(shapes)
        self._emitter_of_shape = self._emitter_lookup(shapes)
        self.instance_names, self._instance_of_shape = self._instance_lookup(shapes)
        self.focal_px = focal_length_px(self.x_fov_deg, width)
        self.width, self.height, self.spp = width, height, spp
        self.block_px = block_size_px(width, height)  # blocks of render_radiance_block
        x = (np.arange(width) + 0.5 - 0.5 * width) / self.focal_px
        y = (np.arange(height) + 0.5 - 0.5 * height) / self.focal_px
        # Mitsuba's depth AOV is the distance along the ray from the near-clip plane (the perspective sensor starts
        # its rays there); Z is the depth along the optical axis from the camera centre: ray·cos θ + near_clip.
        self._ray_to_z = (1.0 / np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)).astype(np.float32)

    def _object_id_lookup(self, shapes: dict) -> np.ndarray | None:
        """Table from Mitsuba's ``shape_index`` AOV (the shape's registry index in the JIT variants) to our object
        id (:data:`simspad.render.reprojection.OBJECT_ID_CHANNEL`: k for the k-th sorted animated object, 0 for
        the rest). None when there is no animated object, or the variant has no registry index (scalar)."""
        index = self._registry_index(shapes) if self.objects else None
        if index is None:
            return None
        table = np.zeros(max(index.values()) + 1, dtype=np.float32)
        for k, name in enumerate(self.object_names, start=1):
            table[index[name]] = k
        return table

    def _instance_lookup(self, shapes: dict) -> tuple[list[str], np.ndarray | None]:
        """Instance names (id k ≥ 1 is ``names[k − 1]``) and the table from ``shape_index`` to instance id.

        Every shape of the scene is an instance, named by its id, sorted. Shapes without an id get
        ``_shape<k>``, numbered in the order of what they are (class, primitive and vertex counts, surface area,
        bounding box): Mitsuba lists shapes in an order that varies between loads, and every process that renders
        geometry passes must give a shape the same id. Unnamed shapes alike in all of these (duplicates) share one
        instance. ``(names, None)`` when the variant cannot name shapes.
        """
        named = {sid: [s] for sid, s in shapes.items() if sid}

        def key(shape):
            b = shape.bbox()
            counts = (shape.primitive_count(), shape.vertex_count() if hasattr(shape, "vertex_count") else 0)
            return (shape.class_name(), *counts, round(float(np.asarray(shape.surface_area()).ravel()[0]), 9),
                    *(float(v) for v in (*np.asarray(b.min).ravel(), *np.asarray(b.max).ravel())))

        unnamed: dict[tuple, list] = {}
        for shape in self.scene.shapes():
            if not shape.id():
                unnamed.setdefault(key(shape), []).append(shape)
        by_name = dict(named)
        by_name.update({f"_shape{k}": unnamed[kk] for k, kk in enumerate(sorted(unnamed))})
        names = sorted(by_name)
        if not names or not self.mi.variant().startswith(("llvm", "cuda")):
            return names, None
        import drjit as dr  # deferred: heavy; only the JIT variants index shapes in a registry

        index = {n: [int(np.asarray(dr.reinterpret_array(self.mi.UInt32, self.mi.ShapePtr(s))).ravel()[0])
                     for s in group] for n, group in by_name.items()}
        table = np.zeros(max(max(v) for v in index.values()) + 1, dtype=np.uint16)
        for k, n in enumerate(names, start=1):
            table[index[n]] = k
        return names, table

    @property
    def names_instances(self) -> bool:
        """Whether :meth:`render_geometry` can tell shapes apart (JIT variants)."""
        return self._instance_of_shape is not None

    def render_geometry(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Depth Z (float32, m, ``inf`` where nothing is hit) and instance id (uint16, 0 where nothing is hit) at
        every pixel centre, at the current pose: one unjittered sample per pixel, so no seed. None when the
        variant cannot name shapes (scalar)."""
        if self._instance_of_shape is None:
            return None
        img = np.array(self.mi.render(self.scene, self.params, sensor=self.geometry_sensor,
                                      integrator=self.depth_id_integrator, seed=0, spp=1), dtype=np.float32)
        ray, shape = img[..., 0], np.rint(img[..., 1]).astype(np.int64)
        return self._z_from_ray(ray), _lookup(self._instance_of_shape, shape, ray > 0)

    def _registry_index(self, shapes: dict) -> dict | None:
        """Each shape's registry index, the value of Mitsuba's ``shape_index`` AOV on it (JIT variants); None when
        there is none (the scalar variant, or no shape)."""
        if not shapes or not self.mi.variant().startswith(("llvm", "cuda")):
            return None
        import drjit as dr  # deferred: heavy; only the JIT variants index shapes in a registry

        return {sid: int(np.asarray(dr.reinterpret_array(self.mi.UInt32, self.mi.ShapePtr(s))).ravel()[0])
                for sid, s in shapes.items()}

    def _emitter_lookup(self, shapes: dict) -> np.ndarray | None:
        """Table from Mitsuba's ``shape_index`` AOV to True for shapes that emit; None when the variant has no
        registry index (scalar)."""
        index = self._registry_index(shapes)
        if index is None:
            return None
        table = np.zeros(max(index.values()) + 1, dtype=bool)
        for sid, s in shapes.items():
            table[index[sid]] = s.is_emitter()
        return table

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
        self._pose = np.asarray(camera_to_world, dtype=np.float64)
        pose = mi.ScalarTransform4f(self._pose)
        for params in (self.sensor_params, self.depth_sensor_params, self.geometry_sensor_params):
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
        rgb = psf_blur(rgb)
        return np.maximum(rgb, 0.0, dtype=np.float32)

    @property
    def splits_emission(self) -> bool:
        """Whether :meth:`render_emission` gives exactly the directly visible emission inside
        :meth:`render_radiance`: the scene's integrator is Mitsuba's ``path`` integrator showing its emitters."""
        integrator = self.scene.integrator()
        return integrator.class_name() == "PathIntegrator" and not integrator.hide_emitters

    def emitter_in_view(self, seed: int) -> bool:
        """Whether the camera sees an emitter first anywhere at the current pose, by a 1-spp depth + shape pass:
        an emitting shape, or, where rays escape, an environment emitter. An emitter narrower than a pixel can
        slip between the samples; True when the variant cannot name shapes (scalar)."""
        if self._emitter_of_shape is None:
            return True
        ray, shape = self._depth_shape_pass(seed)
        hit = ray > 0
        if np.any(_lookup(self._emitter_of_shape, shape, hit)):
            return True
        return bool(self.scene.environment() is not None and np.any(~hit))

    def render_emission(self, seed: int) -> np.ndarray:
        """The directly visible emission of :meth:`render_radiance` with the same ``seed``: light the camera rays
        find on the emitters they hit first, nothing reflected ([H, W, 3] float32, blurred the same way).

        Mitsuba draws a pixel's camera rays from the sampler before the integrator runs, and the path integrator
        adds the emission of the first hit with weight 1 before any bounce; a path integrator stopped at depth 1
        therefore traces the same camera rays and adds the same first term, sample for sample, so
        ``render_radiance(seed) − render_emission(seed)`` is exactly the reflected light (up to float rounding) when
        :attr:`splits_emission`. It costs one intersection per sample: 7 % of a radiance render of the office,
        more of a scene whose radiance render is cheap (half of one on the Siemens star).
        """
        if self.emission_integrator is None:
            self.emission_integrator = self.mi.load_dict({"type": "path", "max_depth": 1})
        img = self.mi.render(self.scene, self.params, sensor=self.sensor, integrator=self.emission_integrator,
                             seed=seed, spp=self.spp)
        rgb = psf_blur(np.array(img, dtype=np.float32)[..., :3])
        return np.maximum(rgb, 0.0, dtype=np.float32)

    def render_radiance_block(self, seed: int, row: int, col: int) -> np.ndarray:
        """Radiance of one block of the image (:mod:`simspad.render.blocks`) at the current pose, as
        :meth:`render_radiance` gives it up to Monte Carlo noise: the block and a margin as wide as the blur's
        reach are rendered (with the block's own seed), blurred, and the block's pixels returned
        ([h, w, 3] float32; blocks on the last row or column may be partial).

        The block is rendered through a second sensor whose film is the block plus its margin, moved over the
        image by the principal-point offset: changing that offset (a transform) does not recompile Mitsuba's
        kernel, where a crop offset (a constant of the kernel) would, once per block.
        """
        mi = self.mi
        block_px = self.block_px
        side = block_px + 2 * PSF_REACH_PX
        if self._block_sensor is None:
            self._block_sensor = mi.load_dict({
                "type": "perspective", "fov": self.x_fov_deg, "fov_axis": "x", "near_clip": self.near_clip_m,
                "far_clip": self.far_clip_m, "to_world": mi.ScalarTransform4f(self._pose),
                "film": {"type": "hdrfilm", "width": self.width, "height": self.height, "crop_offset_x": 0,
                         "crop_offset_y": 0, "crop_width": side, "crop_height": side, "pixel_format": "rgb",
                         "component_format": "float32", "rfilter": dict(RECONSTRUCTION_FILTER)},
                "sampler": {"type": sampler_for(self.spp), "sample_count": self.spp},
            })
            self._block_params = mi.traverse(self._block_sensor)
        x0, y0 = col * block_px - PSF_REACH_PX, row * block_px - PSF_REACH_PX
        params = self._block_params
        params["to_world"] = mi.ScalarTransform4f(self._pose)
        params["principal_point_offset_x"] = x0 / self.width
        params["principal_point_offset_y"] = y0 / self.height
        params.update()
        img = np.array(mi.render(self.scene, self.params, sensor=self._block_sensor, seed=block_seed(seed, row, col),
                                 spp=self.spp), dtype=np.float32)[..., :3]
        # Only the pixels inside the image: at its border the whole render's blur repeats the edge pixel
        # (mode "nearest"), which blurring the clipped block with the same mode reproduces.
        ya, yb = max(y0, 0), min(y0 + side, self.height)
        xa, xb = max(x0, 0), min(x0 + side, self.width)
        rgb = img[ya - y0:yb - y0, xa - x0:xb - x0]
        rgb = psf_blur(rgb)
        rows, cols = block_window(row, col, self.width, self.height, block_px)
        inner = rgb[rows.start - ya:rows.stop - ya, cols.start - xa:cols.stop - xa]
        return np.maximum(inner, 0.0, dtype=np.float32)

    def render_depth(self, seed: int) -> np.ndarray:
        img = self.mi.render(self.scene, self.params, sensor=self.depth_sensor, integrator=self.depth_integrator,
                             seed=seed, spp=DEPTH_SPP)
        ray = np.array(img, dtype=np.float32)[..., 0]
        return self._z_from_ray(ray)

    def _z_from_ray(self, ray: np.ndarray) -> np.ndarray:
        """Depth Z (m) along the optical axis from the camera centre, ``inf`` where the ray hit nothing."""
        return np.where(ray > 0, ray * self._ray_to_z + np.float32(self.near_clip_m),
                        np.float32(np.inf)).astype(np.float32)


    @property
    def moves_objects_without_ids(self) -> bool:
        """Objects are animated but their pixels cannot be told apart (scalar variant): no reprojection."""
        return bool(self.objects) and self._object_id_of_shape is None

    def render_depth_ids(self, seed: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Depth Z (m, as :meth:`render_depth`, same samples) and the per-pixel object id (float32; None when the
        scene has no animated object or the variant cannot name shapes), from one AOV pass."""
        if self._object_id_of_shape is None:
            return self.render_depth(seed), None
        ray, shape = self._depth_shape_pass(seed)
        return self._z_from_ray(ray), _lookup(self._object_id_of_shape, shape, ray > 0).astype(np.float32)

    def _depth_shape_pass(self, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """One 1-spp AOV pass: ray depth from the near-clip plane (0: no hit) and ``shape_index`` (int64)."""
        img = np.array(self.mi.render(self.scene, self.params, sensor=self.depth_sensor,
                                      integrator=self.depth_id_integrator, seed=seed, spp=DEPTH_SPP),
                       dtype=np.float32)
        return img[..., 0], np.rint(img[..., 1]).astype(np.int64)


def _lookup(table: np.ndarray, shape_index: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """``table[shape_index]`` where a ray hit a shape the table knows, the table's zero elsewhere."""
    known = hit & (shape_index >= 0) & (shape_index < table.size)
    return np.where(known, table[np.clip(shape_index, 0, table.size - 1)], table.dtype.type(0))


def psf_blur(rgb: np.ndarray) -> np.ndarray:
    """The reconstruction blur (:data:`PSF_SIGMA_PX`) of an [H, W, 3] image, edge pixels repeated."""
    if PSF_SIGMA_PX <= 0:
        return rgb
    return gaussian_filter(rgb, sigma=(PSF_SIGMA_PX, PSF_SIGMA_PX, 0.0), mode="nearest", truncate=PSF_TRUNCATE)


def _matrix(transform) -> np.ndarray:
    m = np.asarray(transform.matrix, dtype=np.float64)
    return m.reshape(4, 4) if m.size == 16 else m[..., 0]


class CompileCounter:
    """Counts Dr.Jit kernels new to this process (compiled, or loaded from the on-disk kernel cache)."""

    def __init__(self, variant: str):
        self.enabled = variant.startswith("llvm") or variant.startswith("cuda")
        if self.enabled:
            import drjit as dr  # deferred: heavy; only the JIT variants count kernels

            self.dr = dr
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            dr.kernel_history()  # clear what came before

    def take(self) -> int:
        if not self.enabled:
            return -1
        history = self.dr.kernel_history((self.dr.KernelType.JIT,))
        # A kernel new to this process is either compiled (no cache hit) or loaded from the disk cache.
        return sum(1 for k in history if not k.get("cache_hit", 0) or k.get("cache_disk", 0))

"""Reprojection: the pinhole model against Mitsuba's own position AOV, round trips, and per-pixel object ids.

Scenes are tiny Mitsuba XML folders written into ``tmp_path`` (48×32 px, 1 spp geometry passes).
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simspad.io.exr import read_exr
from simspad.motion.generators import linear_pan, object_rotation
from simspad.motion.trajectory import TrajectorySet, look_at
from simspad.radiance.timeline import Timeline
from simspad.render.mitsuba_scene import MitsubaScene
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.render.reprojection import (
    PinholeCamera,
    image_motion_px,
    move_points,
    project,
    reproject,
    unproject,
)
from simspad.render.schedule import focal_length_px
from simspad.scenes.library import resolve_scene

W, H = 48, 32
FOV_DEG = 40.0


def _scene(root, *, extra=""):
    root.mkdir(parents=True, exist_ok=True)
    (root / "scene.xml").write_text(f"""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective" id="camera">
    <float name="fov" value="{FOV_DEG}"/>
    <transform name="to_world"><lookat origin="0.3, 0.2, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="64"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
  <shape type="rectangle" id="plane">
    <transform name="to_world"><scale value="10"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.3"/></bsdf>
  </shape>
  <shape type="cube" id="box">
    <transform name="to_world"><scale value="0.25"/><translate x="0.2" y="-0.1" z="0.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf>
  </shape>
  {extra}
</scene>
""")
    return root


@pytest.fixture(scope="module", autouse=True)
def _variant():
    return select_variant()


def _random_pose(rng):
    m = np.eye(4)
    m[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
    m[:3, 3] = rng.normal(size=3)
    return m


# ------------------------------------------------------------------------------------------ pure geometry
def test_intrinsics_match_the_renderers_focal_length():
    cam = PinholeCamera.from_fov(FOV_DEG, W, H)
    assert cam.focal_px == pytest.approx(focal_length_px(FOV_DEG, W))
    assert cam.focal_px == pytest.approx(0.5 * W / math.tan(math.radians(FOV_DEG / 2)))
    meta = {"width": W, "height": H, "renderer": {"x_fov_deg": FOV_DEG}}
    assert PinholeCamera.from_timeline_meta(meta) == cam
    with pytest.raises(ValueError):
        PinholeCamera.from_fov(180.0, W, H)


def test_unproject_then_project_returns_every_pixel_and_its_depth():
    rng = np.random.default_rng(0)
    cam = PinholeCamera.from_fov(FOV_DEG, W, H)
    pose = _random_pose(rng)
    depth = rng.uniform(0.5, 5.0, (H, W))
    col, row, z = project(cam, unproject(cam, depth, pose), pose)
    np.testing.assert_allclose(col, np.broadcast_to(np.arange(W), (H, W)), atol=1e-9)
    np.testing.assert_allclose(row, np.broadcast_to(np.arange(H)[:, None], (H, W)), atol=1e-9)
    np.testing.assert_allclose(z, depth, rtol=1e-12)
    # A point behind the camera has no pixel; a ray that hit nothing has no point.
    behind = pose[:3, 3] - pose[:3, 2]
    c, r, zb = project(cam, behind, pose)
    assert np.isnan(c) and np.isnan(r) and zb < 0
    depth[0, 0] = np.inf
    assert not np.all(np.isfinite(unproject(cam, depth, pose)[0, 0]))


def test_pure_rotation_motion_does_not_depend_on_depth():
    # Rotating the camera about its centre moves the image independently of depth; translating does not.
    rng = np.random.default_rng(1)
    cam = PinholeCamera.from_fov(FOV_DEG, W, H)
    a = _random_pose(rng)
    b = a.copy()
    b[:3, :3] = a[:3, :3] @ Rotation.from_rotvec([0.0, 0.02, 0.0]).as_matrix()  # yaw about its own up axis
    near, far = np.full((H, W), 1.0), np.full((H, W), 10.0)
    np.testing.assert_allclose(image_motion_px(cam, near, a, b), image_motion_px(cam, far, a, b), atol=1e-9)
    # 0.02 rad of yaw moves a point on the axis to f·tan(0.02) px off the centre.
    motion = image_motion_px(cam, far, a, b)
    assert abs(motion[H // 2, W // 2, 0]) == pytest.approx(cam.focal_px * math.tan(0.02), rel=0.01)
    assert abs(motion[H // 2, W // 2, 1]) < 0.01 * cam.focal_px * 0.02
    c = a.copy()
    c[:3, 3] += 0.05 * a[:3, 0]
    assert not np.allclose(image_motion_px(cam, near, a, c), image_motion_px(cam, far, a, c), atol=0.1)


def test_move_points_applies_each_objects_relative_transform_and_leaves_static_points():
    rng = np.random.default_rng(2)
    points = rng.normal(size=(5, 3))
    ids = np.array([0, 1, 2, 1, 0], dtype=np.float32)
    a1, b1, a2, b2 = (_random_pose(rng) for _ in range(4))
    moved = move_points(points, ids, [a1, a2], [b1, b2])
    np.testing.assert_array_equal(moved[[0, 4]], points[[0, 4]])
    for i, (a, b) in ((1, (a1, b1)), (3, (a1, b1)), (2, (a2, b2))):
        local = np.linalg.solve(a, np.append(points[i], 1.0))  # the point in the object's own frame
        np.testing.assert_allclose(moved[i], (b @ local)[:3], atol=1e-12)


# ------------------------------------------------------------------------------------------ against Mitsuba
def test_unprojected_depth_lands_on_mitsubas_own_hit_positions(tmp_path):
    import mitsuba as mi  # deferred: heavy; imported once the variant is set

    info = resolve_scene(_scene(tmp_path / "s"))
    ts = TrajectorySet(camera=None, objects={}, source="<static>")
    ms = MitsubaScene(info, ts, W, H, 1)
    depth = ms.render_depth(0)
    position = np.array(mi.render(ms.scene, ms.params, sensor=ms.depth_sensor, seed=0, spp=1,
                                  integrator=mi.load_dict({"type": "aov", "aovs": "p:position"})))[..., :3]
    cam = PinholeCamera.from_fov(ms.x_fov_deg, W, H)
    hit = np.isfinite(depth)
    assert hit.all()
    # The depth pass samples one point per pixel, anywhere in it (box filter): ±½ px of the centre, so
    # compare the ray through the centre with the sampled hit point within that footprint.
    points = unproject(cam, depth, ms.rest_camera_to_world)
    col, row, z = project(cam, position, ms.rest_camera_to_world)
    np.testing.assert_allclose(col, np.broadcast_to(np.arange(W), (H, W)), atol=0.5 + 1e-3)
    np.testing.assert_allclose(row, np.broadcast_to(np.arange(H)[:, None], (H, W)), atol=0.5 + 1e-3)
    # Z of the sampled hit: the renderer converts ray length with the centre ray's angle (≤ 0.3 % off here).
    np.testing.assert_allclose(z, depth, rtol=5e-3)
    # The centre ray at that depth misses the sampled hit by at most the ½-px jitter (√2/2 px diagonally).
    footprint_m = depth / cam.focal_px  # one pixel at that depth
    err = np.linalg.norm(points - position, axis=-1)
    assert np.all(err < 0.75 * footprint_m + 5e-3 * depth)
    # Mean signed offsets vanish: the pixel-centre convention and the axis signs are right (a flip of x or y
    # would offset every point by up to the image half-width).
    assert np.abs(np.mean(col - np.arange(W))) < 0.05 and np.abs(np.mean(row - np.arange(H)[:, None])) < 0.05


def test_keyframes_of_an_animated_scene_carry_object_ids_and_poses(tmp_path, _variant):
    if not _variant.startswith("llvm"):
        pytest.skip("shape indices name shapes on the JIT variants only")
    folder = _scene(tmp_path / "s")
    cam_pose = look_at((0.3, 0.2, 2.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    camera = linear_pan(cam_pose[:3, 3], Rotation.from_matrix(cam_pose[:3, :3]).as_quat(),
                        velocity_m_s=(0.5, 0.0, 0.0), duration_s=0.05)
    spin = object_rotation(center_m=(0.2, -0.1, 0.5), axis=(0.0, 1.0, 0.0), rpm=300.0, duration_s=0.05)
    ts = TrajectorySet(camera=camera, objects={"box": spin}, source="<test>")
    s = render_sequence(folder, ts, RenderSettings(duration_s=0.02, resolution=(W, H), spp=1, max_flow_px=4.0,
                                                   min_rate_hz=100.0), out_dir=tmp_path / "r", progress=False)
    tl = Timeline.open(s.out_dir)
    assert tl.meta["renderer"]["animated_objects"] == ["box"]
    kfs = tl.meta["keyframes"]
    a, b = read_exr(s.out_dir / kfs[0]["file"]), read_exr(s.out_dir / kfs[-1]["file"])
    ids = a["object_id"]
    assert set(np.unique(ids)) == {0.0, 1.0}
    # The box is nearer than the plane: id 1 exactly where the depth is well in front of the plane.
    cam = PinholeCamera.from_timeline_meta(tl.meta)
    z_plane = project(cam, unproject(cam, a["z"], tl.poses[0]) * [1, 1, 0], tl.poses[0])[2]
    assert np.array_equal(ids == 1, a["z"] < z_plane - 0.05)
    # Reprojecting the first keyframe's box pixels with camera and object motion lands them on the last
    # keyframe's box, at the depth it rendered there (without the object's motion they miss).
    pa, pb = (np.asarray(kfs[i]["object_to_world"]["box"]) for i in (0, -1))
    col, row, z = reproject(cam, a["z"], tl.poses[0], tl.poses[-1], ids, [pa], [pb])
    box = (ids == 1) & (col > 1) & (col < W - 2) & (row > 1) & (row < H - 2)
    ci, ri = np.rint(col[box]).astype(int), np.rint(row[box]).astype(int)
    interior = b["object_id"][ri, ci] == 1
    assert interior.mean() > 0.85
    rel = np.abs(z[box] - b["z"][ri, ci]) / b["z"][ri, ci]
    assert np.median(rel[interior]) < 0.01
    col0, row0, _ = reproject(cam, a["z"], tl.poses[0], tl.poses[-1])
    ci0 = np.clip(np.rint(col0[box]).astype(int), 0, W - 1)
    ri0 = np.clip(np.rint(row0[box]).astype(int), 0, H - 1)
    assert np.median(np.abs(np.hypot(ci0 - ci, ri0 - ri))) >= 1

"""Keyframe synthesis by reprojection: analytic scenes (planes ray-traced in numpy), the render/synthesize
schedule, and the ``--interpolation warp`` render directory (tiny Mitsuba renders).
"""

import dataclasses
import json

import numpy as np
import pytest
from scipy.ndimage import binary_dilation, binary_erosion
from scipy.spatial.transform import Rotation

from simspad.cli import main
from simspad.io.exr import read_exr
from simspad.motion.generators import linear_pan
from simspad.motion.trajectory import TrajectorySet, look_at
from simspad.radiance.timeline import Timeline
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.render.reprojection import PinholeCamera
from simspad.render.warp.synthesis import WarpSource, prepare, synthesize
from simspad.render.warp.schedule import PATCH_MAX_RENDERS, anchor_indices, synthesize_keyframes

W, H = 64, 48
CAM = PinholeCamera.from_fov(50.0, W, H)


def _pose(x=0.0, yaw_rad=0.0):
    """Camera at (x, 0, 3) looking down −Z (towards the planes), turned by ``yaw_rad`` about +Y."""
    m = look_at((x, 0.0, 3.0), (x, 0.0, 0.0), (0.0, 1.0, 0.0))
    m[:3, :3] = m[:3, :3] @ Rotation.from_rotvec([0.0, yaw_rad, 0.0]).as_matrix()
    return m


def _texture(x, y):
    return 1.0 + 0.4 * np.sin(9.1 * x + 0.3) * np.cos(6.3 * y) + 0.2 * np.sin(17.0 * y - 5.1 * x)


def _trace(pose, square_offset=(0.0, 0.0)):
    """Point-sampled image of a textured wall (z = 0) and a textured square (z = 1, |x|,|y| < 0.4, moved by
    ``square_offset``): rgb, Z depth, object id (1 on the square)."""
    d = CAM.rays() @ pose[:3, :3].T
    o = pose[:3, 3]
    rgb = np.zeros((H, W, 3))
    depth = np.full((H, W), np.inf)
    ids = np.zeros((H, W), dtype=np.float32)
    for z_plane, obj in ((0.0, 0), (1.0, 1)):
        t = (z_plane - o[2]) / d[..., 2]  # d scaled to unit camera Z, so t is the Z depth
        p = o + t[..., None] * d
        x, y = p[..., 0], p[..., 1]
        hit = t > 0
        if obj:
            x, y = x - square_offset[0], y - square_offset[1]
            hit &= (np.abs(x) < 0.4) & (np.abs(y) < 0.4)
        nearer = hit & (t < depth)
        value = _texture(x, y) * (0.5 if obj else 1.0)
        rgb[nearer] = np.stack([value, 0.9 * value, 0.8 * value], axis=-1)[nearer]
        depth[nearer] = t[nearer]
        ids[nearer] = obj
    return rgb.astype(np.float32), depth.astype(np.float32), ids


def _object_pose(offset):
    m = np.eye(4)
    m[:2, 3] = offset
    return m


def _source(pose, offset=(0.0, 0.0), with_ids=False):
    rgb, z, ids = _trace(pose, offset)
    return WarpSource(rgb, z, pose, ids if with_ids else None, (_object_pose(offset),) if with_ids else ())


def _rel_rms(a, b, margin=2):
    s = np.s_[margin:a.shape[0] - margin, margin:a.shape[1] - margin]
    return float(np.sqrt(np.mean((a[s] - b[s]) ** 2)) / np.mean(b[s]))


# ------------------------------------------------------------------------------------------ synthesis
def test_a_target_at_a_sources_pose_is_that_source_bit_for_bit():
    a = _source(_pose())
    b = _source(_pose(0.1, 0.05))
    rgb, depth, ids, _ = synthesize(CAM, prepare(a), prepare(b), 0.0, a.camera_to_world)
    np.testing.assert_array_equal(rgb, a.rgb)
    np.testing.assert_array_equal(depth, a.depth_z)
    assert ids is None


def test_parallax_and_rotation_are_synthesized_with_occlusions_resolved():
    # Camera translates 0.12 m and turns 0.06 rad: the square (1 m nearer) slides over the wall by several
    # pixels, covering and uncovering it. The synthesized mid-way frame matches the traced one.
    a, b = _pose(0.0, 0.0), _pose(0.12, -0.06)
    mid = _pose(0.06, -0.03)
    truth, z_truth, _ = _trace(mid)
    rgb, depth, _, dis = synthesize(CAM, prepare(_source(a)), prepare(_source(b)), 0.5, mid)
    err = _rel_rms(rgb, truth)
    naive = _rel_rms(0.5 * (_trace(a)[0] + _trace(b)[0]), truth)  # blending without motion compensation
    assert err < 0.02 and naive > 5 * err, (err, naive)
    assert np.median(np.abs(depth - z_truth) / z_truth) < 1e-3
    assert dis.hole_fraction < 0.002 and dis.rel_rms < 0.06, (dis, err, naive)
    # Without the depth test the wall behind the square would bleed through: the square's pixels stay right.
    # Inside the square (away from its point-sampled, aliased outline) the synthesized frame is exact to 2 %.
    on_square = binary_erosion(np.abs(z_truth - 2.0) < 0.1, iterations=2)
    assert on_square.sum() > 100
    assert _rel_rms(rgb[on_square][None], truth[on_square][None], margin=0) < 0.02


def test_moving_objects_follow_their_own_transform():
    # A static camera; the square moves 0.1 m right between the sources. With object ids and poses the
    # synthesized frame matches; treating the square as static it does not, and the disagreement says so.
    pose = _pose()
    a, b = _source(pose, (0.0, 0.0), True), _source(pose, (0.1, 0.0), True)
    truth, _, ids_truth = _trace(pose, (0.05, 0.0))
    rgb, _, ids, dis = synthesize(CAM, prepare(a), prepare(b), 0.5, pose, (_object_pose((0.05, 0.0)),))
    # Exact away from the square's outline (point-sampled: its sub-pixel position is aliased in every frame).
    outline = binary_dilation(ids_truth == 1, iterations=2) & ~binary_erosion(ids_truth == 1, iterations=2)
    err_in = _rel_rms(rgb[~outline][None], truth[~outline][None], margin=0)
    assert err_in < 0.01
    assert np.mean(ids == ids_truth) > 0.99
    static_a = WarpSource(a.rgb, a.depth_z, pose)
    static_b = WarpSource(b.rgb, b.depth_z, pose)
    rgb_s, _, _, dis_s = synthesize(CAM, prepare(static_a), prepare(static_b), 0.5, pose)
    assert _rel_rms(rgb_s[~outline][None], truth[~outline][None], margin=0) > 5 * err_in
    assert dis_s.score() > 2 * dis.score(), (dis_s, dis)


def _emission(pose):
    """A bright, finely textured emitter on the wall (z = 0) outside the square, seen from ``pose``: [H, W, 3]."""
    _, depth, _ = _trace(pose)
    d = CAM.rays() @ pose[:3, :3].T
    o = pose[:3, 3]
    t = -o[2] / d[..., 2]
    p = o + t[..., None] * d
    value = 30.0 * (1.0 + 0.9 * np.sin(41.0 * p[..., 0]) * np.sin(37.0 * p[..., 1]))
    on_wall = np.abs(depth - t) < 1e-6
    return (np.where(on_wall, value, 0.0)[..., None] * np.array([1.0, 0.8, 0.6])).astype(np.float32)


def test_the_emission_layer_renders_emitters_and_warps_only_reflected_light():
    # A bright emitter texture finer than the motion's resampling can carry: warped with the rest it is the
    # frame's whole error; with the emission layer the target's own emission is added to the warped reflected
    # light, so the synthesized frame is as exact as a warp of the reflected light alone.
    a, b = _pose(0.0, 0.0), _pose(0.12, -0.06)
    mid = _pose(0.06, -0.03)

    def source(pose, layer):
        rgb, z, _ = _trace(pose)
        e = _emission(pose)
        return WarpSource(rgb + e, z, pose, emission=e if layer else None)

    truth = _trace(mid)[0] + _emission(mid)
    plain, *_ = synthesize(CAM, prepare(source(a, False)), prepare(source(b, False)), 0.5, mid)
    layered, _, _, dis = synthesize(CAM, prepare(source(a, True)), prepare(source(b, True)), 0.5, mid,
                                    emission=_emission(mid))
    reflected_only, *_ = synthesize(CAM, prepare(_source(a)), prepare(_source(b)), 0.5, mid)
    np.testing.assert_allclose(layered, reflected_only + _emission(mid), rtol=1e-5, atol=1e-5)
    err_plain, err_layer = _rel_rms(plain, truth), _rel_rms(layered, truth)
    assert err_layer < 0.2 * err_plain, (err_layer, err_plain)
    # The disagreement is that of the reflected light: the emitter's resampling error no longer counts.
    _, _, _, dis_reflected = synthesize(CAM, prepare(_source(a)), prepare(_source(b)), 0.5, mid)
    assert dis.hole_fraction == dis_reflected.hole_fraction
    with pytest.raises(ValueError, match="need the target's emission pass"):
        synthesize(CAM, prepare(_source(a)), prepare(source(b, True)), 0.5, mid)


def test_a_rendered_target_geometry_puts_moving_silhouettes_right():
    # The square moves 0.1 m between the sources. Splatting its pixels forward rounds each to the nearest
    # target pixel, so its outline is off by a pixel here and there (on the fan's blades that flickers into
    # events); with the target's own depth and ids (the renderer's geometry pass) ids and depth are exact and
    # the outline's error drops several-fold.
    pose = _pose()
    a, b = _source(pose, (0.0, 0.0), True), _source(pose, (0.1, 0.0), True)
    truth, z_truth, ids_truth = _trace(pose, (0.05, 0.0))
    objects = (_object_pose((0.05, 0.0)),)
    rgb_s, _, ids_s, _ = synthesize(CAM, prepare(a), prepare(b), 0.5, pose, objects)
    rgb_g, z_g, ids_g, _ = synthesize(CAM, prepare(a), prepare(b), 0.5, pose, objects, geometry=(z_truth, ids_truth))
    np.testing.assert_array_equal(z_g, z_truth)
    np.testing.assert_array_equal(ids_g, ids_truth)
    assert np.mean(ids_s == ids_truth) < 1.0
    outline = binary_dilation(ids_truth == 1, iterations=2) & ~binary_erosion(ids_truth == 1, iterations=2)
    err_s = _rel_rms(rgb_s[outline][None], truth[outline][None], margin=0)
    err_g = _rel_rms(rgb_g[outline][None], truth[outline][None], margin=0)
    assert err_g < 0.04 and err_s > 3 * err_g, (err_s, err_g)
    with pytest.raises(ValueError, match="target depth"):
        synthesize(CAM, prepare(a), prepare(b), 0.5, pose, objects, geometry=(z_truth[:-1], ids_truth))


# ------------------------------------------------------------------------------------------ schedule
class _Keyframes:
    """A :class:`~simspad.render.warp.schedule.KeyframeSource` over analytic frames: ``render(i)`` and the poses
    given, synthesized frames kept in ``written``, an optional geometry pass."""

    def __init__(self, render, poses, geometry=None):
        self._render, self.poses, self._geometry, self.written = render, poses, geometry, {}

    def render(self, i):
        return self._render(i)

    def pose(self, i):
        return self.poses[i], ()

    def geometry(self, i):
        return None if self._geometry is None else self._geometry(i)

    def emission(self, i):
        return None

    def write(self, i, rgb, depth_z, object_id):
        self.written.setdefault(i, rgb)

    def final(self, i):
        pass


def _schedule(threshold, stride=8, n=17):
    poses = [_pose(0.2 * i / (n - 1), 0.0) for i in range(n)]
    rendered = []

    def render(i):
        rendered.append(i)
        return _source(poses[i])

    keyframes = _Keyframes(render, poses)
    report = synthesize_keyframes(CAM, np.linspace(0.0, 1.0, n), keyframes, stride=stride, threshold=threshold)
    return report, rendered, keyframes.written


def test_schedule_renders_anchors_and_bisects_where_warps_disagree():
    assert anchor_indices(17, 8) == [0, 8, 16]
    assert anchor_indices(18, 8) == [0, 8, 16, 17]
    plan, rendered, written = _schedule(threshold=1.0)
    assert sorted(rendered) == [0, 8, 16] and plan.n_rendered == 3
    assert sorted(written) == [i for i in range(17) if i not in (0, 8, 16)]
    assert plan.sources[4] == "warp" and plan.sources[8] == "render"
    # A threshold nothing meets renders every keyframe (bisection down to neighbours), each once.
    _, rendered0, written0 = _schedule(threshold=-1.0)
    assert sorted(rendered0) == list(range(17)) and not written0
    # A geometry pass is asked once for each synthesized keyframe, never for a rendered one.
    poses = [_pose(0.2 * i / 16, 0.0) for i in range(17)]
    asked = []

    def geometry(i):
        asked.append(i)
        _, z, _ = _trace(poses[i])
        return z, None

    plan_g = synthesize_keyframes(CAM, np.linspace(0.0, 1.0, 17), _Keyframes(lambda i: _source(poses[i]), poses,
                                                                             geometry), stride=8, threshold=1.0)
    assert sorted(asked) == [i for i in range(17) if plan_g.sources[i] == "warp"]
    # Deterministic: the same inputs give bit-identical synthesized frames.
    _, _, again = _schedule(threshold=1.0)
    assert all(np.array_equal(written[i], again[i]) for i in written)


# ------------------------------------------------------------------------------------------ renderer
@pytest.fixture(scope="module")
def _variant():
    return select_variant()


def _pan_scene(root):
    from simspad.io.exr import write_exr

    rng = np.random.default_rng(5)
    from scipy.ndimage import gaussian_filter

    tex = gaussian_filter(rng.random((128, 128)), 3.0)
    tex = (0.1 + 0.8 * (tex - tex.min()) / np.ptp(tex)).astype(np.float32)
    root.mkdir(parents=True)
    write_exr(root / "tex.exr", {"R": tex, "G": tex, "B": tex})
    (root / "scene.xml").write_text("""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective" id="camera"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film></sensor>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
  <shape type="rectangle" id="plane"><transform name="to_world"><scale value="5"/></transform>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="tex.exr"/>
    <boolean name="raw" value="true"/></texture></bsdf></shape>
  <shape type="cube" id="box"><transform name="to_world"><scale value="0.2"/><translate z="0.8"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf></shape>
</scene>
""")
    return root


def test_warp_render_directory_marks_sources_and_matches_the_linear_render(tmp_path, _variant):
    folder = _pan_scene(tmp_path / "scene")
    pose = look_at((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    cam = linear_pan(pose[:3, 3], Rotation.from_matrix(pose[:3, :3]).as_quat(), velocity_m_s=(0.4, 0.0, 0.0),
                     yaw_rate_deg_s=10.0, duration_s=0.05)
    ts = TrajectorySet(camera=cam, objects={}, source="<pan>")
    settings = RenderSettings(duration_s=0.03, resolution=(32, 24), spp=16, warp_stride=8, interpolation="warp")
    warp = render_sequence(folder, ts, settings, out_dir=tmp_path / "w", progress=False)
    meta = json.loads((tmp_path / "w" / "timeline.json").read_text())
    sources = [kf["source"] for kf in meta["keyframes"]]
    assert sources[0] == sources[-1] == "render" and "warp" in sources
    assert warp.n_warped == sources.count("warp") and warp.n_rendered == sources.count("render")
    assert meta["schedule"]["interpolation"] == "warp" and meta["schedule"]["n_rendered_keyframes"] < len(sources)
    # The emission layer is on by default. This scene shows no emitter (the plane fills the view): no keyframe
    # needs an emission pass, and the keyframes are those of a warp without the layer, pixel for pixel.
    warp_meta = meta["schedule"]["warp"]
    assert warp_meta["emission_layer"] is True
    assert warp_meta["n_emission_passes"] == 0
    render_sequence(folder, ts, RenderSettings(duration_s=0.03, resolution=(32, 24), spp=16, warp_stride=8,
                                               interpolation="warp", warp_emission=False),
                    out_dir=tmp_path / "plain", progress=False)
    plain = json.loads((tmp_path / "plain" / "timeline.json").read_text())
    assert plain["schedule"]["warp"]["emission_layer"] is False and plain["schedule"]["warp"]["n_emission_passes"] == 0
    for kf, kp in zip(meta["keyframes"], plain["keyframes"]):
        assert kf["source"] == kp["source"]
        a, b = read_exr(tmp_path / "w" / kf["file"]), read_exr(tmp_path / "plain" / kp["file"])
        np.testing.assert_array_equal(a["rgb"], b["rgb"])
    # The linear schedule renders the same instants; rendered keyframes are shared byte for byte, synthesized
    # ones differ from the renders by about the Monte Carlo noise (two renders' noise), not by the motion.
    linear = render_sequence(folder, ts, RenderSettings(duration_s=0.03, resolution=(32, 24), spp=16,
                                                        interpolation="linear"), out_dir=tmp_path / "l2",
                             progress=False)
    lin_meta = json.loads((tmp_path / "l2" / "timeline.json").read_text())
    assert all(kf["source"] == "render" for kf in lin_meta["keyframes"]) and linear.n_warped == 0
    assert [kf["t"] for kf in lin_meta["keyframes"]] == [kf["t"] for kf in meta["keyframes"]]
    tw, tl = Timeline.open(tmp_path / "w"), Timeline.open(tmp_path / "l2")
    noise = meta["schedule"]["warp"]["render_noise"]
    for i, s in enumerate(sources):
        if s == "render":
            np.testing.assert_array_equal(tw.rgb_keyframe(i), tl.rgb_keyframe(i))
        else:
            err = _rel_rms(tw.rgb_keyframe(i), tl.rgb_keyframe(i), margin=1)
            assert err < 2.5 * noise + 0.01, (i, err, noise)
    assert read_exr(tmp_path / "w" / meta["keyframes"][1]["file"]).keys() >= {"rgb", "z"}
    # Re-running gives the same bytes (synthesis is deterministic; rendered anchors come from the cache).
    again = render_sequence(folder, ts, settings, out_dir=tmp_path / "w2", progress=False)
    assert again.n_warped == warp.n_warped
    for kf in meta["keyframes"]:
        assert (tmp_path / "w" / kf["file"]).read_bytes() == (tmp_path / "w2" / kf["file"]).read_bytes()


def test_emission_pass_is_exactly_the_directly_seen_part_of_a_render(tmp_path, _variant):
    # Office: the window (an emitter 40x brighter than the room) is in view. The emission pass draws the same
    # camera rays as the radiance render of the same seed, so subtracting it leaves the reflected light, never
    # below zero; with another seed its antialiasing differs and the difference goes negative at the window.
    from simspad.render.renderer import load_scene

    ms = load_scene("office", None, 48, 36, 4).ms
    assert ms.splits_emission
    full, emission = ms.render_radiance(3), ms.render_emission(3)
    assert emission.max() > 10.0 and (emission.max(axis=-1) == 0).mean() > 0.5  # the window; most pixels none
    rest = full - emission
    assert rest.min() > -1e-6 * full.max(), rest.min()
    assert (full - ms.render_emission(4)).min() < -1e-3 * full.max()
    # A 1-spp pass tells whether any emitter is in view (the window here; none where a plane fills the view).
    assert ms.emitter_in_view(3)
    assert not load_scene(_pan_scene(tmp_path / "pan"), None, 32, 24, 1).ms.emitter_in_view(3)
    # A path integrator that hides its emitters has no such part to split off.
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "scene.xml").write_text("""<scene version="3.0.0">
  <integrator type="path"><boolean name="hide_emitters" value="true"/></integrator>
  <sensor type="perspective" id="camera"><float name="fov" value="40"/></sensor>
  <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>
""")
    assert not load_scene(tmp_path / "s", None, 8, 6, 1).ms.splits_emission


def test_warp_renders_each_keyframes_emission_where_the_sources_show_some(tmp_path, _variant):
    # The office window is in view throughout: every synthesized keyframe gets its own emission pass, and where
    # emission is most of a pixel, the synthesized keyframe is much nearer the linear render's than a warp
    # without the layer (the window's texture is rendered, not resampled; only the reflected rest is warped).
    settings = RenderSettings(duration_s=0.012, resolution=(32, 24), spp=4, warp_stride=4, interpolation="warp")
    render_sequence("office", None, settings, out_dir=tmp_path / "w", progress=False)
    render_sequence("office", None, dataclasses.replace(settings, warp_emission=False), out_dir=tmp_path / "p",
                    progress=False)
    meta = json.loads((tmp_path / "w" / "timeline.json").read_text())
    sources = [kf["source"] for kf in meta["keyframes"]]
    assert "warp" in sources
    assert meta["schedule"]["warp"]["n_emission_passes"] == len(sources) + 1  # and the noise probe
    render_sequence("office", None, RenderSettings(duration_s=0.012, resolution=(32, 24), spp=4,
                                                   interpolation="linear"), out_dir=tmp_path / "l", progress=False)
    tw, tp, tl = (Timeline.open(tmp_path / d) for d in ("w", "p", "l"))
    from simspad.render.renderer import load_scene

    ms = load_scene("office", None, 32, 24, 4).ms
    err_layer, err_plain = [], []
    for i, source in enumerate(sources):
        if source != "warp":
            continue
        ms.set_pose(np.asarray(meta["keyframes"][i]["camera_to_world"]), {})
        lin = tl.rgb_keyframe(i).sum(axis=-1)
        window = ms.render_emission(meta["renderer"]["seed"]).sum(axis=-1) > 0.9 * lin
        assert window.sum() >= 10
        for t, err in ((tw, err_layer), (tp, err_plain)):
            err.append(((t.rgb_keyframe(i).sum(axis=-1)[window] - lin[window]) / lin[window]) ** 2)
    rms_layer, rms_plain = (float(np.sqrt(np.mean(np.concatenate(e)))) for e in (err_layer, err_plain))
    assert rms_layer < 0.03 and rms_layer < 0.5 * rms_plain, (rms_layer, rms_plain)


def test_cli_interpolation_flag(tmp_path, _variant):
    folder = _pan_scene(tmp_path / "scene")
    assert main(["render", str(folder), "--duration", "0.002", "--resolution", "32x24", "--spp", "1",
                 "--interpolation", "linear", "--out", str(tmp_path / "r")]) == 0
    meta = json.loads((tmp_path / "r" / "timeline.json").read_text())
    assert {kf["source"] for kf in meta["keyframes"]} == {"render"}
    assert meta["schedule"]["interpolation"] == "linear"
    assert main(["render", str(folder), "--duration", "0.002", "--resolution", "32x24",
                 "--interpolation", "cubic", "--out", str(tmp_path / "x")]) == 2


def test_disagreement_is_measured_in_noise_units_per_tile():
    # Two warps differing by two renders' noise alone score about 1; a wrong patch of one tile stands out
    # although it barely moves the frame's RMS.
    from simspad.render.warp.synthesis import _tile_noise_ratios

    def _tile_noise_ratio(diff, both, sigma):  # the worst tile
        return _tile_noise_ratios(diff, both, sigma).max()

    rng = np.random.default_rng(4)
    sigma = np.full((H, W), 0.05)
    diff = rng.normal(0.0, np.sqrt(2) * 0.05, (H, W))
    both = np.ones((H, W), dtype=bool)
    assert 0.9 < _tile_noise_ratio(diff, both, sigma) < 1.5
    bad = diff.copy()
    bad[8:16, 16:24] += 0.5  # one 8x8 tile off by 10 sigma
    assert _tile_noise_ratio(bad, both, sigma) > 5
    assert np.sqrt(np.mean(bad ** 2)) < 2 * np.sqrt(np.mean(diff ** 2))


def _trace_with_sheen(pose):
    """:func:`_trace` with a view-dependent patch on the wall (brighter as the camera moves right): no warp can
    carry it from one pose to another, so the warps disagree there and only there."""
    rgb, z, ids = _trace(pose)
    d = CAM.rays() @ pose[:3, :3].T
    p = pose[:3, 3] + (-pose[2, 3] / d[..., 2])[..., None] * d  # the wall point each pixel would see
    sheen = (np.abs(p[..., 0] - 0.6) < 0.1) & (np.abs(p[..., 1] + 0.3) < 0.1) & (ids == 0)
    rgb[sheen] *= 1.0 + 8.0 * pose[0, 3]
    return rgb, z, ids


class _TracedBlocks:
    """The :class:`Patcher` of the analytic scene: blocks ray-traced at the keyframe's pose."""

    def __init__(self, poses, block_px=8):
        from simspad.render import blocks

        self.poses, self.b, self.blocks_mod, self.n_applied = poses, block_px, blocks, 0

    def blocks(self, tiles):
        return self.blocks_mod.blocks_of_tiles(tiles, self.b)

    def tiles(self, blocks, tile_shape):
        return self.blocks_mod.tiles_of_blocks(blocks, tile_shape, self.b)

    def cost(self, blocks):
        return self.blocks_mod.render_fraction(blocks, W, H, self.b, 0, 1024)  # exact pixels: no blur margin

    def apply(self, i, blocks, rgb):
        self.n_applied += 1
        truth, _, _ = _trace_with_sheen(self.poses[i])
        out = rgb.copy()
        for r, c in zip(*np.nonzero(blocks)):
            out[self.blocks_mod.block_window(r, c, W, H, self.b)] = truth[self.blocks_mod.block_window(r, c, W, H, self.b)]
        return out


def test_schedule_renders_only_the_blocks_where_warps_disagree():
    n = 5
    poses = [_pose(0.06 * i / (n - 1), 0.0) for i in range(n)]
    noise = np.full((H, W), 0.02)

    def run(patch):
        rendered = []

        def render(i):
            rendered.append(i)
            rgb, z, ids = _trace_with_sheen(poses[i])
            return WarpSource(rgb, z, poses[i])

        keyframes = _Keyframes(render, poses)
        report = synthesize_keyframes(CAM, np.linspace(0.0, 1.0, n), keyframes, stride=4, threshold=2.0,
                                      noise_y=noise, patch=patch)
        return report, rendered, keyframes.written

    # Without blocks the sheen makes the schedule bisect: more keyframes rendered than the two anchors.
    plan_b, rendered_b, _ = run(None)
    assert len(rendered_b) > 2 and not plan_b.patched
    # With them only the anchors are rendered; every synthesized keyframe gets the same blocks, which hold the
    # sheen and cost less than one render in all, and are exactly the traced pixels; the rest scores ≤ 2 noise units.
    patch = _TracedBlocks(poses)
    plan, rendered, written = run(patch)
    assert sorted(rendered) == [0, 4] and patch.n_applied == 3 and set(plan.patched) == {1, 2, 3}
    costs = {cost for cost, _ in plan.patched.values()}
    assert len(costs) == 1 and 0 < costs.pop() * 3 <= PATCH_MAX_RENDERS
    assert all(after <= 2.0 for _, after in plan.patched.values())
    assert plan.patch_renders == pytest.approx(3 * plan.patched[1][0])
    for i in (1, 2, 3):
        truth, _, _ = _trace_with_sheen(poses[i])
        same = np.all(written[i] == truth, axis=-1)
        assert same.mean() < 0.5  # the rest is synthesized, not traced ...
        assert _rel_rms(written[i], truth) < 0.05  # ... and close to the truth everywhere, sheen included

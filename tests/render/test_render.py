"""Rendering: lux scaling, frozen noise, kernel reuse, cache and resume, adaptive schedule, bad input.

Scenes are tiny Mitsuba XML folders written into ``tmp_path`` (≤ 48×32 px, ≤ 16 spp).
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from scipy.spatial.transform import Rotation

from simspad.cli import main
from simspad.errors import SimSpadError
from simspad.io.exr import write_exr
from simspad.motion.generators import linear_pan, static_pose
from simspad.motion.trajectory import Trajectory, TrajectorySet, look_at
from simspad.physics import radiometry as rad
from simspad.radiance.timeline import Timeline
from simspad.render import schedule as sch
from simspad.render.mitsuba_scene import CompileCounter, emitter_order, load_canonical
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.scenes.library import resolve_scene, scene_dict_or_file
from simspad.sensors.presets import SpadParams

W, H = 48, 32
FOV_DEG = 40.0
CAMERA_Z = 2.0


def _scene_folder(root, *, reflectance='<rgb name="reflectance" value="0.18"/>', env=1.0, extra="",
                  camera_id="camera", toml=None):
    root.mkdir(parents=True, exist_ok=True)
    (root / "scene.xml").write_text(f"""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective" id="{camera_id}">
    <float name="fov" value="{FOV_DEG}"/>
    <transform name="to_world"><lookat origin="0, 0, {CAMERA_Z}" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="64"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="{env}"/></emitter>
  <shape type="rectangle" id="plane">
    <transform name="to_world"><scale value="10"/></transform>
    <bsdf type="diffuse">{reflectance}</bsdf>
  </shape>
  {extra}
</scene>
""")
    if toml is not None:
        (root / "scene.toml").write_text(toml)
    return root


def _textured_folder(root):
    tex = gaussian_filter(np.random.default_rng(3).random((256, 256)), 2.0)
    tex = (0.1 + 0.8 * (tex - tex.min()) / np.ptp(tex)).astype(np.float32)
    root.mkdir(parents=True, exist_ok=True)
    write_exr(root / "texture.exr", {"R": tex, "G": tex, "B": tex})
    return _scene_folder(root, reflectance='<texture type="bitmap" name="reflectance">'
                                           '<string name="filename" value="texture.exr"/>'
                                           '<boolean name="raw" value="true"/></texture>')


def _pan(velocity_m_s=(1.0, 0.0, 0.0), duration_s=0.2, yaw_rate_deg_s=0.0):
    pose = look_at((0.0, 0.0, CAMERA_Z), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    cam = linear_pan(pose[:3, 3], Rotation.from_matrix(pose[:3, :3]).as_quat(), velocity_m_s=velocity_m_s,
                     yaw_rate_deg_s=yaw_rate_deg_s, duration_s=duration_s, rate_hz=200.0)
    return TrajectorySet(camera=cam, objects={}, source="<pan>")


@pytest.fixture(scope="module", autouse=True)
def _variant():
    return select_variant()


# ------------------------------------------------------------------------------------------ radiometry
def test_flat_grey_scene_at_E_lux_has_mean_luminance_0_18_E_over_pi(tmp_path):
    lux = 50.0
    folder = _scene_folder(tmp_path / "grey", env=lux / math.pi)  # uniform sky radiance L gives E = π·L
    summary = render_sequence(folder, None, RenderSettings(duration_s=0.002, resolution=(W, H), spp=4,
                                                           min_rate_hz=1000.0), out_dir=tmp_path / "r",
                              progress=False)
    tl = Timeline.open(summary.out_dir)
    mean_y = float(tl.keyframe(0).mean(dtype=np.float64))
    assert mean_y == pytest.approx(0.18 * lux / math.pi, rel=0.02)
    # The lux convention applied to this physically lit scene changes (almost) nothing.
    assert rad.luminance_scale(mean_y, lux) == pytest.approx(1.0, rel=0.02)
    np.testing.assert_allclose(tl.keyframe_depth(0)[H // 2, W // 2], CAMERA_Z, rtol=0.02)


# ------------------------------------------------------------------------------------------ noise, kernels
def test_noise_is_frozen_and_renders_are_deterministic(tmp_path):
    folder = _textured_folder(tmp_path / "tex")
    a = render_sequence(folder, None, RenderSettings(duration_s=0.002, resolution=(W, H), spp=2),
                        out_dir=tmp_path / "a", progress=False)
    b = render_sequence(folder, None, RenderSettings(duration_s=0.002, resolution=(W, H), spp=2),
                        out_dir=tmp_path / "b", progress=False)
    ta, tb = Timeline.open(a.out_dir), Timeline.open(b.out_dir)
    # Static camera: every instant gives the same noise pattern (no flicker), and re-renders are bit-identical.
    np.testing.assert_array_equal(ta.rgb_keyframe(0), ta.rgb_keyframe(ta.n_keyframes - 1))
    np.testing.assert_array_equal(ta.rgb_keyframe(1), tb.rgb_keyframe(1))
    c = render_sequence(folder, None, RenderSettings(duration_s=0.002, resolution=(W, H), spp=2, seed=1),
                        out_dir=tmp_path / "c", progress=False)
    assert not np.array_equal(Timeline.open(c.out_dir).rgb_keyframe(0), ta.rgb_keyframe(0))


def test_no_kernel_recompilation_while_only_poses_change(tmp_path, _variant):
    if not _variant.startswith("llvm"):
        pytest.skip("kernel compilation is counted on the LLVM variant only")
    folder = _textured_folder(tmp_path / "tex")
    s = render_sequence(folder, _pan(), RenderSettings(duration_s=0.03, resolution=(W, H), spp=2, min_rate_hz=200.0,
                                                                   interpolation="linear"),
                        out_dir=tmp_path / "r", progress=False)
    assert s.n_rendered >= 6
    assert s.compiled_after_first == 0, s
    tl = Timeline.open(s.out_dir)
    assert not np.array_equal(tl.keyframe(0), tl.keyframe(tl.n_keyframes - 1))  # the camera did move
    # The counter does see compilations: a different integrator needs new kernels.
    import mitsuba as mi  # deferred: heavy; imported once the variant is set

    counter = CompileCounter(_variant)
    scene = mi.load_file(str(folder / "scene.xml"))
    mi.render(scene, integrator=mi.load_dict({"type": "direct", "emitter_samples": 3}), spp=1, seed=0).numpy()
    assert counter.take() > 0


def test_simspad_render_compares_with_the_spad_preset_bin(tmp_path, capsys):
    # The renderer knows no sensor: the CLI passes the SPAD preset's bin, and the comparison reaches the
    # printed summary and timeline.json.
    folder = _scene_folder(tmp_path / "scene")
    out = tmp_path / "r"
    assert main(["render", str(folder), "--duration", "0.002", "--resolution", f"{W}x{H}", "--spp", "1",
                 "--out", str(out)]) == 0
    n_bins = sch.brute_force_keyframes(0.002, SpadParams().bin_s)
    assert f"versus one per 10.24 µs SPAD bin: {n_bins} renders" in capsys.readouterr().out
    schedule = json.loads((out / "timeline.json").read_text())["schedule"]
    assert list(schedule)[:3] == ["n_keyframes", "n_spad_bins", "max_predicted_flow_px"]
    assert schedule["n_spad_bins"] == n_bins


# ------------------------------------------------------------------------------------------ stages
def test_stages_in_chunks_give_the_bytes_of_one_render(tmp_path):
    """plan → keyframes in two interleaved chunks, each in its own scene load (as two workers) → the noise probe →
    finalize: every file byte-identical to render_sequence's; finalizing with a keyframe missing is refused."""
    from simspad.render.render_layout import RenderLayout
    from simspad.render.renderer import finalize_render, layout_render, render_keyframes, render_probe

    folder = _textured_folder(tmp_path / "tex")
    settings = RenderSettings(duration_s=0.03, resolution=(W, H), spp=2, min_rate_hz=100.0)
    render_sequence(folder, _pan(), settings, out_dir=tmp_path / "whole", progress=False)
    plan = RenderLayout.from_dict(layout_render(folder, _pan(), settings).to_dict())  # as it travels to workers
    assert plan.n_keyframes >= 4
    out = tmp_path / "chunks"
    render_keyframes(folder, _pan(), plan, range(1, plan.n_keyframes, 2), out_dir=out)
    with pytest.raises(SimSpadError, match="not rendered yet"):
        finalize_render(plan, out)
    done = render_keyframes(folder, _pan(), plan, range(plan.n_keyframes - 1, -1, -1), out_dir=out)
    assert (len(done.frame_times_s), done.n_reused) == (plan.n_keyframes - plan.n_keyframes // 2,
                                                        plan.n_keyframes // 2)
    assert render_probe(folder, _pan(), plan, out_dir=out)  # the render-noise budget's probe, as a stage of its own
    assert not render_probe(folder, _pan(), plan, out_dir=out)  # there already
    finalize_render(plan, out)
    assert json.loads((out / "timeline.json").read_text())["render_noise"]["relative_noise_median"] > 0
    files = sorted(p.relative_to(tmp_path / "whole") for p in (tmp_path / "whole").rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    for rel in files:
        assert (out / rel).read_bytes() == (tmp_path / "whole" / rel).read_bytes(), rel


# ------------------------------------------------------------------------------------------ cache, resume
def test_cache_reuse_resume_and_invalidation(tmp_path):
    folder = _textured_folder(tmp_path / "tex")
    settings = RenderSettings(duration_s=0.05, resolution=(W, H), spp=2, min_rate_hz=100.0, interpolation="linear")
    kwargs = dict(out_dir=tmp_path / "r", progress=False)
    first = render_sequence(folder, _pan(), settings, **kwargs)
    doc = (tmp_path / "r" / "timeline.json").read_text()
    frames = sorted(p for p in (tmp_path / "r" / "frames").iterdir() if not p.name.startswith("noise-probe-"))
    reference = Timeline.open(tmp_path / "r").rgb_keyframe(2)

    again = render_sequence(folder, _pan(), settings, **kwargs)
    assert (again.n_rendered, again.n_reused) == (0, first.n_keyframes)
    assert (tmp_path / "r" / "timeline.json").read_text() == doc

    # An interrupted render: timeline.json (written last) and two frames are missing.
    (tmp_path / "r" / "timeline.json").unlink()
    frames[2].unlink()
    frames[-1].unlink()
    resumed = render_sequence(folder, _pan(), settings, **kwargs)
    assert (resumed.n_rendered, resumed.n_reused) == (2, first.n_keyframes - 2)
    np.testing.assert_array_equal(Timeline.open(tmp_path / "r").rgb_keyframe(2), reference)

    # Another setting: everything is rendered anew and the old frames are removed.
    other = render_sequence(folder, _pan(), replace(settings, spp=3), **kwargs)
    assert other.n_reused == 0
    assert len(list((tmp_path / "r" / "frames").iterdir())) == other.n_keyframes + 1  # and its noise probe
    assert len(list((tmp_path / "r" / "frames").glob("noise-probe-*.exr"))) == 1  # the old one is gone
    assert not list((tmp_path / "r").glob(".*tmp*")) and not list((tmp_path / "r" / "frames").glob(".*"))


# ------------------------------------------------------------------------------------------ schedule
def test_schedule_constant_speed_and_min_rate():
    times = sch.keyframe_schedule(0.0, 0.1, lambda t: np.full(np.shape(t), 200.0), 0.5, 10.0)
    steps = np.diff(times)
    assert times[0] == 0.0 and times[-1] == 0.1
    assert np.all(steps * 200.0 <= 0.5 + 1e-9) and np.median(steps) * 200.0 > 0.45
    still = sch.keyframe_schedule(0.0, 0.01, lambda t: np.zeros(np.shape(t)), 0.5, 1000.0)
    assert np.allclose(np.diff(still), 1e-3) and still.size == 11


def test_schedule_bounds_integrated_flow_of_a_ramp():
    speed = lambda t: 50.0 + 4e4 * np.asarray(t)  # px/s
    times = sch.keyframe_schedule(0.0, 0.05, speed, 0.5, 100.0)
    flow = 50.0 * np.diff(times) + 2e4 * np.diff(times**2)  # exact ∫ speed dt per step
    assert flow.max() <= 0.5 + 1e-9
    assert np.median(flow) > 0.4  # not wastefully small


def _project(camera_to_world, points, focal_px):
    cam = np.linalg.inv(camera_to_world)
    p = points @ cam[:3, :3].T + cam[:3, 3]
    return focal_px * p[:, :2] / p[:, 2:3]


@pytest.mark.parametrize("velocity, yaw", [((0.8, 0.3, 0.0), 0.0), ((0.0, 0.0, 0.5), 0.0), ((0.0, 0.0, 0.0), 25.0),
                                           ((0.3, 0.0, 0.2), 10.0)])
def test_camera_flow_bound_matches_projected_motion(velocity, yaw):
    ts = _pan(velocity, duration_s=0.1, yaw_rate_deg_s=yaw)
    focal = sch.focal_length_px(FOV_DEG, W)
    depth = CAMERA_Z
    t, dt = 0.05, 1e-5
    pose_a, pose_b = ts.camera.pose(t), ts.camera.pose(t + dt)
    # Points of the plane z = 0 that lie inside the image at t.
    x, y = sch.flow_grid(W, H, focal)
    rays = np.stack([x, y, np.ones_like(x)], axis=1)
    measured = 0.0
    for z in (depth, 1e5):  # the bound covers every depth from the near one to infinity
        world = (rays * z) @ pose_a[:3, :3].T + pose_a[:3, 3]
        shift = np.linalg.norm(_project(pose_b, world, focal) - _project(pose_a, world, focal), axis=1)
        measured = max(measured, np.max(shift) / dt)
    v, w = ts.camera.velocity(np.array([t]))
    predicted = sch.camera_flow_bound(pose_a[None], v, w, depth, focal, W, H)[0]
    assert measured <= predicted * 1.001
    assert measured >= predicted * 0.95  # a bound, and a tight one


def _centroid_col(image):
    weight = np.clip(image - np.median(image), 0, None)
    return float(np.sum(weight * np.arange(image.shape[1])[None, :]) / np.sum(weight))


def test_schedule_respects_max_flow_on_a_rendered_pan(tmp_path):
    # A white patch on a black plane: its centroid is the measured image motion.
    patch = ('<shape type="rectangle" id="patch"><transform name="to_world"><scale value="0.06"/>'
             '<translate z="0.01"/></transform><bsdf type="diffuse"><rgb name="reflectance" value="1.0"/></bsdf>'
             '</shape>')
    folder = _scene_folder(tmp_path / "patch", reflectance='<rgb name="reflectance" value="0.0"/>', extra=patch)
    speed_px_s = sch.focal_length_px(FOV_DEG, W) * 1.0 / CAMERA_Z
    duration = 4.0 / speed_px_s  # a 4 px pan
    settings = RenderSettings(duration_s=duration, resolution=(W, H), spp=8, max_flow_px=0.5, min_rate_hz=1.0)
    s = render_sequence(folder, _pan((1.0, 0.0, 0.0), duration_s=0.2), settings, out_dir=tmp_path / "r",
                        progress=False)
    tl = Timeline.open(s.out_dir)
    assert s.max_predicted_flow_px <= 0.5 + 1e-6
    assert tl.n_keyframes >= 9  # 4 px in steps of at most 0.5 px
    predicted = np.diff(tl.times_s) * speed_px_s
    assert predicted.max() <= 0.5 + 1e-6
    cols = np.array([_centroid_col(tl.keyframe(i)) for i in range(tl.n_keyframes)])
    measured_speed_px_s = abs(np.polyfit(tl.times_s, cols, 1)[0])  # fit: robust to per-frame centroid noise
    assert measured_speed_px_s == pytest.approx(speed_px_s, rel=0.05)
    assert measured_speed_px_s * np.diff(tl.times_s).max() <= 0.5 * 1.05
    assert abs(cols[-1] - cols[0]) == pytest.approx(predicted.sum(), rel=0.08)


# ------------------------------------------------------------------------------------------ objects
@pytest.mark.slow
def test_object_trajectory_moves_the_mesh(tmp_path):
    cube = ('<shape type="cube" id="box"><transform name="to_world"><scale value="0.15"/></transform>'
            '<bsdf type="diffuse"><rgb name="reflectance" value="0.0"/></bsdf></shape>')
    folder = _scene_folder(tmp_path / "obj", reflectance='<rgb name="reflectance" value="0.5"/>', extra=cube)
    box = Trajectory([0.0, 0.01], [[-0.3, 0.0, 0.5], [0.3, 0.0, 0.5]], [[0, 0, 0, 1], [0, 0, 0, 1]])
    ts = TrajectorySet(camera=None, objects={"box": box}, source="<box>")
    s = render_sequence(folder, ts, RenderSettings(duration_s=0.01, resolution=(W, H), spp=4, min_rate_hz=200.0),
                        out_dir=tmp_path / "r", progress=False)
    tl = Timeline.open(s.out_dir)
    focal = sch.focal_length_px(FOV_DEG, W)
    for i in (0, tl.n_keyframes - 1):
        dark = tl.keyframe(i) < 0.1
        col = np.mean(np.nonzero(dark)[1]) + 0.5
        expected_x = box.position(tl.times_s[i])[0]
        # Mitsuba's camera x points to the left: world +x appears toward smaller columns when looking along −z.
        predicted_col = W / 2 + focal * expected_x / (CAMERA_Z - 0.5)
        assert col == pytest.approx(predicted_col, abs=1.0)
        assert np.nanmin(tl.keyframe_depth(i)) == pytest.approx(CAMERA_Z - 0.5 - 0.15, rel=0.05)
    # Object speed 60 m/s at 1.35 m: the schedule follows the object, far above the 200 Hz floor.
    assert s.n_keyframes > 0.01 * 200 * 3
    assert s.compiled_after_first in (0, -1), s  # moving vertices does not recompile either
    assert np.isinf(tl.depth(0.5 * (tl.times_s[0] + tl.times_s[1]))).sum() == 0  # the wall is everywhere behind


# ------------------------------------------------------------------------------------------ bad input
def test_bad_input_is_one_clear_error_and_nothing_is_written(tmp_path):
    folder = _scene_folder(tmp_path / "grey")
    out = tmp_path / "out"
    with pytest.raises(SimSpadError, match="unknown scene 'no-such-scene'"):
        render_sequence("no-such-scene", None, RenderSettings(duration_s=0.01), out_dir=out, progress=False)
    bad_cam = _scene_folder(tmp_path / "badcam", toml='camera_id = "missing"\n')
    with pytest.raises(SimSpadError, match="no sensor with id 'missing'") as info:
        render_sequence(bad_cam, None, RenderSettings(duration_s=0.01, resolution=(W, H)), out_dir=out,
                        progress=False)
    assert "camera_id" in str(info.value)
    with pytest.raises(SimSpadError, match=r"covers \[0, 0.2\] s but the render needs \[0.1, 0.4\] s"):
        render_sequence(folder, _pan(), RenderSettings(start_s=0.1, duration_s=0.3, resolution=(W, H)), out_dir=out,
                        progress=False)
    with pytest.raises(SimSpadError, match="no shape with that id"):
        render_sequence(folder, TrajectorySet(None, {"ghost": static_pose()}, "<ghost>"),
                        RenderSettings(duration_s=0.01, resolution=(W, H)), out_dir=out, progress=False)
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(SimSpadError, match="not a directory"):
        render_sequence(folder, None, RenderSettings(duration_s=0.01), out_dir=blocker / "sub", progress=False)
    with pytest.raises(SimSpadError, match="spp"):
        render_sequence(folder, None, RenderSettings(duration_s=0.01, spp=0), out_dir=out, progress=False)
    assert not out.exists()


def test_timeline_reads_mitsuba_written_exr(tmp_path):
    import mitsuba as mi  # deferred: heavy; imported once the variant is set

    rgb = np.random.default_rng(0).random((H, W, 3)).astype(np.float32)
    (tmp_path / "f").mkdir()
    mi.Bitmap(rgb).write(str(tmp_path / "f" / "a.exr"))
    doc = {"format": "simspad-timeline", "version": 1, "width": W, "height": H,
           "keyframes": [{"t": 0.0, "file": "f/a.exr"}, {"t": 1.0, "file": "f/a.exr"}]}
    (tmp_path / "timeline.json").write_text(json.dumps(doc))
    tl = Timeline.open(tmp_path)
    np.testing.assert_allclose(tl.sample(0.3), rad.luminance_from_rgb(rgb), rtol=1e-6)


@pytest.mark.slow
def test_scene_loads_list_emitters_in_canonical_order():
    # Mitsuba 3.9 permutes emitters between loads; emitter sampling picks by index, so without a canonical order
    # the same render seed gives different noise in different processes (office has three emitters).
    select_variant()
    import mitsuba as mi  # deferred: heavy; imported once the variant is set

    source = scene_dict_or_file(resolve_scene("office"))
    orders = {tuple(emitter_order(load_canonical(mi, source, "office"))) for _ in range(8)}
    assert len(orders) == 1 and list(next(iter(orders))) == sorted(next(iter(orders)))
    assert len(next(iter(orders))) >= 3


# ------------------------------------------------------------------------------------------ damaged cache
def test_a_truncated_cached_keyframe_is_rendered_again(tmp_path):
    from simspad.dataset.directory import check_render_cache
    from simspad.io.hashing import file_sha256

    folder = _textured_folder(tmp_path / "tex")
    settings = RenderSettings(duration_s=0.002, resolution=(W, H), spp=2)
    first = render_sequence(folder, None, settings, out_dir=tmp_path / "r", progress=False)
    frames = sorted((tmp_path / "r" / "frames").glob("*.exr"))
    good = file_sha256(frames[1])
    frames[1].write_bytes(frames[1].read_bytes()[: frames[1].stat().st_size // 2])  # a disk that filled up
    logged = []
    assert not check_render_cache(tmp_path / "r", logged.append)  # generate's check: timeline removed, re-render
    assert "damaged keyframe" in logged[0] and not (tmp_path / "r" / "timeline.json").exists()
    again = render_sequence(folder, None, settings, out_dir=tmp_path / "r", progress=False)
    assert again.n_reused == first.n_keyframes - 1 and again.n_rendered == 1
    assert file_sha256(frames[1]) == good  # re-rendered bit-identically
    assert check_render_cache(tmp_path / "r", logged.append) and len(logged) == 1

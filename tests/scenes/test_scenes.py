"""Scene library: every built-in scene renders (tiny, real Mitsuba renders) with real contrast, the HDR scenes
reach 10³ dynamic range, rotating objects animate only where they are, users' XML scenes work, unknown scenes
are refused, and ``simspad scenes`` lists and draws them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from scipy.ndimage import gaussian_filter

from simspad.cli import main
from simspad.errors import SimSpadError
from simspad.io.trajectory_files import load_trajectory
from simspad.radiance.timeline import Timeline
from simspad.render.contact_sheet import LABEL_HEIGHT_PX, tone_map, write_contact_sheet
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.scenes.library import builtin_scene_names, list_scenes, resolve_scene

REQUIRED = {"office", "piano", "plant", "siemens-star", "fan"}
SIZE = (48, 36)
SPP = 4
LUMA = np.array([0.2126, 0.7152, 0.0722])


def _render(scene, out_dir, *, duration_s=1e-3, min_rate_hz=1e3, trajectory=None, spp=SPP):
    """Render the span [0, duration_s] with keyframes only at its ends; returns the opened Timeline."""
    render_sequence(scene, trajectory, RenderSettings(duration_s=duration_s, resolution=SIZE, spp=spp,
                                                      max_flow_px=1e6, min_rate_hz=min_rate_hz), out_dir=out_dir,
                    progress=False)
    return Timeline.open(out_dir)


@pytest.fixture(scope="module")
def first_frames(tmp_path_factory):
    """Linear RGB of each built-in scene at t = 0 of its default trajectory."""
    root = tmp_path_factory.mktemp("scenes")
    return {name: _render(name, root / name).rgb_keyframe(0) for name in sorted(REQUIRED)}


def test_builtin_scenes_exist_with_default_trajectories_covering_a_sequence():
    assert REQUIRED <= set(builtin_scene_names())
    for info in list_scenes():
        assert info.default_trajectory is not None and info.description, info.name
        ts = load_trajectory(info.default_trajectory)
        assert ts.t_start <= 0.0 and ts.t_end >= 0.1, info.name
        assert set(ts.objects) <= set(info.objects), info.name  # every animated body is a declared object


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_scene_renders_finite_nonnegative_radiance_with_contrast(first_frames, name):
    rgb = first_frames[name]
    assert rgb.shape == (SIZE[1], SIZE[0], 3)
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0.0
    lum = gaussian_filter(rgb @ LUMA, 1.0)  # σ = 1 px: contrast of regions, not of Monte Carlo noise
    p5, p95 = np.percentile(lum, [5, 95])
    assert p5 > 0 and p95 / p5 > 3.0, (name, p5, p95)
    # texture, not flat blocks: local detail (difference from a 2 px blur) in a large part of the image
    detail = np.abs(lum - gaussian_filter(lum, 2.0)) / (gaussian_filter(lum, 2.0) + 1e-9)
    assert np.mean(detail > 0.05) > 0.15, name


@pytest.mark.slow
@pytest.mark.parametrize("name", ["office", "plant"])
def test_hdr_scenes_reach_1e3_between_brightest_and_darkest_regions(first_frames, name):
    # Luminance smoothed over σ = 1 px (regions of ~3×3 px, so MC noise does not count as contrast); the 99th
    # percentile (the window) over the 1st (shadows under the desk / beside the pot).
    lum = gaussian_filter(first_frames[name] @ LUMA, 1.0)
    p1, p99 = np.percentile(lum, [1, 99])
    assert p1 > 0
    assert p99 / p1 >= 1e3, (name, p1, p99)


def _disk_mask(render_dir, center_m, radius_m):
    """Distance (px) of each pixel centre from the image of ``center_m`` and the image radius of ``radius_m``.

    Mitsuba's camera looks along local +Z with local +X to the image's left and +Y up.
    """
    meta = json.loads((render_dir / "timeline.json").read_text())
    cam = np.asarray(meta["keyframes"][0]["camera_to_world"], dtype=np.float64)
    focal = float(meta["renderer"]["focal_px"])
    c = np.linalg.solve(cam, np.append(np.asarray(center_m, dtype=np.float64), 1.0))[:3]
    u0, v0 = SIZE[0] / 2 - focal * c[0] / c[2], SIZE[1] / 2 - focal * c[1] / c[2]
    v, u = np.mgrid[0:SIZE[1], 0:SIZE[0]] + 0.5
    return np.hypot(u - u0, v - v0), focal * radius_m / c[2]


@pytest.mark.slow
@pytest.mark.parametrize("name, center_m, radius_m, half_period_s", [
    ("fan", (0.0, 0.62, 0.0), 0.17, 0.5 * 60.0 / 600.0 / 5),     # 5 blades at 600 rpm: half a blade period
    ("siemens-star", (0.0, 0.0, 0.0), 0.25, 0.5 * 60.0 / 60.0 / 36),  # 36 cycles at 60 rpm: half a cycle
])
def test_rotating_object_changes_the_image_only_where_it_is(tmp_path, name, center_m, radius_m, half_period_s):
    info = resolve_scene(name)
    assert info.objects
    tl = _render(name, tmp_path / "r", duration_s=half_period_s, min_rate_hz=1.0 / half_period_s)
    assert tl.n_keyframes == 2
    a, b = (tl.rgb_keyframe(i) @ LUMA for i in (0, 1))
    dist, r_px = _disk_mask(tmp_path / "r", center_m, radius_m)
    inside, outside = dist <= r_px + 1.0, dist >= r_px + 3.0  # margin: 0.5 px PSF + pixel footprint
    diff = np.abs(b - a)
    scale = float(np.mean(a))
    assert inside.sum() > 100 and outside.sum() > 100
    assert diff[inside].mean() > 0.1 * scale, (diff[inside].mean(), scale)
    # outside the rotor only light bounced off it changes: at least 20× less than where it is
    assert diff[outside].mean() < 0.05 * diff[inside].mean(), (diff[outside].mean(), diff[inside].mean())


XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective" id="my_cam">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>
  </sensor>
  <shape type="rectangle">
    <bsdf type="diffuse">
      <texture type="checkerboard" name="reflectance">
        <rgb name="color0" value="0.05"/><rgb name="color1" value="0.8"/>
        <transform name="to_uv"><scale x="6" y="6"/></transform>
      </texture>
    </bsdf>
  </shape>
  <emitter type="constant"><rgb name="radiance" value="1.0"/></emitter>
</scene>
"""


def test_user_xml_scene_folder_resolves_and_renders(tmp_path):
    folder = tmp_path / "my_scene"
    folder.mkdir()
    (folder / "scene.xml").write_text(XML)
    info = resolve_scene(folder)
    assert info.camera_id == "my_cam" and not info.builtin and info.default_trajectory is None
    tl = _render(folder, tmp_path / "r", trajectory=None, spp=2)
    lum = tl.rgb_keyframe(0) @ LUMA
    assert np.all(np.isfinite(lum)) and lum.min() >= 0.0
    # the checkerboard fills the view: its two reflectances (0.05, 0.8 under unit radiance) both show up
    lo, hi = np.percentile(lum, [10, 90])
    assert lo < 0.15 and hi > 0.5, (lo, hi)


def test_unknown_scene_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(SimSpadError, match="unknown scene 'no-such-scene'"):
        resolve_scene("no-such-scene")
    with pytest.raises(SimSpadError, match="no-such-scene"):
        render_sequence("no-such-scene", None, RenderSettings(duration_s=1e-3, resolution=SIZE, spp=1),
                        out_dir=tmp_path / "r", progress=False)
    assert not (tmp_path / "r").exists()


def test_simspad_scenes_lists_every_scene_with_its_trajectory(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(builtin_scene_names())
    for name in REQUIRED:
        (line,) = [ln for ln in lines if ln.split()[0] == name]
        assert f"trajectories/{name}.toml" in line
    assert any("[animated: blades]" in ln for ln in lines)


@pytest.mark.slow
def test_contact_sheet_tiles_tone_mapped_labelled_renders(tmp_path):
    out = write_contact_sheet(tmp_path / "sheet.png", ["fan", "office"], columns=2, resolution=(40, 30), spp=2)
    sheet = np.asarray(Image.open(out).convert("RGB"), dtype=np.float64)
    gap = 4
    assert sheet.shape == (30 + LABEL_HEIGHT_PX + 2 * gap, 2 * 40 + 3 * gap, 3)
    for col in range(2):  # each picture has real tonal range (not blank, not clipped flat)
        x0 = gap + col * (40 + gap)
        tile = sheet[gap + LABEL_HEIGHT_PX:gap + LABEL_HEIGHT_PX + 30, x0:x0 + 40].mean(axis=2)
        assert tile.std() > 20 and np.percentile(tile, 95) - np.percentile(tile, 5) > 60
    # HDR: a 10⁴:1 ramp keeps distinct display levels at both ends, monotonically
    ramp = np.logspace(-3, 1, 64)[None, :, None].repeat(3, axis=2)
    disp = tone_map(ramp)[0, :, 0]
    assert np.all(np.diff(disp) > 0) and disp[0] < 0.1 and disp[-1] > 0.95

"""Timeline: piecewise-linear radiance, exact integration, lazy streaming, render-directory validation."""

import json
import math

import numpy as np
import OpenEXR
import pytest
from scipy.integrate import quad_vec

from simspad.errors import InputError
from simspad.io.render_dir import write_render_dir
from simspad.physics import radiometry as rad
from simspad.radiance.timeline import Timeline

H, W = 6, 8


def _frames(k, seed=0):
    return np.random.default_rng(seed).gamma(2.0, 0.5, size=(k, H, W, 3)).astype(np.float32)


@pytest.fixture
def render_dir(tmp_path):
    times = np.array([0.0, 1e-4, 2.5e-4, 3e-4, 7e-4])
    frames = _frames(times.size)
    depth = np.random.default_rng(5).uniform(1, 3, size=(times.size, H, W))
    poses = np.tile(np.eye(4), (times.size, 1, 1))
    poses[:, 0, 3] = times * 10
    write_render_dir(tmp_path / "r", times, frames, depth=depth, poses=poses, scene="test")
    return tmp_path / "r", times, frames, depth, poses


def test_open_round_trip(render_dir):
    path, times, frames, depth, poses = render_dir
    tl = Timeline.open(path)
    assert (tl.width, tl.height, tl.n_keyframes) == (W, H, times.size)
    np.testing.assert_array_equal(tl.times_s, times)
    np.testing.assert_array_equal(tl.poses, poses)
    assert tl.has_depth and tl.meta["scene"] == "test"
    for i in range(times.size):
        np.testing.assert_allclose(tl.keyframe(i), rad.luminance_from_rgb(frames[i]), rtol=1e-6)
        np.testing.assert_allclose(tl.rgb_keyframe(i), frames[i], rtol=1e-6)
        np.testing.assert_allclose(tl.keyframe_depth(i), depth[i], rtol=1e-6)


def test_sample_is_linear_between_keyframes(render_dir):
    tl = Timeline.open(render_dir[0])
    t = 0.4 * 1e-4 + 0.6 * 2.5e-4
    np.testing.assert_allclose(tl.sample(t), 0.4 * tl.keyframe(1) + 0.6 * tl.keyframe(2), rtol=1e-5)
    np.testing.assert_allclose(tl.depth(t), 0.4 * tl.keyframe_depth(1) + 0.6 * tl.keyframe_depth(2), rtol=1e-5)
    np.testing.assert_array_equal(tl.sample(3e-4), tl.keyframe(3))
    np.testing.assert_array_equal(tl.sample(7e-4 + 1e-10), tl.keyframe(4))  # round-off tolerance
    for bad in (-1e-6, 8e-4):
        with pytest.raises(ValueError, match="outside the timeline"):
            tl.sample(bad)


@pytest.mark.parametrize("t0, t1", [(0.0, 7e-4), (0.3e-4, 6.1e-4), (1e-4, 2.5e-4), (1.2e-4, 1.9e-4)])
def test_integrate_is_exact_against_quadrature(render_dir, t0, t1):
    tl = Timeline.open(render_dir[0])
    breaks = [t for t in tl.times_s if t0 < t < t1]
    reference, _ = quad_vec(lambda t: tl.sample(t).astype(np.float64), t0, t1, points=breaks or None,
                            epsabs=0, epsrel=1e-6)
    got = tl.integrate(t0, t1)
    np.testing.assert_allclose(got, reference, rtol=2e-6)
    # Additive over a split point, and the mean of a constant-free piece is its midpoint value.
    mid = 0.5 * (t0 + t1)
    np.testing.assert_allclose(tl.integrate(t0, mid) + tl.integrate(mid, t1), got, rtol=2e-6)


def test_segments_cover_the_interval_contiguously(render_dir):
    tl = Timeline.open(render_dir[0])
    pieces = list(tl.segments(0.5e-4, 6e-4))
    assert pieces[0][0] == 0.5e-4 and pieces[-1][1] == 6e-4
    assert [p[1] for p in pieces[:-1]] == [p[0] for p in pieces[1:]]
    assert [p[1] for p in pieces[:-1]] == [1e-4, 2.5e-4, 3e-4]
    for ta, tb, ya, yb in pieces:
        np.testing.assert_allclose(ya, tl.sample(ta), rtol=1e-6)
        np.testing.assert_allclose(yb, tl.sample(tb), rtol=1e-6)
    assert list(tl.segments(2e-4, 2e-4)) == []


def test_scaled_and_photon_flux(render_dir):
    tl = Timeline.open(render_dir[0])
    np.testing.assert_allclose(tl.scaled(3.0).integrate(0, 7e-4), 3.0 * tl.integrate(0, 7e-4), rtol=1e-6)
    flux = tl.photon_flux(10.0)
    expected_mean = 0.18 * 10.0 / math.pi * math.pi * 0.9 / (4 * 2.0**2) * rad.photons_per_lux("D65")
    assert float(flux.keyframe(0).mean(dtype=np.float64)) == pytest.approx(expected_mean, rel=1e-5)


def test_memory_does_not_grow_with_keyframes():
    k = 60
    times = np.arange(k) * 1e-5
    tl = Timeline.from_arrays(times, _frames(k)[..., 0])
    for t in np.linspace(0, times[-1], 500):
        tl.sample(t)
    tl.integrate(0, times[-1])
    assert len(tl._cache._frames) <= 4


def test_from_arrays_rgb_and_validation():
    times = [0.0, 1.0]
    rgb = _frames(2)
    tl = Timeline.from_arrays(times, rgb)
    np.testing.assert_allclose(tl.keyframe(1), rad.luminance_from_rgb(rgb[1]), rtol=1e-6)
    with pytest.raises(ValueError, match="strictly increasing"):
        Timeline.from_arrays([0.0, 0.0], rgb)
    with pytest.raises(ValueError, match="non-negative"):
        Timeline.from_arrays(times, -rgb)


def _write_channels(path, channels):
    path.parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as f:
        f.write(str(path))


def test_reads_other_renderers_y_half_and_rgb_half(tmp_path):
    y = np.full((H, W), 0.25, np.float16)
    _write_channels(tmp_path / "a.exr", {"Y": y, "Z": np.ones((H, W), np.float16)})
    _write_channels(tmp_path / "b.exr", {c: np.full((H, W), 0.5, np.float16) for c in "RGB"})
    doc = {"format": "simspad-timeline", "version": 1, "width": W, "height": H,
           "keyframes": [{"t": 0.5, "file": "a.exr"}, {"t": 0.75, "file": "b.exr"}]}
    (tmp_path / "timeline.json").write_text(json.dumps(doc))
    tl = Timeline.open(tmp_path)
    assert not tl.has_depth and tl.poses is None
    np.testing.assert_allclose(tl.sample(0.625), 0.375, rtol=1e-6)
    np.testing.assert_allclose(tl.rgb_keyframe(0), 0.25)
    assert tl.keyframe(0).dtype == np.float32


def _corrupt(case, root):
    meta_path = root / "timeline.json"
    doc = json.loads(meta_path.read_text())
    frame0 = root / doc["keyframes"][0]["file"]
    if case == "missing timeline.json":
        meta_path.unlink()
    elif case == "bad json":
        meta_path.write_text("{not json")
    elif case == "format":
        doc["format"] = "other"
    elif case == "version":
        doc["version"] = 7
    elif case == "missing frame":
        (root / doc["keyframes"][2]["file"]).unlink()
    elif case == "non-increasing t":
        doc["keyframes"][3]["t"] = doc["keyframes"][2]["t"]
    elif case == "size mismatch":
        doc["width"] = W + 1
    elif case == "nan radiance":
        _write_channels(frame0, {c: np.full((H, W), np.nan, np.float32) for c in "RGB"})
    elif case == "negative radiance":
        _write_channels(frame0, {c: np.full((H, W), -1.0, np.float32) for c in "RGB"})
    elif case == "missing channels":
        _write_channels(frame0, {"A": np.ones((H, W), np.float32)})
    elif case == "bad pose":
        doc["keyframes"][1]["camera_to_world"] = [[1, 0], [0, 1]]
    if case not in ("missing timeline.json", "bad json"):
        meta_path.write_text(json.dumps(doc))
    return frame0


@pytest.mark.parametrize("case, where, field", [
    ("missing timeline.json", "r", "timeline.json"),
    ("bad json", "timeline.json", "JSON"),
    ("format", "timeline.json", "format"),
    ("version", "timeline.json", "version"),
    ("missing frame", "timeline.json", "keyframes[2].file"),
    ("non-increasing t", "timeline.json", "keyframes[3].t"),
    ("size mismatch", "000000.exr", "dataWindow"),
    ("nan radiance", "000000.exr", "NaN"),
    ("negative radiance", "000000.exr", "negative radiance"),
    ("missing channels", "000000.exr", "channels"),
    ("bad pose", "timeline.json", "keyframes[1].camera_to_world"),
])
def test_open_reports_file_and_field(render_dir, case, where, field):
    root = render_dir[0]
    _corrupt(case, root)
    with pytest.raises(InputError) as info:
        tl = Timeline.open(root)
        tl.keyframe(0)  # pixel values are checked when a frame is read
    message = str(info.value)
    assert where in message and field in message, message


def test_depth_with_no_hit_pixels_never_becomes_nan():
    z0 = np.full((H, W), 2.0, np.float32)
    z1 = z0.copy()
    z0[0, 0] = z1[0, 0] = np.inf  # sky in both
    z1[1, 1] = np.inf  # sky appears
    tl = Timeline.from_arrays([0.0, 1.0], np.ones((2, H, W), np.float32), depth=np.stack([z0, z1]))
    early, late = tl.depth(0.25), tl.depth(0.75)
    assert not np.isnan(early).any() and not np.isnan(late).any()
    assert np.isinf(early[0, 0]) and early[1, 1] == 2.0 and np.isinf(late[1, 1])
    assert early[2, 2] == pytest.approx(2.0)

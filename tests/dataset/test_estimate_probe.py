"""The estimate's simulation probe runs on its small render with every pixel repeated towards the spec's width:
the upsampled render directory is the same content, instants and poses at the larger size, with its noise probe
and geometry passes."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from simspad.dataset.estimate import _settings, upsample_render_dir
from simspad.dataset.spec_validation import spec_from_dict
from simspad.io.exr import read_exr
from simspad.io.geometry import read_geometry
from simspad.physics.radiometry import Optics
from simspad.render.renderer import render_sequence
from simspad.sensors.simulate import RecordingSettings, simulate_recording
from simspad.io.render_dir import write_render_dir
from simspad.radiance.timeline import Timeline


def test_upsampled_render_repeats_every_pixel_and_keeps_instants_and_poses(tmp_path):
    rng = np.random.default_rng(0)
    times = np.array([0.0, 1e-3, 2.5e-3])
    rgb = rng.uniform(0.0, 5.0, (3, 4, 6, 3)).astype(np.float32)
    depth = rng.uniform(1.0, 3.0, (3, 4, 6)).astype(np.float32)
    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, 0, 3] = [0.0, 0.01, 0.02]
    src = write_render_dir(tmp_path / "src", times, rgb, depth=depth, poses=poses).parent
    dst = upsample_render_dir(src, tmp_path / "dst", 3)

    small, big = Timeline.open(src), Timeline.open(dst)
    assert (big.width, big.height) == (18, 12)
    np.testing.assert_array_equal(big.times_s, small.times_s)
    np.testing.assert_array_equal(big.poses, small.poses)
    for i in range(3):
        block = np.ones((3, 3), np.float32)
        np.testing.assert_array_equal(big.keyframe(i), np.kron(small.keyframe(i), block))
        np.testing.assert_array_equal(big.keyframe_depth(i), np.kron(small.keyframe_depth(i), block))
        np.testing.assert_array_equal(big.rgb_keyframe(i), np.repeat(np.repeat(small.rgb_keyframe(i), 3, 0), 3, 1))
    a, b = (json.loads((d / "timeline.json").read_text()) for d in (src, dst))
    assert {k: v for k, v in a.items() if k not in ("width", "height")} == \
        {k: v for k, v in b.items() if k not in ("width", "height")}
    assert set(read_exr(dst / a["keyframes"][0]["file"])) == {"rgb", "z"}


@pytest.mark.slow
def test_the_upsampled_probe_render_simulates_with_its_noise_budget_and_geometry(tmp_path):
    """The estimate's probe render as ``_probe_simulation`` renders it (a noise probe, geometry passes at the
    ground-truth instants), upsampled: every file its timeline names is there at the larger size, and a recording
    simulates from it (a paper-scale spec, 512 px wide, upsamples its probe 4×)."""
    spec = spec_from_dict({"name": "up", "seed": 1, "lux": [100], "speed": [1],
                           "sequences": [{"scene": "siemens-star", "duration_s": 0.004, "resolution": [16, 12],
                                          "spp": 1}],
                           "sensors": {"events": {"preset": "prophesee_gen4"}}})
    seq = spec.sequences[0]
    src = tmp_path / "src"
    render_sequence(seq.scene, seq.trajectory, replace(_settings(seq, (16, 12), 0.004, 1), gt_rate_hz=1000.0),
                    out_dir=src, progress=False)
    dst = upsample_render_dir(src, tmp_path / "dst", 2)
    meta = json.loads((dst / "timeline.json").read_text())
    probe = meta["render_noise"]["probe_file"]
    assert read_exr(dst / probe)["rgb"].shape[:2] == (24, 32)
    assert meta["geometry"]["instants"]
    for instant in meta["geometry"]["instants"]:
        depth_z, instance = read_geometry(dst / instant["file"], 32, 24)
        assert depth_z.shape == instance.shape == (24, 32)
    settings = RecordingSettings(lux=100.0, sensors={"events": spec.sensors["events"].params}, start_s=0.0,
                                 duration_s=0.004, seed=1, stream_key=("estimate", 100.0), gt_rate_hz=1000.0,
                                 optics=Optics())
    simulate_recording(dst, tmp_path / "rec.h5", settings, metadata={"created_utc": "2025-01-01T00:00:00Z"},
                       progress=False)
    assert (tmp_path / "rec.h5").stat().st_size > 0

"""The estimate's simulation probe runs on its small render with every pixel repeated towards the spec's width:
the upsampled render directory is the same content, instants and poses at the larger size."""

from __future__ import annotations

import json

import numpy as np

from simspad.dataset.estimate import upsample_render_dir
from simspad.io.exr import read_exr
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

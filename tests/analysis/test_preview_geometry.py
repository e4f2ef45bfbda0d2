"""``simspad preview`` of a recording with geometry: the flow panel is the colour wheel of the ground-truth image
velocity and the instances panel the mask's colours, read back from the PNG strip at every pixel."""

from __future__ import annotations

import json

import imageio.v2 as imageio
import numpy as np

from simspad.analysis.preview import STRIP_INSTANTS, PreviewSettings, instance_colours, write_preview
from simspad.io.recording import RecordingWriter

H, W = 12, 16


def _recording(path):
    n = 6
    t = np.arange(n) * 1e-3
    velocity = np.zeros((n, H, W, 2), np.float32)
    velocity[:, :, : W // 2, 0] = 1000.0  # left half moves right: red
    velocity[:, :, W // 2:, 1] = 1000.0  # right half moves down: hue 90°, yellow-green
    instance = np.ones((n, H, W), np.uint16)
    instance[:, :, W // 2:] = 2
    instance[:, 0, :] = 0  # top row: nothing hit
    valid = np.ones((n, H, W), np.uint8)
    valid[:, -1, :] = 0  # bottom row: occluded next
    root = dict(width=W, height=H, duration_s=t[-1], lux=1.0, t_start_s=0.0, t_end_s=t[-1], scene="test",
                created_utc="2026-01-01T00:00:00Z")
    with RecordingWriter(path, root) as w:
        w.write_dataset("gt/t", t)
        w.write_dataset("gt/flux", np.full((n, H, W), 1e16, np.float32))
        w.write_dataset("gt/instance", instance, attrs={"names": json.dumps(["", "left", "right"])})
        w.write_dataset("gt/flow", velocity * 1e-3)
        w.write_dataset("gt/flow_valid", valid)
        w.write_dataset("gt/velocity", velocity)
    return path


def test_flow_and_instance_panels(tmp_path):
    res = write_preview(_recording(tmp_path / "rec.h5"), tmp_path / "strip.png", PreviewSettings())
    assert set(res.panels) == {"gt", "flow", "instances"}
    strip = imageio.imread(res.path)[..., :3].astype(int)
    frame_h = res.height_px / STRIP_INSTANTS

    def pixels(box, k):
        x0, y0, x1, y1 = box
        ys = (y0 + (np.arange(H) + 0.5) * (y1 - y0) / H + k * frame_h).astype(int)
        xs = (x0 + (np.arange(W) + 0.5) * (x1 - x0) / W).astype(int)
        return strip[np.ix_(ys, xs)]

    expect_mask = np.rint(instance_colours(np.where(np.arange(H)[:, None] == 0, 0,
                                                    np.where(np.arange(W)[None, :] < W // 2, 1, 2))) * 255)
    for k in range(STRIP_INSTANTS):
        flow = pixels(res.panels["flow"], k)
        # every speed is the clip's top speed: full saturation. +x is red, +y (down) hue 90°: (127, 255, 0)
        assert np.abs(flow[:-1, : W // 2] - [255, 0, 0]).max() <= 2
        assert np.abs(flow[:-1, W // 2:] - [127, 255, 0]).max() <= 2
        assert np.abs(flow[-1, : W // 2] - [127, 0, 0]).max() <= 2  # not valid: half value
        assert np.abs(pixels(res.panels["instances"], k) - expect_mask).max() <= 2

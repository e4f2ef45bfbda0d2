"""``simspad export --to dsec-flow``: ground-truth flow as DSEC distributes optical flow, read back by a reader
written here from DSEC's documentation (and a PNG decoder written from the PNG specification), never by the
library that wrote it. The npz export's geometry file is read back with numpy.

DSEC (dsec.ifi.uzh.ch, "Data Format", optical flow): forward flow maps are 16-bit PNG with three channels; the
first two hold x and y flow as ``value = flow · 128 + 2¹⁵``, the third is 1 where the flow is valid; maps are listed
with ``from_timestamp_us, to_timestamp_us`` in ``forward_timestamps.txt``.
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.io.export.dispatch import export_recording
from simspad.io.recording import RecordingWriter

W, H, F = 20, 15, 30.0
DEPTH_M, STEP_M = 2.0, 0.004  # a wall 2 m away; the camera moves 4 mm along its +X (left) per instant


def read_png16(path: Path) -> np.ndarray:
    """Decode an 8-bit-depth-free, non-interlaced 16-bit RGB PNG (PNG specification, ISO/IEC 15948)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, header = 8, b"", None
    while pos < len(data):
        (length,), kind = struct.unpack(">I", data[pos:pos + 4]), data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        assert struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])[0] == zlib.crc32(kind + body)
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    width, height, depth, colour, _, _, interlace = header
    assert (depth, colour, interlace) == (16, 2, 0)
    bpp, stride = 6, width * 6
    raw = zlib.decompress(idat)
    out = np.zeros((height, stride), np.uint8)
    prev = np.zeros(stride, np.int64)
    for r in range(height):
        ftype = raw[r * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, r * (stride + 1) + 1).astype(np.int64)
        cur = np.zeros(stride, np.int64)
        for i in range(stride):
            a = cur[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if ftype == 0:
                pred = 0
            elif ftype == 1:
                pred = a
            elif ftype == 2:
                pred = b
            elif ftype == 3:
                pred = (a + b) // 2
            else:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            cur[i] = (line[i] + pred) & 0xFF
        out[r], prev = cur, cur
    return out.view(">u2").reshape(height, width, 3).astype(np.uint16)


def read_dsec_flow(folder: Path):
    """DSEC's decoding: flow_x = (ch0 − 2¹⁵) / 128, flow_y = (ch1 − 2¹⁵) / 128, valid = ch2."""
    lines = (folder / "flow" / "forward_timestamps.txt").read_text().splitlines()
    stamps = np.array([[int(v) for v in line.split(",")] for line in lines if not line.startswith("#")])
    maps = []
    for n in range(len(stamps)):
        png = read_png16(folder / "flow" / "forward" / f"{n:06d}.png").astype(np.float64)
        maps.append((np.stack([(png[..., 0] - 2**15) / 128.0, (png[..., 1] - 2**15) / 128.0], -1),
                     png[..., 2].astype(bool)))
    return stamps, maps


@pytest.fixture
def recording(tmp_path):
    """A camera sliding past a wall: exact flow f·Δ/Z px per instant to the right; stored flow with odd values."""
    n = 5
    t = 0.010 + np.arange(n) * 1e-3
    poses = np.repeat(np.eye(4)[None], n, axis=0)
    poses[:, 0, 3] = np.arange(n) * STEP_M
    rng = np.random.default_rng(3)
    flow = rng.uniform(-40, 40, (n, H, W, 2)).astype(np.float32)
    flow[0, 0, 0] = np.nan
    flow[0, 0, 1] = (300.0, 0.0)  # beyond DSEC's ±256 px
    valid = rng.random((n, H, W)) < 0.8
    path = tmp_path / "rec.h5"
    root = dict(width=W, height=H, duration_s=0.004, lux=1.0, t_start_s=t[0], t_end_s=t[-1],
                created_utc="2026-01-01T00:00:00Z", scene="test")
    with RecordingWriter(path, root) as w:
        w.write_dataset("gt/t", t)
        w.write_dataset("gt/flux", np.ones((n, H, W), np.float32))
        w.write_dataset("gt/depth", np.full((n, H, W), DEPTH_M, np.float32))
        w.write_dataset("gt/instance", np.ones((n, H, W), np.uint16), attrs={"names": json.dumps(["", "wall"])})
        w.write_dataset("gt/flow", flow, attrs={"interval_s": 1e-3, "definition": "test"})
        w.write_dataset("gt/flow_valid", valid.astype(np.uint8))
        w.write_dataset("gt/velocity", flow * 1e3)
        w.write_dataset("gt/camera_to_world", poses)
        w.set_attrs("camera", width=W, height=H, focal_px=F, cx_px=(W - 1) / 2, cy_px=(H - 1) / 2)
        w.write_dataset("camera/K", np.array([[F, 0, (W - 1) / 2], [0, F, (H - 1) / 2], [0, 0, 1]]))
    return path, t, flow, valid


def test_dsec_flow_round_trip(recording, tmp_path):
    path, t, flow, valid = recording
    out = export_recording(path, "dsec-flow", tmp_path / "flow")
    stamps, maps = read_dsec_flow(out)
    np.testing.assert_array_equal(stamps, np.round(np.column_stack([t[:-1], t[1:]]) * 1e6).astype(np.int64))
    for i, (got, ok) in enumerate(maps):
        expect_ok = valid[i] & np.isfinite(flow[i]).all(-1) & (np.abs(flow[i]) < 256).all(-1)
        np.testing.assert_array_equal(ok, expect_ok)
        assert np.abs(got[ok] - flow[i][ok]).max() <= 0.5 / 128 + 1e-6  # DSEC's 1/128 px step
        assert (got[~ok] == -256).all()  # DSEC writes 0 in both channels where invalid
    assert not maps[0][1][0, 0] and not maps[0][1][0, 1]


def test_dsec_flow_stride_spans_several_instants(recording, tmp_path):
    """With a stride the maps are the exact motion field between instants k apart (here f·kΔ/Z to the right)."""
    path, t, _, _ = recording
    out = export_recording(path, "dsec-flow", tmp_path / "flow2", stride=2)
    stamps, maps = read_dsec_flow(out)
    assert stamps.tolist() == [[10000, 12000], [12000, 14000]]
    shift = F * 2 * STEP_M / DEPTH_M  # px: the camera moved to its left, so the wall moves right
    for got, ok in maps:
        x = np.arange(W)[None, :] + np.zeros((H, 1))
        np.testing.assert_array_equal(ok, x + shift < W - 0.5)  # pixels pushed out of the image are invalid
        np.testing.assert_allclose(got[ok][:, 0], shift, atol=0.5 / 128)
        np.testing.assert_allclose(got[ok][:, 1], 0.0, atol=0.5 / 128)


def test_dsec_flow_refuses_a_recording_without_flow(tmp_path):
    path = tmp_path / "plain.h5"
    with RecordingWriter(path, dict(width=4, height=3, duration_s=0.001, lux=1.0)) as w:
        w.write_dataset("gt/t", np.array([0.0, 0.001]))
        w.write_dataset("gt/flux", np.ones((2, 3, 4), np.float32))
    with pytest.raises(SimSpadError, match="no ground-truth motion field"):
        export_recording(path, "dsec-flow", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_npz_export_carries_flow_masks_and_intrinsics(recording, tmp_path):
    path, t, flow, valid = recording
    out = export_recording(path, "npz", tmp_path / "npz")
    meta = json.loads((out / "metadata.json").read_text())
    np.testing.assert_allclose(meta["camera"]["K"], [[F, 0, (W - 1) / 2], [0, F, (H - 1) / 2], [0, 0, 1]])
    assert meta["groups"]["gt"]["geometry"]["instance_names"] == ["", "wall"]
    with np.load(out / "gt" / "geometry.npz") as z:
        np.testing.assert_array_equal(z["flow"], flow)
        np.testing.assert_array_equal(z["flow_valid"], valid)
        np.testing.assert_array_equal(z["instance"], 1)
        np.testing.assert_array_equal(z["t_s"], t)
        assert z["camera_to_world"].shape == (5, 4, 4) and "object_to_world" not in z

"""The recording as ML samples: event windows with signed polarity, SPAD blocks, frames, ground truth."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import simspad
from tests.helpers.synthetic_recordings import write_recording
from tests.io.export.conftest import event_source  # noqa: F401  (fixture)

H, W = 6, 11


def test_event_windows_partition_the_span_with_signed_polarity(event_source):  # noqa: F811
    with simspad.open_recording(event_source.path) as rec:
        windows = rec.events.windows(0.002)
        assert len(windows) == 20  # 40 ms from 12.3 ms
        for i in (0, 7, -1):
            t0, t1 = windows.bounds(i % len(windows))
            keep = (event_source.t >= round(t0 * 1e6)) & (event_source.t < round(t1 * 1e6))
            w = windows[i]
            assert w.dtype.names == ("x", "y", "t", "p")
            np.testing.assert_array_equal(w["t"], event_source.t[keep])
            np.testing.assert_array_equal(w["x"], event_source.x[keep])
            np.testing.assert_array_equal(w["p"], np.where(event_source.p[keep] == 1, 1, -1))
        assert sum(len(w) for w in windows) == event_source.t.size
        with pytest.raises(IndexError):
            windows[20]


def test_tonic_voxel_grid_sums_the_signed_polarities(event_source):  # noqa: F811
    tonic = pytest.importorskip("tonic")
    with simspad.open_recording(event_source.path) as rec:
        events = rec.events.windows(0.005)[3]
    grid = tonic.transforms.ToVoxelGrid(sensor_size=(event_source.width, event_source.height, 2),
                                        n_time_bins=5)(events)
    # The event volume (Zhu et al. 2019) by its definition: V[b, y, x] = Σ p·max(0, 1 − |b − t*|), with
    # t* = n_bins·(t − t_first)/(t_last − t_first); with polarity 1/0 instead of ±1 the OFF events would vanish.
    t_star = 5 * (events["t"] - events["t"][0]) / (events["t"][-1] - events["t"][0])
    expected = np.zeros((5, event_source.height, event_source.width))
    for b in range(5):
        np.add.at(expected[b], (events["y"], events["x"]), events["p"] * np.maximum(0.0, 1.0 - np.abs(b - t_star)))
    assert grid.shape == (5, 1, event_source.height, event_source.width)
    np.testing.assert_allclose(grid[:, 0], expected, atol=1e-9)
    assert 0 < (events["p"] == -1).sum() < events.size  # both polarities present: the sum tests the sign


def test_spad_blocks_frames_and_ground_truth_match_the_file(tmp_path):
    path = tmp_path / "rec.h5"
    write_recording(path, lambda t: np.full((H, W), 2e12) * (1 + t), shape=(H, W), duration_s=0.006, events=False)
    with simspad.open_recording(path) as rec, h5py.File(path, "r") as h5:
        blocks = rec.spad.blocks(100)
        assert len(blocks) == h5["spad/bits"].shape[0] // 100
        t_start, bits = blocks[2]
        assert t_start == h5["spad/t_start"][200] and bits.shape == (100, H, W)
        np.testing.assert_array_equal(np.packbits(bits, axis=2, bitorder="little"), h5["spad/bits"][200:300])
        frames = rec.frames.items()
        t0, t1, dn = frames[-1]
        assert (t0, t1) == (h5["frames/t_start"][-1], h5["frames/t_end"][-1])
        np.testing.assert_array_equal(dn, h5["frames/dn"][-1])
        t, flux, depth = rec.gt.items()[1]
        assert t == h5["gt/t"][1] and depth is None
        np.testing.assert_array_equal(flux, h5["gt/flux"][1])

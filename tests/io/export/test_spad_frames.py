"""The npz/PNG/TIFF/EXR export, read back by numpy, imageio, tifffile and OpenEXR."""

from __future__ import annotations

import json

import h5py
import imageio.v3 as iio
import numpy as np
import OpenEXR
import pytest
import tifffile

from simspad.errors import SimSpadError
from simspad.io.export.dispatch import export_recording
from tests.helpers.synthetic_recordings import write_recording

H, W = 12, 19  # W not a multiple of 8: the packed rows end in a partial byte


@pytest.fixture(scope="module")
def full_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("full") / "rec.h5"
    rng = np.random.default_rng(4)
    base = 1e12 * (0.5 + rng.random((H, W)))
    write_recording(path, lambda t: base * (1.0 + 0.3 * np.sin(300.0 * t)), shape=(H, W), duration_s=0.01,
                    events=False)
    return path


@pytest.mark.parametrize("packing", ["packed", "unpacked"])
def test_spad_bits_read_back_by_numpy(full_recording, tmp_path, packing):
    out = export_recording(full_recording, "npz", tmp_path / "out", packing=packing, chunk_bins=100)
    with h5py.File(full_recording, "r") as h5, np.load(out / "spad.npz") as npz:
        stored = h5["spad/bits"][()]
        bits = npz["bits"]
        if packing == "packed":
            np.testing.assert_array_equal(bits, stored)
        else:
            assert bits.shape == (stored.shape[0], H, W)
            np.testing.assert_array_equal(np.packbits(bits, axis=2, bitorder="little"), stored)
        np.testing.assert_array_equal(npz["t_start_s"], h5["spad/t_start"][()])
        np.testing.assert_array_equal(npz["dcr_cps"], h5["spad/dcr_cps"][()])
        assert float(npz["gate_s"]) == h5["spad"].attrs["gate_s"]
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["groups"]["spad"]["packing"] == packing and meta["attrs"]["width"] == W


@pytest.mark.parametrize("frames_format", ["png", "tiff"])
def test_frames_and_ground_truth_read_back_by_image_libraries(full_recording, tmp_path, frames_format):
    out = export_recording(full_recording, "npz", tmp_path / "out", frames_format=frames_format)
    with h5py.File(full_recording, "r") as h5:
        dn, gt = h5["frames/dn"][()], h5["gt/flux"][()]
        t_start, gt_t = h5["frames/t_start"][()], h5["gt/t"][()]
    if frames_format == "png":
        images = np.stack([iio.imread(out / "frames" / f"{i:06d}.png") for i in range(dn.shape[0])])
    else:
        images = tifffile.imread(out / "frames" / "frames.tif")
    assert images.dtype == np.uint16
    np.testing.assert_array_equal(images, dn)
    table = np.loadtxt(out / "frames" / "timestamps.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], t_start)
    for i in range(gt.shape[0]):
        with OpenEXR.File(str(out / "gt" / f"{i:06d}.exr")) as f:
            np.testing.assert_array_equal(f.channels()["Y"].pixels, gt[i])
    np.testing.assert_array_equal(np.loadtxt(out / "gt" / "timestamps.csv", delimiter=",", skiprows=1)[:, 1], gt_t)


def test_bad_option_is_one_clear_error(full_recording, tmp_path):
    with pytest.raises(SimSpadError, match="--spad-packing.*expected one of packed, unpacked"):
        export_recording(full_recording, "npz", tmp_path / "out", packing="zip")
    assert not (tmp_path / "out").exists()


def test_same_recording_same_bytes(full_recording, tmp_path):
    a = export_recording(full_recording, "npz", tmp_path / "a", chunk_bins=300)
    b = export_recording(full_recording, "npz", tmp_path / "b", chunk_bins=1000)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f

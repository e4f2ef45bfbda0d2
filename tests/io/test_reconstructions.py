"""Reconstruction files of a results directory: what docs/format.md promises an outside reader."""

import subprocess
import sys

import h5py
import numpy as np

from simspad.io.reconstructions import ReconstructionSink

OUTSIDE_READER = r"""
import sys
import h5py, hdf5plugin  # nothing of SimSPAD: the filter comes from hdf5plugin alone
import numpy as np
with h5py.File(sys.argv[1], "r") as f:
    plist = f["flux"].id.get_create_plist()
    filters = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
    np.save(sys.argv[2], f["flux"][()])
    print(filters, f["t"].shape, dict(f.attrs))
"""


def test_frames_written_out_of_order_runs_read_back_exactly_by_h5py_with_hdf5plugin(tmp_path, child_env):
    rng = np.random.default_rng(3)
    n, shape = 9, (37, 51)
    frames = (rng.lognormal(30, 1.0, (n, *shape))).astype(np.float32)
    times = np.arange(n) * 1e-3
    path = tmp_path / "rec" / "qbp.h5"
    sink = ReconstructionSink(path, times, shape, {"method": "qbp", "recording": "rec.h5", "units": "ph s-1 m-2"})
    for i in [0, 1, 2, 5, 6, 3, 4, 8, 7]:  # runs of consecutive frames, and single ones
        sink(i, frames[i])
    sink.close()
    out = tmp_path / "flux.npy"
    res = subprocess.run([sys.executable, "-c", OUTSIDE_READER, str(path), str(out)], capture_output=True, text=True,
                         env=child_env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert np.array_equal(np.load(out), frames)
    # byte shuffle (2) then Zstandard (32015), as docs/format.md says
    assert res.stdout.startswith("[2, 32015] (9,)"), res.stdout
    assert "'method': 'qbp'" in res.stdout


def test_noisy_frames_are_stored_smaller_than_raw(tmp_path):
    # the filter is chosen for noisy float frames; the sign bit and exponent bytes shuffle into runs that compress
    rng = np.random.default_rng(4)
    n, shape = 20, (60, 80)
    frames = (1e15 * (1 + 0.1 * rng.standard_normal((n, *shape)))).astype(np.float32)
    path = tmp_path / "nedi.h5"
    sink = ReconstructionSink(path, np.arange(n) * 1e-3, shape, {"method": "nedi"})
    for i in range(n):
        sink(i, frames[i])
    sink.close()
    with h5py.File(path) as f:
        ratio = f["flux"].id.get_storage_size() / frames.nbytes
    assert ratio < 0.85, ratio

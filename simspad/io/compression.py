"""HDF5 storage filters of the SPAD bit stream: the names a spec may give and the h5py arguments each means.

Packed binary frames compress well at the light levels SPAD datasets are made for, and they are most of a
dataset's bytes (a 512 × 512 SwissSPAD2 stream is 3.2 GB per second, uncompressed). The candidates were measured
on the packed bits of real recordings (``benchmarks/bench_spad.py``, storage filters; docs/sensors.md gives the
table): Zstandard at level 1 gives the smallest files of the fast filters and writes faster than gzip and lzf;
Blosc2 with bit-shuffle does worse on this data, because the bits are already packed (there is no byte structure
to transpose). Zstandard is HDF5 filter 32015, registered by the ``hdf5plugin`` package: importing this module
(every SimSPAD reader and writer does) registers it, and an outside reader needs ``import hdf5plugin`` before
opening such a file with h5py.
"""

from __future__ import annotations

import hdf5plugin

#: Name of each storage filter a spec may choose for ``/spad/bits``, with the keyword arguments of
#: ``h5py.Group.create_dataset`` that select it.
SPAD_COMPRESSIONS: dict[str, dict] = {
    # fastest to write and read, readable by any HDF5 reader; largest (one bit per pixel and bin)
    "none": {},
    # any HDF5 reader decodes it (deflate is built into the library); slowest to write
    "gzip": {"compression": "gzip", "compression_opts": 1},
    # smallest of the fast filters; needs the hdf5plugin filter to read
    "zstd": dict(hdf5plugin.Zstd(clevel=1)),
}

#: Storage of float32 image stacks that are outputs, not inputs (the reconstructions of a results directory):
#: byte shuffle + Zstandard level 1. On the 240 reconstructions of the mini dataset's evaluation (80×60 px
#: frames, one chunk each) it stores 0.75 of the raw bytes in 3.5 ms of CPU per file (written and read back),
#: against LZF's 0.87 in 10.3 ms; unshuffled Zstandard 0.79 in 3.1 ms, gzip level 1 with shuffle 0.76 in 9.2 ms.
#: LZF is slowest where it gains least: on noisy frames (the usual reconstruction) it compresses at ≈ 30 MB/s and
#: keeps 0.97–0.99 of the bytes.
FLOAT_FRAMES_STORAGE: dict = dict(shuffle=True, **hdf5plugin.Zstd(clevel=1))

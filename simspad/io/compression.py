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

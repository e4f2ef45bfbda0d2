"""Every file format SimSPAD reads or writes, and nothing else.

Render directories, trajectory files, HDF5 recordings (``io/recording/``, one checked opener in ``hdf5.py``),
the dataset manifest, results directories, reconstructions and submissions; atomic writes, EXR, file hashes and
provenance stamps. io imports only ``errors``, ``defaults``, ``physics`` and ``motion`` (the trajectory model its
readers return); see docs/internals.md for the layer map.
"""

"""Saved reconstructions of a results directory: ``reconstructions/<rec>/<method>.h5``.

Layout: ``/t`` [N] float64 s, ``/flux`` [N,H,W] float32 ph s⁻¹ m⁻² (one LZF-compressed chunk per frame), root
attributes ``method``, ``recording``, ``units``. Frames are written as the method produces them.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np


class ReconstructionSink:
    """Appends frames to a reconstruction file as they are produced; call :meth:`close` when done.

    Parameters
    ----------
    path : Path
        The file (its directory is created).
    times_s : array of float
        The N instants, s.
    shape : (H, W)
        Frame shape, pixels.
    attrs : dict
        Root attributes.
    """

    def __init__(self, path: Path, times_s: np.ndarray, shape: tuple[int, int], attrs: dict):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.h5 = h5py.File(path, "w")
        self.h5.create_dataset("t", data=np.asarray(times_s, np.float64), track_times=False)
        self.ds = self.h5.create_dataset("flux", shape=(len(times_s), *shape), dtype=np.float32,
                                         chunks=(1, *shape), compression="lzf", track_times=False)
        for k, v in attrs.items():
            self.h5.attrs[k] = v

    def __call__(self, i: int, img: np.ndarray) -> None:
        """Store frame ``i``."""
        self.ds[i] = img

    def close(self) -> None:
        self.h5.close()

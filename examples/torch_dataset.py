"""Feed a recording to PyTorch: fixed-length event windows as voxel grids, through a Dataset of three short methods.

Run on any recording with events, e.g. one of the mini dataset::

    python examples/torch_dataset.py output/mini/recordings/fan/fan_100lx.h5 --window-ms 10 --bins 5

``simspad.open_recording(path).events.windows(window_s)`` is a lazy sequence (``len`` and ``[i]``) of numpy
structured arrays with fields x, y, t (µs) and p (+1 ON / −1 OFF), so a ``torch.utils.data.Dataset`` only has to
turn a window into a tensor-ready array (:class:`EventVoxels`). simspad does not need torch: without it, this
script batches the same Dataset by hand. With ``DataLoader(num_workers > 0)`` open the recording inside each worker (HDF5 handles do not
survive a fork), e.g. on the first ``__getitem__``.

The voxel grid is the event volume of Zhu et al. (2019) as E2VID builds it: each event's polarity is shared
between the two time bins nearest its normalised time t* = (bins − 1)·(t − t_first)/(t_last − t_first), so a
grid sums to (ON − OFF) events of its window; the script prints both sums to show it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import simspad
from simspad.errors import SimSpadError

try:
    from torch.utils.data import DataLoader, Dataset
except ImportError:  # torch is optional: the Dataset below is then a plain sequence
    DataLoader, Dataset = None, object


def voxel_grid(events: np.ndarray, width: int, height: int, n_bins: int) -> np.ndarray:
    """Event volume ``[n_bins, H, W]`` float32 of one window (structured array with signed ``p``)."""
    grid = np.zeros((n_bins, height, width), np.float32)
    if events.size == 0:
        return grid
    t = events["t"].astype(np.float64)
    span = max(t[-1] - t[0], 1.0)
    t_star = (n_bins - 1) * (t - t[0]) / span
    left = np.floor(t_star).astype(np.int64)
    frac = t_star - left
    p = events["p"].astype(np.float32)
    np.add.at(grid, (left, events["y"], events["x"]), p * (1.0 - frac))
    inside = left + 1 < n_bins
    np.add.at(grid, (left[inside] + 1, events["y"][inside], events["x"][inside]), (p * frac)[inside])
    return grid


class EventVoxels(Dataset):
    def __init__(self, path, window_s, n_bins):
        self.rec, self.n_bins = simspad.open_recording(path), n_bins
        self.windows = self.rec.events.windows(window_s)

    def __len__(self):
        return len(self.windows)

    def __getitem__(self, i):
        return voxel_grid(self.windows[i], self.rec.width, self.rec.height, self.n_bins)


def batches(dataset, batch_size: int):
    """Batches of voxel grids: torch's DataLoader when torch is installed, else the same stacking by hand."""
    if DataLoader is not None:
        yield from (b.numpy() for b in DataLoader(dataset, batch_size=batch_size))
        return
    for i in range(0, len(dataset), batch_size):
        yield np.stack([dataset[k] for k in range(i, min(i + batch_size, len(dataset)))])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording")
    parser.add_argument("--window-ms", type=float, default=10.0, help="window length, ms")
    parser.add_argument("--bins", type=int, default=5, help="time bins per voxel grid")
    parser.add_argument("--batch", type=int, default=4, help="windows per batch")
    args = parser.parse_args()

    dataset = EventVoxels(args.recording, args.window_ms * 1e-3, args.bins)
    n_batches, grid_sum, shape = 0, 0.0, None
    for batch in batches(dataset, args.batch):
        n_batches, grid_sum, shape = n_batches + 1, grid_sum + float(batch.sum(dtype=np.float64)), batch.shape[1:]
    signed = sum(int(w["p"].sum()) for w in dataset.windows)
    n_events = sum(w.size for w in dataset.windows)
    print(f"{'torch DataLoader' if DataLoader else 'plain batches (torch not installed)'}: {len(dataset)} windows "
          f"of {args.window_ms:g} ms in {n_batches} batches, grids {shape}")
    print(f"events {n_events}, ON - OFF {signed}, voxel grid sum {grid_sum:.3f}")


if __name__ == "__main__":
    try:
        main()
    except SimSpadError as exc:  # a missing or invalid recording: one line, as the simspad command prints it
        print(f"{Path(__file__).name}: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None

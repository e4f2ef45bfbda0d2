"""Feed a recording to PyTorch: fixed-length event windows as voxel grids, through a Dataset of three short methods.

Run on any recording with events, e.g. one of the mini dataset::

    python examples/torch_dataset.py output/mini/recordings/fan/fan_100lx.h5 --window-ms 10 --bins 5

``simspad.open_recording(path).events.windows(window_s)`` is a lazy sequence (``len`` and ``[i]``) of numpy
structured arrays with fields x, y, t (µs) and p (+1 ON / −1 OFF), so a ``torch.utils.data.Dataset`` only has to
turn a window into a tensor-ready array (:class:`EventVoxels`). simspad does not need torch: without it, this
script batches the same Dataset by hand. With ``DataLoader(num_workers > 0)`` open the recording inside each worker (HDF5 handles do not
survive a fork), e.g. on the first ``__getitem__``.

With ``--flow`` each item also carries the ground-truth motion field over its window (recordings rendered with
geometry passes, docs/format.md ``/gt/flow``): ``rec.gt.flow_between(i, j)`` is the exact forward displacement
(px, x right, y down) of each pixel's surface point from the ground-truth instant at the window's start to the one
at its end, with the mask of pixels still visible there, computed from the recording's depth, poses and intrinsics
(the windows then should be whole ground-truth intervals, e.g. 1 ms steps at the default 1 kHz).

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
    def __init__(self, path, window_s, n_bins, flow=False):
        self.rec, self.n_bins, self.flow = simspad.open_recording(path), n_bins, flow
        self.windows = self.rec.events.windows(window_s)
        if flow:
            self.gt_t = self.rec.gt.t

    def __len__(self):
        return len(self.windows)

    def _instant(self, t):
        """Index of the ground-truth instant at ``t`` (s): the window's bounds must lie on the ground-truth grid."""
        k = int(np.argmin(np.abs(self.gt_t - t)))
        if abs(self.gt_t[k] - t) > 1e-9:
            raise SimSpadError(f"window bound {t:.9g} s is not a ground-truth instant: choose a window of whole "
                               f"ground-truth intervals", field="--window-ms")
        return k

    def __getitem__(self, i):
        grid = voxel_grid(self.windows[i], self.rec.width, self.rec.height, self.n_bins)
        if not self.flow:
            return grid
        a, b = self.windows.bounds(i)
        flow, valid = self.rec.gt.flow_between(self._instant(a), self._instant(b))
        # channels first, as a network takes them: [2, H, W] (x right, y down), invalid pixels 0 with valid = 0
        return grid, np.moveaxis(np.where(valid[..., None], flow, 0.0), -1, 0).astype(np.float32), valid


def batches(dataset, batch_size: int):
    """Batches of voxel grids: torch's DataLoader when torch is installed, else the same stacking by hand."""
    if DataLoader is not None:
        for b in DataLoader(dataset, batch_size=batch_size):
            yield b.numpy() if not isinstance(b, (list, tuple)) else tuple(x.numpy() for x in b)
        return
    for i in range(0, len(dataset), batch_size):
        items = [dataset[k] for k in range(i, min(i + batch_size, len(dataset)))]
        yield np.stack(items) if not isinstance(items[0], tuple) else tuple(np.stack(x) for x in zip(*items))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording")
    parser.add_argument("--window-ms", type=float, default=10.0, help="window length, ms")
    parser.add_argument("--bins", type=int, default=5, help="time bins per voxel grid")
    parser.add_argument("--batch", type=int, default=4, help="windows per batch")
    parser.add_argument("--flow", action="store_true", help="also yield each window's ground-truth motion field")
    args = parser.parse_args()

    dataset = EventVoxels(args.recording, args.window_ms * 1e-3, args.bins, flow=args.flow)
    n_batches, grid_sum, shape, flow_px, n_valid, n_px = 0, 0.0, None, 0.0, 0, 0
    for batch in batches(dataset, args.batch):
        if args.flow:
            batch, flow, valid = batch
            flow_px += float(np.hypot(flow[:, 0], flow[:, 1])[valid].sum())
            n_valid, n_px = n_valid + int(valid.sum()), n_px + valid.size
        n_batches, grid_sum, shape = n_batches + 1, grid_sum + float(batch.sum(dtype=np.float64)), batch.shape[1:]
    signed = sum(int(w["p"].sum()) for w in dataset.windows)
    n_events = sum(w.size for w in dataset.windows)
    print(f"{'torch DataLoader' if DataLoader else 'plain batches (torch not installed)'}: {len(dataset)} windows "
          f"of {args.window_ms:g} ms in {n_batches} batches, grids {shape}")
    print(f"events {n_events}, ON - OFF {signed}, voxel grid sum {grid_sum:.3f}")
    if args.flow:
        print(f"flow over each window: mean {flow_px / max(n_valid, 1):.4f} px where valid "
              f"({n_valid / max(n_px, 1):.1%} of pixels)")


if __name__ == "__main__":
    try:
        main()
    except SimSpadError as exc:  # a missing or invalid recording: one line, as the simspad command prints it
        print(f"{Path(__file__).name}: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None

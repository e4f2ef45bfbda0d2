"""DSEC event files: ``events.h5`` as the DSEC dataset ships them, read by its ``EventSlicer`` and tonic.

Layout (DSEC, Gehrig et al. 2021)::

    /events/p    uint8   polarity, 1 ON / 0 OFF
    /events/t    int64   µs since t_offset
    /events/x    uint16
    /events/y    uint16
    /ms_to_idx   uint64  ms_to_idx[k] = index of the first event with t ≥ 1000·k µs (k = 0 … ceil(t_end/1 ms))
    /t_offset    int64   µs; absolute time = t + t_offset

``t_offset`` is the recording's start rounded down to a whole millisecond, so ``t`` starts near 0 as in DSEC and
``t + t_offset`` is the recording's own time base (µs since the timeline's t = 0). ``ms_to_idx`` is recomputed
while the events stream through (from the offset, not copied), which also checks that the events are sorted.
The same recording always gives the same bytes. A full disk ends the export with one line: the HDF5 objects whose
write failed are kept alive, not freed (which would crash the process). Datasets are gzip-compressed with h5py's built-in filter (DSEC's files use Blosc through ``hdf5plugin``; gzip
needs no plugin on the reading side).
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import h5py
import numpy as np

from simspad.io.atomic import atomic_path, is_disk_full
from simspad.io.export.common import EXPORT_CHUNK_EVENTS, check_sorted, require_group
from simspad.io.recording.writer import keep_after_disk_full

#: HDF5 library version bounds (fixed, and no object times stored: the same recording gives the same bytes).
_LIBVER = ("v110", "v110")
#: HDF5 chunk of each event column (rows).
_H5_CHUNK = 1 << 16
_COLUMNS = (("p", np.uint8), ("t", np.int64), ("x", np.uint16), ("y", np.uint16))


@contextlib.contextmanager
def _h5_output(path: Path, held: list):
    """``h5py.File(path, "w")``; on a full disk the file and the dataset objects the caller put in ``held`` are
    kept alive rather than freed (HDF5 would crash retrying their close:
    :func:`simspad.io.recording.writer.keep_after_disk_full`) and the error passes on."""
    h5 = h5py.File(path, "w", libver=_LIBVER)
    try:
        yield h5
        h5.close()
    except BaseException as exc:
        if is_disk_full(exc):
            keep_after_disk_full((h5, held))
        else:
            h5.close()
        raise


def export_dsec(rec, out: Path, *, chunk_events: int = EXPORT_CHUNK_EVENTS) -> Path:
    """Write the recording's events as a DSEC ``events.h5`` at ``out``.

    Parameters
    ----------
    rec : Recording
        An open recording with ``/events``.
    out : Path
        The file to write (conventionally ``…/events_left/events.h5``).
    chunk_events : int
        Events read and written per step.

    Returns
    -------
    Path
        ``out``.
    """
    require_group(rec, "events", "dsec")
    t0_s, t1_s = rec.events.span_s()
    t_offset_us = int(math.floor(round(t0_s * 1e3, 6))) * 1000
    # One entry per millisecond up to and including the one that holds the last instant, as the recording has.
    n_ms = int(math.ceil(round(t1_s * 1e3, 6))) + 1 - t_offset_us // 1000
    boundaries_us = np.arange(n_ms, dtype=np.int64) * 1000
    ms_to_idx = np.zeros(n_ms, dtype=np.uint64)
    held: list = []
    with atomic_path(out) as tmp, _h5_output(tmp, held) as h5:
        cols = {name: h5.create_dataset(f"events/{name}", shape=(0,), maxshape=(None,), dtype=dtype,
                                        chunks=(_H5_CHUNK,), compression="gzip", compression_opts=1, shuffle=True,
                                        track_times=False)
                for name, dtype in _COLUMNS}
        held.append(cols)
        n, last_us = 0, np.iinfo(np.int64).min
        for ev in rec.events.iter_chunks(chunk_events):
            t_us = ev["t"].astype(np.int64, copy=False)
            check_sorted(t_us, last_us, rec, n)
            t_rel = t_us - t_offset_us
            # Events before a boundary in this chunk push that boundary's index forward.
            ms_to_idx += np.searchsorted(t_rel, boundaries_us, side="left").astype(np.uint64)
            m = n + t_rel.size
            for name, dtype in _COLUMNS:
                values = t_rel if name == "t" else ev[name]
                cols[name].resize((m,))
                cols[name][n:m] = np.asarray(values, dtype=dtype)
            n, last_us = m, int(t_us[-1]) if t_us.size else last_us
        h5.create_dataset("ms_to_idx", data=ms_to_idx, track_times=False)
        h5.create_dataset("t_offset", data=np.int64(t_offset_us), track_times=False)
    return out

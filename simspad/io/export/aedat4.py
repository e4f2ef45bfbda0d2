"""AEDAT 4 event files (iniVation's DV format), written through the ``dv-processing`` library.

The file holds one event stream named ``events`` of camera ``SimSPAD`` at the recording's resolution; each event
is (timestamp int64 µs on the recording's time base, x, y, polarity with True = ON), written in chunks of
``chunk_events``. ``dv-processing`` is an optional dependency (``pip install simspad[export]``); its Python
binding fills an event store one event at a time, so this exporter runs at about 10⁵ events s⁻¹.

``dv-processing`` aborts the whole process (it does not raise) when asked to write a file whose name does not end
in ``.aedat4``, so the temporary file keeps that suffix. It also aborts when its writer thread meets a full disk,
so the export first checks that the disk holds the file uncompressed (:data:`BYTES_PER_EVENT` per event, the
LZ4-compressed file takes ~7) and refuses in one line otherwise (``SIMSPAD_IGNORE_LIMITS=1`` skips the check).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from simspad.errors import InputError, SimSpadError
from simspad.io.atomic import atomic_path
from simspad.io.export.common import EXPORT_CHUNK_EVENTS, check_sorted, require_group

#: Largest width and height: dv-processing stores event addresses as int16.
MAX_SIDE = 1 << 15
#: Camera name stored in the file's stream metadata.
CAMERA_NAME = "SimSPAD"
#: Bytes of one event in an uncompressed AEDAT 4 event packet (int64 time, int16 x, y, bool polarity, padding),
#: and the room kept for the header, packet framing and file index.
BYTES_PER_EVENT = 16
OVERHEAD_BYTES = 1 << 20


def _check_free_space(out: Path, n_events: int) -> None:
    """Refuse an export the disk may not hold: dv-processing aborts the process on a full disk (no exception)."""
    if os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1":
        return
    need = BYTES_PER_EVENT * n_events + OVERHEAD_BYTES
    folder = Path(out).absolute().parent
    while not folder.exists() and folder != folder.parent:  # the folder is made later, on this disk
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    if free < need:
        raise SimSpadError(f"the disk is too full for this export: {n_events} events need up to "
                           f"{need / 2**20:.1f} MiB and {free / 2**20:.1f} MiB are free (dv-processing cannot "
                           "report a full disk, it ends the process); free space or choose another output folder "
                           "(SIMSPAD_IGNORE_LIMITS=1 skips this check)", path=out)


def _dv():
    try:
        import dv_processing  # deferred: optional dependency (simspad[export]), only this exporter needs it
    except ImportError:
        raise SimSpadError("export to aedat4 needs the dv-processing library: pip install 'simspad[export]' "
                           "(or pip install dv-processing)", field="--to") from None
    return dv_processing


def export_aedat4(rec, out: Path, *, chunk_events: int = EXPORT_CHUNK_EVENTS) -> Path:
    """Write the recording's events as an AEDAT 4 file at ``out`` (through ``dv-processing``).

    Parameters
    ----------
    rec : Recording
        An open recording with ``/events``.
    out : Path
        The ``.aedat4`` file to write.
    chunk_events : int
        Events per event store handed to the writer.
    """
    require_group(rec, "events", "aedat4")
    if rec.width > MAX_SIDE or rec.height > MAX_SIDE:
        raise InputError(f"AEDAT 4 event addresses are int16: {rec.width} × {rec.height} pixels exceed "
                         f"{MAX_SIDE} × {MAX_SIDE}", path=rec.path, field="/.width")
    dv = _dv()
    config = dv.io.MonoCameraWriter.EventOnlyConfig(CAMERA_NAME, (rec.width, rec.height))
    _check_free_space(out, rec.events.n_events)
    with atomic_path(out) as tmp:
        tmp_aedat4 = tmp.with_name(tmp.name + ".aedat4")
        try:
            writer = dv.io.MonoCameraWriter(str(tmp_aedat4), config)
            n, last_us = 0, np.iinfo(np.int64).min
            for ev in rec.events.iter_chunks(chunk_events):
                t_us = ev["t"].astype(np.int64, copy=False)
                check_sorted(t_us, last_us, rec, n)
                store = dv.EventStore()
                push = store.push_back
                for t, x, y, p in zip(t_us.tolist(), ev["x"].tolist(), ev["y"].tolist(),
                                      (ev["p"] > 0).tolist()):
                    push(t, x, y, p)
                writer.writeEvents(store)
                n += t_us.size
                last_us = int(t_us[-1]) if t_us.size else last_us
            del writer  # closes the file (the binding has no close(); destruction flushes it)
            os.replace(tmp_aedat4, tmp)
        finally:
            tmp_aedat4.unlink(missing_ok=True)
    return out

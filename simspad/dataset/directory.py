"""The dataset directory's layout, its lock and the clean-up of an interrupted run.

::

    <out>/manifest.json                                   what the folder holds (simspad.io.manifest)
    <out>/.simspad.lock                                   held by the one run writing the folder
    <out>/renders/<sequence>[_x<k>]-<render hash[:12]>/   one render per (sequence, speed) (simspad.io.render_dir)
    <out>/recordings/<sequence>/<sequence>[_x<k>]_<lux>lx.h5  one recording per (sequence, speed, lux)

``_x<k>`` appears for a speed factor k ≠ 1 only (simspad.dataset.speed).

A lock (``fcntl.flock`` on ``<out>/.simspad.lock``) refuses a second concurrent run on one output directory; the
kernel releases it when the process dies, even by kill -9, and the next run removes the temporary files the
dead one left (the lock guarantees no one else is writing them).
"""

from __future__ import annotations

import fcntl
import os
import re
import shutil
from pathlib import Path

from simspad.dataset.speed import speed_suffix
from simspad.errors import SimSpadError
from simspad.io.provenance import utc_now

LOCK_NAME = ".simspad.lock"
RENDERS_DIR = "renders"
RECORDINGS_DIR = "recordings"
#: Temporary names written by simspad.io.atomic.temporary_sibling: ``.<name>.tmp-<pid>-<8 hex>``.
_TMP_NAME = re.compile(r"^\..+\.tmp-\d+-[0-9a-f]{8}$")


def lux_label(lux: float) -> str:
    """The lux level as it appears in file names: ``1``, ``10000``, ``0.5``."""
    lux = float(lux)
    return str(int(lux)) if lux.is_integer() and abs(lux) < 1e15 else repr(lux)


def recording_rel_path(sequence_name: str, lux: float, speed: float = 1.0) -> str:
    """``recordings/<sequence>/<sequence>_<lux>lx.h5`` (speed 1), ``.../<sequence>_x<speed>_<lux>lx.h5`` (others)."""
    return f"{RECORDINGS_DIR}/{sequence_name}/{sequence_name}{speed_suffix(speed)}_{lux_label(lux)}lx.h5"



class DatasetLock:
    """``fcntl.flock`` on ``<out>/.simspad.lock`` for the whole run: a second run on the same directory is
    refused at once with a clear message. The kernel releases the lock when the process dies, even by kill -9."""

    def __init__(self, out_dir: Path):
        self.path = Path(out_dir) / LOCK_NAME
        self.fd: int | None = None

    def __enter__(self) -> "DatasetLock":
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise SimSpadError(f"another `simspad generate` is already writing this dataset ({holder}); wait for "
                               "it to finish or choose another --out", path=self.path.parent) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {os.uname().nodename} since {utc_now()}\n".encode())
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None


def remove_temporaries(out_dir: Path) -> list[Path]:
    """Delete the temporary files and folders a killed run left behind (``.<name>.tmp-<pid>-<hex>``)."""
    removed = []
    roots = [out_dir, out_dir / RENDERS_DIR, out_dir / RECORDINGS_DIR]
    rec_root = out_dir / RECORDINGS_DIR
    if rec_root.is_dir():
        roots += [p for p in rec_root.iterdir() if p.is_dir()]
    for root in roots:
        if not root.is_dir():
            continue
        for p in root.iterdir():
            if _TMP_NAME.match(p.name):
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                removed.append(p)
    return removed

"""Write to a temporary name, rename when complete: readers never see a half-written file.

Every writer goes through here: :func:`check_output_path` refuses to replace anything but a regular file or a
directory (a device node, FIFO, socket or symbolic link named as an output is refused, never replaced or
followed), and :func:`disk_full_error` turns a full disk into one line naming it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import uuid
from pathlib import Path
from typing import Iterator

from simspad.errors import SimSpadError


#: What :func:`temporary_sibling` appends after ``.<name>.tmp-``: the writer's pid and 8 hex digits.
_TMP_SUFFIX = re.compile(r"(\d+)-[0-9a-f]{8}")


def temporary_sibling(path: str | Path) -> Path:
    """A unique temporary name next to ``path`` (same directory, so the rename is atomic)."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")


#: errno values that mean "the disk (or the file-size limit) is full", not a bug.
_DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_DISK_FULL_TEXT = ("errno = 28", "errno = 122", "errno = 27", "No space left", "Disk quota", "File too large")


def check_output_path(path: str | Path, *, kind: str | None = None, field: str | None = "--out") -> Path:
    """Refuse an existing ``path`` that an output must not replace; return ``path``.

    Parameters
    ----------
    path : str or Path
        The output's final name.
    kind : {"file", "dir", None}
        What the output is: an existing path must be a regular file (``"file"``), a directory (``"dir"``), or
        either (None). A symbolic link, device node, FIFO or socket is always refused: replacing it would
        destroy it (as root, a disk device), and following a link would write outside the named place.
    field : str, optional
        The option or field named in the message.

    Raises
    ------
    SimSpadError
        Naming the path and what it is.
    """
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise SimSpadError(f"cannot inspect the output path ({exc.strerror})", path=path, field=field) from None
    if stat.S_ISLNK(mode):
        raise SimSpadError("is a symbolic link; refusing to replace or follow it (name a new path or the link's "
                           "target itself)", path=path, field=field)
    is_file, is_dir = stat.S_ISREG(mode), stat.S_ISDIR(mode)
    what = ("a directory" if is_dir else "a regular file" if is_file else "a FIFO" if stat.S_ISFIFO(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a device node" if stat.S_ISBLK(mode) or stat.S_ISCHR(mode)
            else "a special file")
    wanted = {"file": is_file, "dir": is_dir, None: is_file or is_dir}[kind]
    if not wanted:
        expected = {"file": "a file", "dir": "a directory", None: "a file or directory"}[kind]
        raise SimSpadError(f"exists and is {what}; refusing to replace it with {expected}", path=path, field=field)
    return path


def check_output_file(path: str | Path, *, field: str | None = "--out", recognise=None,
                      what: str = "a file of this kind") -> Path:
    """Up-front check of an output file, before any slow work: not a special file or link, and its folder can
    be created and written.

    ``recognise(path) -> bool``, when given, says whether an existing non-empty file is one the command writes
    (``what`` names that kind in the refusal): a command replaces its own earlier output, never a file of
    another kind (a recording named as an export's ``--out``, a user's document named as a figure).
    """
    path = Path(path)
    check_output_path(path, kind="file", field=field)
    if recognise is not None and path.is_file() and path.stat().st_size > 0 and not _recognised(recognise, path):
        raise SimSpadError(f"exists and is not {what}; refusing to replace it (choose a new name, or delete the "
                           "file first if it is yours to lose)", path=path, field=field)
    ensure_writable_dir(path.parent, what=f"{field or 'output'} folder")
    return path


def _recognised(recognise, path: Path) -> bool:
    try:
        return bool(recognise(path))
    except Exception:  # noqa: BLE001 - a file the recogniser cannot even read is not one this command wrote
        return False


def starts_with(magic: bytes, *, within: int = 0):
    """A recogniser for :func:`check_output_file`: the file starts with ``magic`` (or, with ``within`` > 0, holds
    it in its first ``within`` bytes)."""

    def recognise(path: Path) -> bool:
        with open(path, "rb") as f:
            head = f.read(max(within, len(magic)))
        return head.startswith(magic) if within == 0 else magic in head

    return recognise


#: PNG files (``simspad snr``, ``simspad scenes --contact-sheet``).
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def is_disk_full(exc: BaseException) -> bool:
    """True if ``exc`` says the disk (or quota, or file-size limit) is full; h5py reports it only in the text."""
    if isinstance(exc, OSError) and exc.errno in _DISK_FULL_ERRNOS:
        return True
    return isinstance(exc, (OSError, RuntimeError)) and any(t in str(exc) for t in _DISK_FULL_TEXT)


def disk_full_error(path: str | Path) -> SimSpadError:
    """One line naming the disk that filled up while writing ``path`` and what is left on it."""
    path = Path(path)
    directory = path.parent if not path.is_dir() else path
    mount = directory.resolve()
    while not os.path.ismount(mount) and mount != mount.parent:
        mount = mount.parent
    try:
        free = shutil.disk_usage(directory).free
        left = f"{free / 2**30:.2f} GiB free now"
    except OSError:
        left = "free space unknown"
    return SimSpadError(f"the disk is full (filesystem mounted at {mount}, {left}); nothing was written under "
                        "this name: free space or choose another output folder", path=path)


def fsync_file(path: str | Path) -> None:
    """Flush ``path``'s bytes to the disk (so a rename after it never exposes a file the disk has not got)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def ensure_writable_dir(directory: str | Path, *, what: str = "output") -> Path:
    """Create ``directory`` if needed; raise a clear :class:`SimSpadError` if it cannot be written."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SimSpadError(f"cannot create {what} directory ({exc.strerror})", path=directory) from None
    if not os.access(directory, os.W_OK):
        raise SimSpadError(f"{what} directory is not writable", path=directory)
    return directory


@contextlib.contextmanager
def atomic_path(path: str | Path, *, kind: str | None = None) -> Iterator[Path]:
    """Yield a temporary path; on success rename it to ``path``, on any exception delete it.

    Works for files and directories (``kind``: see :func:`check_output_path`, checked before anything is
    written). A directory replaces only a missing or empty one: nothing is ever deleted to make room (see
    :mod:`simspad.io.output_dirs` for folders a command re-writes). The parent directory is created if needed. A
    full disk raises one :class:`SimSpadError` naming it.
    """
    path = Path(path)
    check_output_path(path, kind=kind, field=None)
    ensure_writable_dir(path.parent)
    remove_stale_temporaries(path)
    tmp = temporary_sibling(path)
    try:
        yield tmp
        if tmp.is_file():
            fsync_file(tmp)
        check_output_path(path, kind="dir" if tmp.is_dir() else "file", field=None)
        if tmp.is_dir() and path.is_dir() and any(path.iterdir()):
            # Never delete a folder to put another in its place: it may hold what this command did not write.
            # Folders that commands re-write go through simspad.io.output_dirs, which replaces only their files.
            raise SimSpadError("is a folder that is not empty; refusing to replace it (choose a new or empty "
                               "folder)", path=path)
        os.replace(tmp, path)  # over a file, or an empty folder
    except BaseException as exc:
        _remove(tmp)
        if is_disk_full(exc):
            raise disk_full_error(path) from None
        raise


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Delete temporary siblings of ``path`` (``.<name>.tmp-<pid>-<hex>``) left by killed processes.

    Only those whose process no longer exists on this machine are removed, so a concurrent writer keeps its
    file; a killed ``simulate`` or ``evaluate`` thus leaves no multi-GB temporary behind for long.
    """
    path = Path(path)
    removed = []
    prefix = f".{path.name}.tmp-"
    try:
        siblings = [p for p in path.parent.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for p in siblings:
        match = _TMP_SUFFIX.fullmatch(p.name[len(prefix):])  # exactly the names temporary_sibling makes
        if match is None or int(match[1]) == os.getpid() or _pid_alive(int(match[1])):
            continue
        _remove(p)
        removed.append(p)
    return removed


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()

"""Output folders that a command owns: refused unless new, empty or its own; only its own files replaced.

A command that writes a folder (``evaluate``, ``score``, ``export --to npz``, ``render``, ``leaderboard``) names it
with ``--out``. The folder may be new, empty, or one the same command wrote before, recognised by its marker
file ``.simspad-<command>`` (JSON: ``format`` ``"simspad-output"``, ``version`` 1, ``command``, ``files``: the
POSIX paths, relative to the folder, of every file the command wrote there). Anything else — a dataset, a home
folder, another command's output — is refused in one line before any work.

A re-run replaces the files it writes again, deletes the files its previous run wrote that this one does not (a
recording no longer evaluated), and leaves every other file alone: a user's notes, the leaderboard that
``simspad leaderboard`` wrote into a results folder. Nothing is deleted through a symbolic link: a link inside
the folder where one of its files or folders should be is refused. The new files are built in a temporary
sibling folder first (:mod:`simspad.io.atomic`), so each file appears under its final name whole.

:class:`OutputLock` (``fcntl.flock`` on ``<folder>/.simspad.lock``) refuses a second concurrent run on the same
folder; ``simspad generate`` takes the same lock on its dataset folder.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import stat
from pathlib import Path
from typing import Callable, Iterator

from simspad.errors import SimSpadError
from simspad.io.atomic import (
    check_output_path,
    disk_full_error,
    ensure_writable_dir,
    is_disk_full,
    remove_stale_temporaries,
    temporary_sibling,
)
from simspad.io.provenance import utc_now

LOCK_NAME = ".simspad.lock"
MARKER_PREFIX = ".simspad-"
MARKER_FORMAT = "simspad-output"
MARKER_VERSION = 1

#: ``legacy(folder)``: the files an older SimSPAD (before markers) wrote in ``folder`` if it recognises the
#: folder as such an output, else None.
Legacy = Callable[[Path], "set[str] | None"]


def marker_name(command: str) -> str:
    """``.simspad-<command>``: the marker file of a folder ``command`` wrote."""
    return f"{MARKER_PREFIX}{command}"


def is_bookkeeping(name: str) -> bool:
    """True for a top-level name SimSPAD keeps in any output folder: the lock and the commands' markers."""
    return name == LOCK_NAME or name.startswith(MARKER_PREFIX)


class OutputLock:
    """``fcntl.flock`` on ``<folder>/.simspad.lock`` while a command writes the folder.

    A second run on the same folder is refused at once, naming the holder (the line the holder writes into the
    file, emptied again on release). The kernel releases the lock when the process dies, even by kill -9.
    ``command`` (written into the lock file) names the holder in a refusal; ``what`` names the folder
    (``folder``, ``dataset``).
    """

    def __init__(self, directory: str | Path, command: str = "simspad", what: str = "folder"):
        self.path = Path(directory) / LOCK_NAME
        self.command = command
        self.what = what
        self.fd: int | None = None

    def __enter__(self) -> "OutputLock":
        check_output_path(self.path, kind="file", field=None)  # a link or FIFO named .simspad.lock is not ours
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise SimSpadError(f"cannot create the lock file ({exc.strerror})", path=self.path) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise SimSpadError(f"another SimSPAD command is already writing this {self.what} ({holder}); wait "
                               "for it to finish or choose another --out", path=self.path.parent,
                               field="--out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{self.command}: pid {os.getpid()} on {os.uname().nodename} since {utc_now()}\n".encode())
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            # The holder line is for a refusal while held; emptied on release, the folder's bytes are the same
            # from run to run. The file itself stays: deleting it would let two runs lock two different files.
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, 0)
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None


def read_marker(directory: Path, command: str) -> set[str] | None:
    """The files ``command`` recorded in its marker in ``directory``; None when there is no valid marker."""
    path = directory / marker_name(command)
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not (isinstance(doc, dict) and doc.get("format") == MARKER_FORMAT and doc.get("command") == command
            and isinstance(doc.get("files"), list) and all(isinstance(f, str) for f in doc["files"])):
        return None
    return {f for f in doc["files"] if _is_plain_relative(f)}


def write_marker(directory: Path, command: str, files: set[str]) -> None:
    """Write ``directory``'s marker for ``command`` listing ``files`` (atomically: temporary name, rename)."""
    text = json.dumps({"format": MARKER_FORMAT, "version": MARKER_VERSION, "command": command,
                       "files": sorted(files)}, indent=1) + "\n"
    final = directory / marker_name(command)
    tmp = temporary_sibling(final)
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def claim_output_dir(path: str | Path, command: str, *, legacy: Legacy | None = None, also: tuple[str, ...] = (),
                     field: str | None = "--out") -> set[str] | None:
    """Check that ``command`` may write the folder ``path``; return the files it wrote there before.

    Parameters
    ----------
    path : str or Path
        The output folder.
    command : str
        The command's marker name (``evaluate``, ``score``, ``export-npz``, ``render``, ``leaderboard``).
    legacy : callable, optional
        Recognises a folder this command wrote before markers existed (see :data:`Legacy`).
    also : tuple of str
        Other commands whose folders this one may write into, leaving their files alone (``leaderboard`` writes
        into a results folder by default).
    field : str, optional
        The option named in a refusal.

    Returns
    -------
    set of str or None
        None if ``path`` does not exist; the relative paths of the command's earlier files otherwise (empty for
        an empty folder, or one written by an ``also`` command).

    Raises
    ------
    SimSpadError
        ``path`` is a file, link or special file, or a folder that is neither empty nor recognised.
    """
    path = Path(path)
    check_output_path(path, kind="dir", field=field)
    if not path.exists():
        return None
    try:
        names = sorted(p.name for p in path.iterdir())
    except OSError as exc:
        raise SimSpadError(f"cannot list the output folder ({exc.strerror})", path=path, field=field) from None
    owned = read_marker(path, command)
    if owned is not None:
        return owned
    if legacy is not None and (owned := legacy(path)) is not None:
        return owned
    if any(read_marker(path, other) is not None for other in also):
        return set()
    foreign = [n for n in names if not is_bookkeeping(n)]
    if not foreign:
        return set()
    shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
    raise SimSpadError(f"exists, is not empty (holds {shown}) and was not written by `simspad {_verb(command)}`; "
                       "refusing to write into it: choose a new or empty folder", path=path, field=field)


def _verb(command: str) -> str:
    return command.replace("-", " --to ") if command.startswith("export-") else command


@contextlib.contextmanager
def owned_output_dir(path: str | Path, command: str, *, legacy: Legacy | None = None,
                     field: str | None = "--out") -> Iterator[Path]:
    """Yield an empty temporary folder; on success install its files into ``path`` as ``command``'s own.

    ``path`` is checked (:func:`claim_output_dir`) and locked (:class:`OutputLock`) before anything is written;
    a folder created here is removed again if the command fails. On success, files of the temporary folder
    replace those of the same name; files the command's previous run wrote and this one did not are deleted;
    every other file in ``path`` is kept. A full disk raises one :class:`SimSpadError` naming it.
    """
    path = Path(path)
    claim_output_dir(path, command, legacy=legacy, field=field)
    created = not path.exists()
    ensure_writable_dir(path, what=field or "output")
    try:
        with OutputLock(path, f"simspad {_verb(command)}"):
            previous = claim_output_dir(path, command, legacy=legacy, field=field) or set()
            remove_stale_temporaries(path)
            tmp = temporary_sibling(path)
            try:
                tmp.mkdir()
                yield tmp
                _install(tmp, path, command, previous)
            except BaseException as exc:
                if is_disk_full(exc):
                    raise disk_full_error(path) from None
                raise
            finally:
                if tmp.is_dir() and not tmp.is_symlink():
                    shutil.rmtree(tmp, ignore_errors=True)  # our own temporary folder
    except BaseException:
        if created:
            _remove_if_only_bookkeeping(path)
        raise


@contextlib.contextmanager
def owned_dir_in_place(path: str | Path, command: str, *, legacy: Legacy | None = None, also: tuple[str, ...] = (),
                       field: str | None = "--out") -> Iterator[Path]:
    """Check, create and lock ``path`` for a command that writes its files in place, one by one (``render``:
    each keyframe atomically, so an interrupted render resumes); yield ``path``.

    The marker is written before anything else, so a folder left by an interrupted run is recognised as the
    command's own; the command records its files with :func:`write_marker` when done (``also``: see
    :func:`claim_output_dir`). A folder created here and still holding nothing but the lock and marker is
    removed if the command fails.
    """
    path = Path(path)
    previous = claim_output_dir(path, command, legacy=legacy, also=also, field=field)
    created = previous is None
    ensure_writable_dir(path, what=field or "output")
    try:
        with OutputLock(path, f"simspad {_verb(command)}"):
            previous = claim_output_dir(path, command, legacy=legacy, also=also, field=field) or set()
            if read_marker(path, command) is None:
                write_marker(path, command, previous)
            yield path
    except BaseException:
        if created:
            _remove_if_only_bookkeeping(path)
        raise


def _install(tmp: Path, path: Path, command: str, previous: set[str]) -> None:
    """Move every file of ``tmp`` into ``path``; delete ``previous`` files not written again; update the marker."""
    new = {p.relative_to(tmp).as_posix() for p in tmp.rglob("*") if p.is_file() and not p.is_symlink()}
    stale = previous - new
    for rel in sorted(new | stale):
        check_no_link(path, rel)
    # The marker lists both sets until the move is done: a run killed half-way leaves no file of ours unlisted.
    write_marker(path, command, previous | new)
    for rel in sorted(new):
        dst = path / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp / rel, dst)
    remove_stale_files(path, stale)
    write_marker(path, command, new)


def remove_stale_files(root: Path, stale: set[str]) -> None:
    """Delete the regular files ``stale`` (paths relative to ``root`` that the command wrote before), never
    through a symbolic link, then the folders that became empty."""
    for rel in sorted(stale):
        if not _is_plain_relative(rel):
            continue
        check_no_link(root, rel)
        with contextlib.suppress(FileNotFoundError):
            if stat.S_ISREG(os.lstat(root / rel).st_mode):
                (root / rel).unlink()
    for rel in sorted({str(Path(r).parent) for r in stale} - {"."}, key=lambda r: -r.count("/")):
        _remove_empty_dirs(root, Path(rel))


def check_no_link(root: Path, rel: str) -> None:
    """Refuse ``root/rel`` if a symbolic link (or a non-folder) stands where one of its parts should be: a move
    or deletion there would reach outside ``root``. A regular file at the final name is fine (replaced)."""
    parts = Path(rel).parts
    here = root
    for i, part in enumerate(parts):
        here = here / part
        try:
            mode = os.lstat(here).st_mode
        except FileNotFoundError:
            return
        last = i == len(parts) - 1
        if stat.S_ISLNK(mode) or (not last and not stat.S_ISDIR(mode)) or (last and not stat.S_ISREG(mode)):
            kind = "a symbolic link" if stat.S_ISLNK(mode) else "a folder" if stat.S_ISDIR(mode) else "not a file"
            raise SimSpadError(f"{here.relative_to(root)} is {kind} where SimSPAD writes its own "
                               f"{'file' if last else 'folder'}; refusing to replace or follow it",
                               path=root, field="--out")


def _remove_empty_dirs(root: Path, rel: Path) -> None:
    """Remove ``root/rel`` and its parents up to ``root`` while they are empty folders (never links)."""
    while rel.parts:
        d = root / rel
        try:
            if stat.S_ISLNK(os.lstat(d).st_mode):
                return
            d.rmdir()
        except OSError:
            return
        rel = rel.parent


def _remove_if_only_bookkeeping(path: Path) -> None:
    """Remove a folder this command created when it holds nothing but the lock, markers and empty folders (a
    failed run: a render that hit a full disk before its first keyframe leaves an empty ``frames/``)."""
    try:
        for sub in path.iterdir():
            if not sub.is_symlink() and sub.is_dir():
                _remove_empty_tree(sub)
        names = [p.name for p in path.iterdir()]
    except OSError:
        return
    if all(is_bookkeeping(n) for n in names):
        for n in names:
            with contextlib.suppress(OSError):
                (path / n).unlink()
        with contextlib.suppress(OSError):
            path.rmdir()


def _remove_empty_tree(d: Path) -> None:
    """Remove ``d`` if it holds only empty folders (never following a link); anything else keeps it."""
    for sub in d.iterdir():
        if sub.is_symlink() or not sub.is_dir():
            return
        _remove_empty_tree(sub)
    with contextlib.suppress(OSError):
        d.rmdir()


def _is_plain_relative(rel: str) -> bool:
    p = Path(rel)
    return bool(rel) and not p.is_absolute() and ".." not in p.parts and "\0" not in rel

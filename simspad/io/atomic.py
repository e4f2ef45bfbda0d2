"""Write to a temporary name, rename when complete: readers never see a half-written file."""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from pathlib import Path
from typing import Iterator

from simspad.errors import SimSpadError


def temporary_sibling(path: str | Path) -> Path:
    """A unique temporary name next to ``path`` (same directory, so the rename is atomic)."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")


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
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path; on success rename it to ``path``, on any exception delete it.

    Works for files and directories. The parent directory is created if needed.
    """
    path = Path(path)
    ensure_writable_dir(path.parent)
    tmp = temporary_sibling(path)
    try:
        yield tmp
    except BaseException:
        _remove(tmp)
        raise
    else:
        if path.is_dir() and tmp.is_dir():
            shutil.rmtree(path)
        os.replace(tmp, path)


def _remove(p: Path) -> None:
    if p.is_dir():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()

"""Paths read from inside a SimSPAD folder or file stay inside it.

A results directory's ``results.csv`` (``image``), a dataset's ``manifest.json`` (``path``, ``render``), a render
directory's ``timeline.json`` (keyframe ``file``) and an HDF5 recording or submission (links) name other files.
A crafted value (absolute, ``../``, a symbolic link leading out, an HDF5 external link) must not make SimSPAD
read, embed or score a file elsewhere on the machine: :func:`confined_path` and :func:`refuse_hdf5_links` refuse
them with one line naming the file and the field.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from simspad.errors import InputError


def confined_path(base: str | Path, rel, *, source: str | Path, field: str) -> Path:
    """``base / rel`` if ``rel`` is a relative path that stays inside ``base`` (after resolving links).

    Parameters
    ----------
    base : str or Path
        The folder the path must stay in.
    rel : str
        The path as read from ``source``.
    source : str or Path
        The file it was read from (for the message).
    field : str
        The field it was read from (for the message).

    Raises
    ------
    InputError
        ``rel`` is not a non-empty string, is absolute, has a ``..`` part, or resolves outside ``base``.
    """
    if not isinstance(rel, str) or not rel or "\0" in rel:
        raise InputError(f"expected a relative path, got {rel!r}", path=source, field=field)
    pure = PurePosixPath(rel.replace("\\", "/"))
    if pure.is_absolute() or ".." in pure.parts or Path(rel).is_absolute():
        raise InputError(f"{rel[:200]!r} leaves its folder (expected a path relative to {Path(base)}, without '..')",
                         path=source, field=field)
    base = Path(base)
    full = base / rel
    try:
        inside = full.resolve().is_relative_to(base.resolve())
    except (OSError, RuntimeError):  # a link loop
        inside = False
    if not inside:
        raise InputError(f"{rel[:200]!r} leads outside {base} (through a symbolic link)", path=source, field=field)
    return full


def refuse_hdf5_links(h5, path: str | Path) -> None:
    """Refuse soft and external links anywhere in an open HDF5 file: an external link would read another file
    of the machine, a dangling soft link fails later with a traceback; SimSPAD writes neither."""
    import h5py  # deferred: h5py (0.4 s) is only needed by callers that already opened an HDF5 file

    stack = [h5]
    while stack:
        group = stack.pop()
        for name in group:
            link = group.get(name, getlink=True)
            where = f"{group.name.rstrip('/')}/{name}"
            if isinstance(link, h5py.ExternalLink):
                raise InputError(f"external link to {link.filename}:{link.path} (links to other files are not "
                                 "followed)", path=path, field=where)
            if isinstance(link, h5py.SoftLink):
                raise InputError(f"soft link to {link.path} (expected datasets and groups, no links)", path=path,
                                 field=where)
            try:
                obj = group[name]
            except (KeyError, OSError, RuntimeError) as exc:
                raise InputError(f"unreadable object ({str(exc)[:120]})", path=path, field=where) from None
            if isinstance(obj, h5py.Group):
                stack.append(obj)

"""Opening HDF5 files for reading: the one checked opener of every SimSPAD HDF5 format.

A recording (:mod:`simspad.io.recording`) and a submission (:mod:`simspad.io.submission`) are both HDF5 files
that name their format in the root attributes ``format`` and ``format_version``. :func:`open_checked` opens such
a file read-only and turns every way it can be wrong — missing, not HDF5 (corrupt or truncated), a foreign HDF5
file, an unsupported version — into one :class:`~simspad.errors.InputError` naming the file and the field.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from simspad.errors import InputError
# registers the storage filters a recording may use (Zstandard on /spad/bits) before any file is opened
from simspad.io.compression import SPAD_COMPRESSIONS  # noqa: F401
from simspad.io.safe_paths import refuse_hdf5_links

_REQUIRED = object()


def decode_attr(value):
    """An HDF5 attribute as a plain Python value (bytes decoded as UTF-8, NumPy scalars as Python scalars)."""
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _root_attr(h5: h5py.File, name: str, default, path: Path):
    """The root attribute ``name`` decoded (``default`` when absent); InputError when the library cannot read it."""
    try:
        return decode_attr(h5.attrs.get(name, default))
    except Exception:  # noqa: BLE001 - an attribute type h5py cannot read, or text that is not UTF-8
        raise InputError("attribute of an unsupported type or unreadable", path=path, field=f"/.{name}") from None


def open_checked(path: str | Path, *, kind: str, format: str, format_version: int,
                 default_version=_REQUIRED) -> h5py.File:
    """Open the HDF5 file ``path`` read-only and check its ``format`` and ``format_version`` root attributes.

    Parameters
    ----------
    path : str or Path
        The file.
    kind : str
        What the file is, in the messages ("recording", "submission").
    format : str
        Expected value of the root attribute ``format``.
    format_version : int
        The version this SimSPAD reads.
    default_version : int, optional
        Version assumed when the file has no ``format_version`` attribute; without it the attribute is required.

    Returns
    -------
    h5py.File
        Open for reading; the caller closes it.

    Raises
    ------
    InputError
        Missing file, not HDF5 (corrupt or truncated), a foreign HDF5 file (``/.format``) or an unsupported
        version (``/.format_version``); the message names the file and the field.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such {kind} file", path=path)
    try:
        h5 = h5py.File(path, "r")
    except OSError:
        raise InputError("not a readable HDF5 file (corrupt or truncated?)", path=path) from None
    try:
        found = _root_attr(h5, "format", None, path)
        if found != format:
            raise InputError(f"not a SimSPAD {kind} (format attr is {found!r}, expected {format!r})",
                             path=path, field="/.format")
        version = _root_attr(h5, "format_version", None if default_version is _REQUIRED else default_version, path)
        if version != format_version:
            raise InputError(f"unsupported format_version {version!r} (this SimSPAD reads {format_version})",
                             path=path, field="/.format_version")
        refuse_hdf5_links(h5, path)
    except BaseException:
        h5.close()
        raise
    return h5

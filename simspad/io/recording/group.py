"""The base of the recording views: one HDF5 group of an open recording, read lazily."""

from __future__ import annotations

from pathlib import Path

import h5py

from simspad.errors import InputError
from simspad.io.hdf5 import decode_attr


class GroupView:
    """Read access to the group ``name`` of an open recording file.

    Parameters
    ----------
    h5 : h5py.File
        The open recording (owned and closed by :class:`~simspad.io.recording.reader.Recording`).
    path : Path
        The file, for error messages.
    name : str
        The group ("gt", "spad", …); it may be absent, and then every dataset read raises :class:`InputError`.
    """

    def __init__(self, h5: h5py.File, path: Path, name: str):
        self._h5 = h5
        self._path = path
        self._name = name
        self._attrs: dict | None = None
        # Datasets stay open while the recording is: HDF5 keeps decoded chunks in a cache per open dataset, so
        # methods reading a compressed stream block by block decode each chunk once, not once per read.
        self._datasets: dict[str, h5py.Dataset] = {}

    @property
    def name(self) -> str:
        """The group's name ("gt", "spad", …)."""
        return self._name

    def preset_attrs(self, attrs: dict | None) -> None:
        """Take the group's attributes as already read and decoded (by the validation on open); None: read them
        when first asked for."""
        self._attrs = attrs

    @property
    def attrs(self) -> dict:
        """Attributes of the group as plain Python values (JSON text left as text); read once (a recording is
        opened read-only), a fresh dict each time."""
        if self._attrs is None:
            self._attrs = {k: decode_attr(v) for k, v in self._h5[self._name].attrs.items()}
        return dict(self._attrs)

    def _dataset(self, name: str) -> h5py.Dataset:
        """The dataset ``<group>/<name>``; InputError naming it when the recording lacks it."""
        dataset = self._datasets.get(name)
        if dataset is not None:
            return dataset
        full = f"{self._name}/{name}"
        try:
            dataset = self._h5[full]
        except KeyError:
            raise InputError("dataset missing from the recording", path=self._path, field=full) from None
        self._datasets[name] = dataset
        return dataset

    def _optional(self, name: str):
        """The whole dataset ``<group>/<name>`` (None when the recording lacks it)."""
        full = f"{self._name}/{name}"
        return self._h5[full][()] if full in self._h5 else None

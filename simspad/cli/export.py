"""``simspad export``: write a recording in a format that event-camera and SPAD tools read.

The formats and what each writes are :data:`simspad.io.export.FORMATS`; the exporters live in
:mod:`simspad.io.export` (one module per format), dispatched by :func:`simspad.io.export.dispatch.export_recording`.
"""

from __future__ import annotations

from pathlib import Path

import click

from simspad.errors import SimSpadError
from simspad.io.atomic import check_output_file, starts_with
from simspad.io.export import DIRECTORY_FORMATS
from simspad.io.export.dispatch import export_recording


def _is_dsec_file(path: Path) -> bool:
    """An HDF5 file laid out as the dsec export writes it (``/events``, ``/ms_to_idx``, ``/t_offset``)."""
    import h5py  # deferred: h5py is loaded by the export itself right after

    if not h5py.is_hdf5(path):
        return False
    with h5py.File(path, "r") as h5:
        return set(h5) == {"events", "ms_to_idx", "t_offset"}


#: How an existing --out file is recognised as an earlier export of the format (replaced), not another file.
_OWN_FILES = {"dsec": _is_dsec_file, "aedat4": starts_with(b"#!AER-DAT4.0"),
              "evt3": starts_with(b"% evt 3.0", within=512)}


def export_from_cli(recording, fmt: str, out, *, packing: str, frames_format: str, flow_stride: int = 1) -> Path:
    """The ``simspad export`` command: check the paths, export, say what was written.

    An existing ``out`` is replaced only when it is an earlier export of the same format (an npz folder: see
    :mod:`simspad.io.output_dirs`); a recording or any other file named as ``--out`` is refused."""
    recording, out = Path(recording), Path(out)
    if not recording.is_file():
        raise SimSpadError("no such recording file", path=recording)
    if out.resolve() == recording.resolve():
        raise SimSpadError("--out would overwrite the recording being exported", path=out, field="--out")
    if fmt in DIRECTORY_FORMATS and out.exists() and not out.is_dir():
        raise SimSpadError(f"{fmt} export writes a directory, and a file of that name exists", path=out,
                           field="--out")
    if fmt not in DIRECTORY_FORMATS and out.is_dir():
        raise SimSpadError(f"{fmt} export writes a file, and a directory of that name exists", path=out,
                           field="--out")
    if fmt in _OWN_FILES:
        check_output_file(out, recognise=_OWN_FILES[fmt], what=f"a file of `simspad export --to {fmt}`")
    options = {"packing": packing, "frames_format": frames_format} if fmt == "npz" else {}
    if fmt == "dsec-flow":
        options = {"stride": flow_stride}
    path = export_recording(recording, fmt, out, **options)
    click.echo(f"wrote {path}")
    return path

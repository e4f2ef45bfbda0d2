"""``simspad info``: a readable summary of whatever file or folder it is given.

Dispatch on the path: a dataset spec or trajectory file is summarised here (:mod:`simspad.dataset.spec`,
:mod:`simspad.motion.trajectory`); a recording (``.h5``) or a dataset directory (``manifest.json``) by
:mod:`simspad.cli.describe`.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import click

from simspad.bundled import find_trajectory
from simspad.cli.describe import describe_dataset, describe_recording
from simspad.cli.describe_spec import describe_spec
from simspad.cli.describe_trajectory import describe_trajectory
from simspad.dataset.spec import find_spec
from simspad.errors import SimSpadError

_TRAJECTORY_SUFFIXES = (".json", ".csv", ".txt", ".tum")
_RECORDING_SUFFIXES = (".h5", ".hdf5")
_TRAJECTORY_TOML_KEYS = {"camera", "objects"}


class VerificationFailed(SimSpadError):
    """A dataset's recordings no longer match the sha256 its manifest records: the summary was printed; exit
    status 1 (as ``sha256sum --check``), so scripts and CI see it."""

    exit_code = 1


def info_from_cli(path) -> None:
    """The ``simspad info`` command: print the summary; raise :class:`VerificationFailed` after it when a
    dataset's recording failed its hash check."""
    corrupt: list = []
    click.echo(describe(path, corrupt))
    if corrupt:
        rel, why = corrupt[0]
        raise VerificationFailed(f"{len(corrupt)} recording(s) do not match the sha256 in manifest.json; first: "
                                 f"{rel}: {why} (re-run `simspad generate` on the dataset to redo them)",
                                 path=path)


def describe(path, corrupt: list | None = None) -> str:
    """Summary text of a spec (``.toml`` or a bundled spec's name), trajectory (``.toml``/``.json``/``.csv``/``.txt``/``.tum``),
    recording (``.h5``) or dataset directory (holding ``manifest.json``).

    ``corrupt`` (a list) receives the (path, why) of a dataset's recordings that fail their sha256 check.

    Raises
    ------
    SimSpadError
        Missing path or a kind of file ``info`` does not know; malformed files raise the loaders' errors.
    """
    path = find_spec(path)  # `simspad info mini` describes the bundled spec of that name
    if not path.exists():  # `simspad info trajectories/office.toml`, as `simspad scenes` prints it
        path = find_trajectory(path)
    if not path.exists():
        raise SimSpadError("no such file or directory", path=path)
    if path.is_dir():
        if (path / "manifest.json").is_file():
            return describe_dataset(path, corrupt)
        raise SimSpadError("not a dataset directory (no manifest.json; expected a dataset directory, a spec, "
                           "a trajectory or a recording)", path=path)
    suffix = path.suffix.lower()
    if path.name == "manifest.json":
        return describe_dataset(path.parent, corrupt)
    if suffix in _RECORDING_SUFFIXES:
        return describe_recording(path)
    if suffix == ".toml":
        if _is_trajectory_toml(path):
            return describe_trajectory(path)
        return describe_spec(path)
    if suffix in _TRAJECTORY_SUFFIXES:
        return describe_trajectory(path)
    raise SimSpadError(f"unknown kind of file {path.suffix or '(no suffix)'!r} (expected a spec .toml, a trajectory "
                       ".toml/.json/.csv/.txt/.tum, a recording .h5 or a dataset directory)", path=path)


def _is_trajectory_toml(path: Path) -> bool:
    """A TOML file with a top-level camera/objects table is a trajectory; anything else is read as a spec
    (whose loader reports syntax errors with their line)."""
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, OSError, UnicodeDecodeError):
        return False
    return bool(_TRAJECTORY_TOML_KEYS & set(doc))

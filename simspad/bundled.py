"""Where the data that ships with SimSPAD lives: dataset specs, built-in scenes and their trajectories.

In a source checkout they are the folders ``datasets/``, ``scenes/`` and ``trajectories/`` at the repository root,
beside ``simspad/``; a wheel carries the same three folders inside the package, as ``simspad/_data/`` (setup.py's
package-dir mapping). :data:`DATA_ROOT` is the folder holding the three: ``simspad/_data`` when it exists (an
installed wheel), else the folder above the imported ``simspad`` package (a checkout, run from it, through
``PYTHONPATH`` or installed editable). Either way the data found is the one that goes with the code running, from
any working directory. This module is the one place that knows these folders; everything else asks here.

Paths between them are relative and the same in both layouts: a built-in scene's ``default_trajectory`` is
``trajectories/<file>`` (relative to :data:`DATA_ROOT`), and recordings store a bundled trajectory as
``../trajectories/<file>`` (relative to :data:`DATASETS_DIR`).
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent
#: The bundled folders inside an installed wheel (setup.py maps the repository's folders here).
PACKAGED_DATA_DIR = _PACKAGE_DIR / "_data"
# Mitsuba, OpenEXR and the TOML readers need real paths: wheels are always installed unpacked, so this is a folder.
DATA_ROOT = PACKAGED_DATA_DIR if PACKAGED_DATA_DIR.is_dir() else _PACKAGE_DIR.parent
DATASETS_DIR = DATA_ROOT / "datasets"
SCENES_DIR = DATA_ROOT / "scenes"
TRAJECTORIES_DIR = DATA_ROOT / "trajectories"
#: The three bundled folders, as named under :data:`DATA_ROOT`.
BUNDLED_DIRS = (DATASETS_DIR, SCENES_DIR, TRAJECTORIES_DIR)


def builtin_spec_names() -> list[str]:
    """Names of the bundled dataset specs (``mini``, ``simspad``, …): what ``simspad generate NAME`` accepts."""
    return sorted(p.stem for p in DATASETS_DIR.glob("*.toml"))


def builtin_spec_path(name: str) -> Path | None:
    """The bundled spec called ``name`` (file stem), or None when there is none."""
    path = DATASETS_DIR / f"{name}.toml"
    return path if path.is_file() else None


def bundled_relative(path) -> str | None:
    """An absolute ``path`` relative to :data:`DATA_ROOT` (``trajectories/office.toml``, POSIX) when it lies in
    one of the bundled folders, else None (also for a relative path, such as a scene's name). A user's file, even
    one elsewhere in a checkout, is never taken for bundled data."""
    if not Path(path).is_absolute():
        return None
    resolved = Path(path).resolve()
    for folder in BUNDLED_DIRS:
        if resolved.is_relative_to(folder.resolve()):
            return resolved.relative_to(DATA_ROOT.resolve()).as_posix()
    return None


def bundled_trajectory_file(name) -> Path | None:
    """The bundled trajectory file that a relative ``name`` means, or None.

    ``name`` is a file of ``trajectories/`` (``office.toml``, or below it) or spelled from :data:`DATA_ROOT`
    (``trajectories/office.toml``, as ``simspad scenes`` prints it and scene.toml files write it).
    """
    path = Path(name)
    if path.is_absolute():
        return None
    candidates = [TRAJECTORIES_DIR / path]
    if len(path.parts) > 1 and path.parts[0] == TRAJECTORIES_DIR.name:
        candidates.append(DATA_ROOT / path)
    return next((c for c in candidates if c.is_file()), None)


def find_trajectory(name_or_path) -> Path:
    """A trajectory path as a user names it: an existing file, else a bundled trajectory.

    ``simspad scenes`` prints bundled trajectories as ``trajectories/office.toml`` (relative to the data root),
    and users type ``office.toml`` or ``office``; all three name the bundled ``trajectories/office.toml`` when no
    such file exists in the working directory. A file that exists always wins, so a user's own
    ``trajectories/office.toml`` is never shadowed. Anything else is returned unchanged for the loader to refuse
    with its own message.
    """
    path = Path(name_or_path)
    if path.exists():
        return path
    parts = path.parts
    if len(parts) == 2 and parts[0] == TRAJECTORIES_DIR.name:
        path = Path(parts[1])
    elif len(parts) != 1:
        return Path(name_or_path)
    candidates = [TRAJECTORIES_DIR / path.name] if path.suffix else sorted(TRAJECTORIES_DIR.glob(f"{path.name}.*"))
    candidates = [c for c in candidates if c.is_file()]
    return candidates[0] if len(candidates) == 1 else Path(name_or_path)

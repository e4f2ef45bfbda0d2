"""Where the data that ships with SimSPAD lives: dataset specs, built-in scenes and their trajectories.

They are package data of ``simspad`` (``simspad/data/``), found through :mod:`importlib.resources`, so an
installed wheel finds them from any working directory exactly as a source checkout does. The one place that
knows these folders; everything else asks here.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

# Mitsuba, OpenEXR and the TOML readers need real paths: SimSPAD is installed unpacked (wheels always are), so the
# package's data folder is a directory on disk.
DATA_ROOT = Path(str(files("simspad") / "data"))
DATASETS_DIR = DATA_ROOT / "datasets"
SCENES_DIR = DATA_ROOT / "scenes"
TRAJECTORIES_DIR = DATA_ROOT / "trajectories"


def builtin_spec_names() -> list[str]:
    """Names of the bundled dataset specs (``mini``, ``simspad``, …): what ``simspad generate NAME`` accepts."""
    return sorted(p.stem for p in DATASETS_DIR.glob("*.toml"))


def builtin_spec_path(name: str) -> Path | None:
    """The bundled spec called ``name`` (file stem), or None when there is none."""
    path = DATASETS_DIR / f"{name}.toml"
    return path if path.is_file() else None


def find_trajectory(name_or_path) -> Path:
    """A trajectory path as a user names it: an existing file, else a bundled trajectory.

    ``simspad scenes`` prints bundled trajectories as ``trajectories/office.toml`` (relative to the data root),
    and users type ``office.toml`` or ``office``; all three name ``simspad/data/trajectories/office.toml`` when no
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

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

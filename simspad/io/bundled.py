"""Where the data that ships with SimSPAD lives: dataset specs, built-in scenes and their trajectories.

The one place that knows these folders; everything else asks here.
"""

from __future__ import annotations

from pathlib import Path

# The data folders sit beside the package in the source tree (simspad/io/bundled.py → the repository root).
REPO_ROOT = Path(__file__).resolve().parents[2]
DATASETS_DIR = REPO_ROOT / "datasets"
SCENES_DIR = REPO_ROOT / "scenes"
TRAJECTORIES_DIR = REPO_ROOT / "trajectories"

"""The bundled data at the repository root: found from the checkout, named as users name it, never confused with
the checkout's other files (the data root of a checkout is the repository root, which holds much else)."""

from __future__ import annotations

from pathlib import Path

import pytest

import simspad
from simspad.bundled import (
    DATA_ROOT,
    DATASETS_DIR,
    SCENES_DIR,
    TRAJECTORIES_DIR,
    bundled_relative,
    bundled_trajectory_file,
)
from simspad.dataset.portable import portable_path
from simspad.dataset.spec_validation import load_spec
from simspad.errors import SpecError
from simspad.scenes.library import list_scenes

REPO = Path(__file__).resolve().parents[1]


def test_a_checkout_finds_the_data_at_its_root():
    assert Path(simspad.__file__).resolve().parent == REPO / "simspad"  # this checkout's code, so its data
    assert DATA_ROOT == REPO
    assert (DATASETS_DIR, SCENES_DIR, TRAJECTORIES_DIR) == (REPO / "datasets", REPO / "scenes", REPO / "trajectories")
    assert not (REPO / "simspad" / "_data").exists()  # only a wheel has it
    for scene in list_scenes():
        assert scene.folder.parent == SCENES_DIR
        assert scene.default_trajectory.parent == TRAJECTORIES_DIR


def test_only_the_three_folders_are_bundled_data():
    assert bundled_relative(TRAJECTORIES_DIR / "office.toml") == "trajectories/office.toml"
    assert bundled_relative(SCENES_DIR / "office" / "scene.toml") == "scenes/office/scene.toml"
    assert bundled_relative(DATASETS_DIR / "mini.toml") == "datasets/mini.toml"
    assert bundled_relative(REPO / "README.md") is None  # elsewhere in the checkout: a user's file
    assert bundled_relative(REPO / "simspad" / "defaults.py") is None
    assert bundled_relative("trajectories/office.toml") is None  # relative: a name, not a place


def test_a_spec_folder_inside_the_checkout_keeps_its_own_relative_paths():
    # A user's spec in the checkout (examples/, a clone's own folder) stores its files relative to itself, not as
    # "../examples/…" from the bundled specs' folder; bundled trajectories as the bundled specs always stored them.
    assert portable_path(REPO / "examples" / "spin.toml", REPO / "examples") == "spin.toml"
    assert portable_path(TRAJECTORIES_DIR / "fan.toml", REPO / "examples") == "../trajectories/fan.toml"


@pytest.mark.parametrize("name", ["office.toml", "trajectories/office.toml"])
def test_a_bundled_trajectory_by_the_names_users_give(name):
    assert bundled_trajectory_file(name) == TRAJECTORIES_DIR / "office.toml"


@pytest.mark.parametrize("name", ["README.md", "datasets/mini.toml", "scenes/office/scene.toml", "nowhere.toml"])
def test_other_files_of_the_data_root_are_not_trajectories(name):
    assert bundled_trajectory_file(name) is None


def test_a_spec_names_a_bundled_trajectory_but_not_a_file_of_the_checkout(tmp_path):
    spec = tmp_path / "spec.toml"
    body = 'name = "p"\nlux = [10]\n[[sequences]]\nscene = "fan"\ntrajectory = "{}"\nduration_s = 0.01\n'
    spec.write_text(body.format("trajectories/fan.toml"))
    assert Path(load_spec(spec).sequences[0].trajectory) == TRAJECTORIES_DIR / "fan.toml"
    spec.write_text(body.format("pyproject.toml"))  # at the checkout's root, not a bundled trajectory
    with pytest.raises(SpecError, match="trajectory file 'pyproject.toml' not found"):
        load_spec(spec)


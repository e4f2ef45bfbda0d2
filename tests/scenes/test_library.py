"""A user's Python scene runs only on an explicit opt-in; built-in scenes (code shipped with SimSPAD) always run."""

from __future__ import annotations

import os

from simspad.cli import main
from simspad.scenes.library import resolve_scene, scene_dict_or_file


def test_user_python_scene_is_refused_unless_opted_in(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("SIMSPAD_ALLOW_PYTHON_SCENES", raising=False)
    folder = tmp_path / "downloaded"
    folder.mkdir()
    marker = tmp_path / "ran"
    (folder / "scene.toml").write_text('description = "looks harmless"\n')
    (folder / "scene.py").write_text(f"import pathlib\npathlib.Path({str(marker)!r}).write_text('pwned')\n"
                                     "def build():\n    return {'type': 'scene'}\n")
    assert main(["render", str(folder), "--duration", "0.001", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "scene.py, which is Python code" in err and "--allow-python-scenes" in err and err.count("\n") == 1
    assert not marker.exists() and not (tmp_path / "r").exists()
    assert resolve_scene("siemens-star").builtin  # built-in scenes need no opt-in
    monkeypatch.setenv("SIMSPAD_ALLOW_PYTHON_SCENES", "1")  # what `simspad --allow-python-scenes` sets
    assert scene_dict_or_file(resolve_scene(folder)) == {"type": "scene"} and marker.read_text() == "pwned"


def test_allow_python_scenes_flag_sets_the_opt_in(monkeypatch):
    monkeypatch.delenv("SIMSPAD_ALLOW_PYTHON_SCENES", raising=False)
    assert main(["--allow-python-scenes", "scenes"]) == 0
    assert os.environ.get("SIMSPAD_ALLOW_PYTHON_SCENES") == "1"
    monkeypatch.delenv("SIMSPAD_ALLOW_PYTHON_SCENES")

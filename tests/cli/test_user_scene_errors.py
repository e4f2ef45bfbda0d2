"""User scenes that Mitsuba or our scene reader must refuse with one line that says why (issue 14, low)."""

from __future__ import annotations

import pytest

_XML = """<scene version="3.0.0">
  {extra}
  <integrator type="path"/>
  <emitter type="constant"/>
  <sensor type="perspective" id="camera"><float name="fov" value="45"/></sensor>
  <shape type="sphere" id="{shape_id}"/>
</scene>
"""


def _scene(tmp_path, *, extra="", shape_id="ball", toml=None):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "scene.xml").write_text(_XML.format(extra=extra, shape_id=shape_id))
    if toml is not None:
        (folder / "scene.toml").write_text(toml)
    return folder


def _render(simspad_cli, tmp_path, folder):
    return simspad_cli.run("render", folder, "--duration", "0.001", "--resolution", "8x6", "--spp", "1",
                           "--out", tmp_path / "out")


def test_missing_include_names_the_missing_file(tmp_path, simspad_cli):
    # Before: "Mitsuba cannot load the scene: … while processing <include>:" and nothing about the cause.
    folder = _scene(tmp_path, extra='<include filename="missing_part.xml"/>')
    proc = _render(simspad_cli, tmp_path, folder)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "<include>" in proc.stderr and "missing_part.xml" in proc.stderr and "not found" in proc.stderr
    assert "parser.cpp" not in proc.stderr


@pytest.mark.parametrize("where, fragment", [
    ("toml", "scene.toml: objects: entry 1 is an empty shape id"),
    ("xml", "scene.xml: shape.id: <shape type=\"sphere\"> has an empty id"),
])
def test_empty_shape_id_is_refused(tmp_path, simspad_cli, where, fragment):
    folder = (_scene(tmp_path, toml='objects = ["ball", ""]\n') if where == "toml"
              else _scene(tmp_path, shape_id=""))
    proc = _render(simspad_cli, tmp_path, folder)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert fragment in proc.stderr, proc.stderr


def test_empty_object_id_in_a_trajectory_is_refused(tmp_path, simspad_cli):
    traj = tmp_path / "t.toml"
    traj.write_text('[objects.""]\ngenerator = "static_pose"\nposition = [0, 0, 0]\n')
    proc = simspad_cli.run("info", traj)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "t.toml: objects: an object with an empty id" in proc.stderr, proc.stderr

"""Geometry passes of a render directory (simspad.io.geometry): files, their checks, the timeline block."""

from __future__ import annotations

import time

import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.geometry import gt_times, read_geometry, read_geometry_index, write_geometry


def test_pass_round_trip_and_same_bytes(tmp_path):
    depth = np.full((3, 4), 2.5, np.float32)
    depth[0, 0] = np.inf
    inst = np.arange(12, dtype=np.uint16).reshape(3, 4)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    write_geometry(a, depth, inst)
    time.sleep(1.1)  # a zip entry stamped with the current time would differ now
    write_geometry(b, depth, inst)
    assert a.read_bytes() == b.read_bytes()
    d, i = read_geometry(a, 4, 3)
    np.testing.assert_array_equal(d, depth)
    np.testing.assert_array_equal(i, inst)


@pytest.mark.parametrize("depth, inst, field", [
    (np.ones((3, 5), np.float32), np.zeros((3, 4), np.uint16), "depth_z"),
    (np.ones((3, 4), np.float32), np.zeros((3, 4), np.int32), "instance"),
    (-np.ones((3, 4), np.float32), np.zeros((3, 4), np.uint16), "depth_z"),
])
def test_bad_pass_is_refused_naming_the_array(tmp_path, depth, inst, field):
    path = tmp_path / "g.npz"
    np.savez(path, depth_z=depth, instance=inst)
    with pytest.raises(InputError) as err:
        read_geometry(path, 4, 3)
    assert err.value.field == field


def test_damaged_pass_is_refused(tmp_path):
    path = tmp_path / "g.npz"
    path.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a readable geometry pass"):
        read_geometry(path, 4, 3)


def _block(**over):
    inst = {"t": 0.0, "file": "geometry/000000-x.npz", "camera_to_world": np.eye(4).tolist()}
    block = {"rate_hz": 1000.0, "instances": ["a", "b"], "objects": [], "instants": [inst]}
    block.update(over)
    return {"geometry": block}


@pytest.mark.parametrize("over, field", [
    ({"rate_hz": 0}, "geometry.rate_hz"),
    ({"instances": ["a", "a"]}, "geometry.instances"),
    ({"objects": ["c"]}, "geometry.objects"),
    ({"instants": [{"t": 0.0, "file": "../x.npz", "camera_to_world": np.eye(4).tolist()}]},
     "geometry.instants[0].file"),
    ({"instants": [{"t": 0.0, "file": "g.npz", "camera_to_world": [[1, 0], [0, 1]]}]},
     "geometry.instants[0].camera_to_world"),
])
def test_malformed_block_names_the_field(tmp_path, over, field):
    with pytest.raises(InputError) as err:
        read_geometry_index(_block(**over), tmp_path, tmp_path / "timeline.json")
    assert err.value.field == field


def test_block_is_parsed(tmp_path):
    g = read_geometry_index(_block(), tmp_path, tmp_path / "timeline.json")
    assert g.instance_of("b") == 2 and g.camera_to_world.shape == (1, 4, 4) and g.object_to_world.shape == (1, 0, 4, 4)
    assert read_geometry_index({}, tmp_path, tmp_path / "timeline.json") is None


def test_gt_grid_includes_the_end_on_the_grid():
    np.testing.assert_allclose(gt_times(0.0, 0.004, 1000.0), [0, 0.001, 0.002, 0.003, 0.004])
    assert len(gt_times(0.0, 0.0045, 1000.0)) == 5

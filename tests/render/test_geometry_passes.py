"""Geometry passes (simspad.render.geometry, MitsubaScene.render_geometry): depth at the pixel centres, and
instance ids that every process gives the same shape."""

from __future__ import annotations

import numpy as np
import pytest

from simspad.motion.pinhole import PinholeCamera, unproject
from simspad.render.renderer import load_scene

W, H = 24, 18


@pytest.mark.slow
def test_instance_ids_do_not_depend_on_the_load():
    """Mitsuba lists a scene's shapes in an order that varies between loads; the office has unnamed shapes.
    Passes rendered by different processes (chunks of one render) must agree on every id."""
    images, names = set(), set()
    for _ in range(4):
        ms = load_scene("office", None, W, H, 4).ms
        ms.set_pose(ms.rest_camera_to_world, {})
        depth, inst = ms.render_geometry()
        images.add(inst.tobytes() + depth.tobytes())
        names.add(tuple(ms.instance_names))
    assert len(images) == 1 and len(names) == 1
    assert sum(n.startswith("_shape") for n in next(iter(names))) >= 2


def test_depth_is_sampled_at_the_pixel_centres():
    """Unprojecting the pass's depth through the pixel centres gives the surface points Mitsuba reports (its
    position AOV through the same unjittered sensor)."""
    ms = load_scene("piano", None, W, H, 4).ms
    ms.set_pose(ms.rest_camera_to_world, {})
    depth, inst = ms.render_geometry()
    mi = ms.mi
    aov = mi.load_dict({"type": "aov", "aovs": "pos:position"})
    img = np.array(mi.render(ms.scene, ms.params, sensor=ms.geometry_sensor, integrator=aov, spp=1), np.float64)
    hit = np.isfinite(depth)
    assert hit.mean() > 0.9 and (inst[hit] > 0).all() and (inst[~hit] == 0).all()
    points = unproject(PinholeCamera.from_fov(ms.x_fov_deg, W, H), depth, ms.rest_camera_to_world)
    assert np.abs(points[hit] - img[..., -3:][hit]).max() < 1e-4  # m; a jittered sample would be ~1 cm off

"""Retiming: a k× trajectory's pose at t is the base pose at k·t, for camera and objects alike."""

import numpy as np
import pytest

from simspad.bundled import TRAJECTORIES_DIR
from simspad.dataset.speed import base_span_s, retimed
from simspad.io.trajectory_files import load_trajectory


@pytest.mark.parametrize("k", [8.0, 3.0, 0.5])
def test_retimed_poses_equal_base_at_k_t(k):
    base = load_trajectory(TRAJECTORIES_DIR / "fan.toml")  # a camera and a spinning object
    fast = retimed(base, k)
    assert set(fast.bodies()) == set(base.bodies())
    t = np.linspace(0.0, base.t_end / k, 257)
    for name, tr in base.bodies().items():
        np.testing.assert_allclose(fast.bodies()[name].pose(t), tr.pose(k * t), rtol=0, atol=1e-12)
        v, w = fast.bodies()[name].velocity(t[1:-1])
        v0, w0 = tr.velocity(k * t[1:-1])
        np.testing.assert_allclose(v, k * v0, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(w, k * w0, rtol=1e-9, atol=1e-9)
    assert fast.t_end == pytest.approx(base.t_end / k, rel=1e-15)


def test_hand_held_camera_retimed_and_factor_one_unchanged():
    base = load_trajectory(TRAJECTORIES_DIR / "office.toml")
    assert retimed(base, 1.0) is base
    t = np.linspace(0.0, 0.25, 101)
    np.testing.assert_allclose(retimed(base, 8.0).camera.pose(t), base.camera.pose(8.0 * t), rtol=0, atol=1e-12)
    assert base_span_s(0.01, 0.05, 8.0) == pytest.approx((0.08, 0.48))


@pytest.mark.parametrize("k", [0.0, -2.0, float("nan"), float("inf")])
def test_bad_factor_refused(k):
    with pytest.raises(ValueError, match="speed factor"):
        retimed(load_trajectory(TRAJECTORIES_DIR / "office.toml"), k)

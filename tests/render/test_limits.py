"""Resource bounds of a render: refused up front with the figure, never after gigabytes are allocated."""

from __future__ import annotations

import resource
import time

import numpy as np
import pytest

from simspad.errors import InputError, SimSpadError
from simspad.io.trajectory_files import load_trajectory
from simspad.render.schedule import keyframe_schedule
from simspad.render.settings import RenderSettings


def test_huge_resolution_is_refused_with_its_memory_figure(monkeypatch):
    settings = RenderSettings(duration_s=0.01, resolution=(16000, 16000))
    with pytest.raises(SimSpadError, match=r"256\.0 Mpx needs about 15\.3 GiB.*SIMSPAD_IGNORE_LIMITS=1"):
        settings.checked_size()
    monkeypatch.setenv("SIMSPAD_IGNORE_LIMITS", "1")
    assert settings.checked_size() == (16000, 16000)  # the override lifts the size bound
    with pytest.raises(SimSpadError, match="max_flow_px"):  # a floor is never lifted
        RenderSettings(duration_s=0.01, max_flow_px=1e-12).checked_size()


def test_a_trajectory_jump_is_refused_before_the_schedule_grid_is_allocated():
    # A 0.5 m jump in 0.1 µs: the predicted image speed explodes (~1e10 px/s); before, the grid took > 5 GB.
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    with pytest.raises(SimSpadError, match=r"needs up to .* keyframes .* check the trajectory for a jump"):
        keyframe_schedule(0.0, 0.01, lambda t: np.full(np.shape(t), 1e10), 0.5, 1000.0)
    assert time.perf_counter() - t0 < 1.0
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0 < 200_000  # KiB: nothing big allocated
    times = keyframe_schedule(0.0, 0.01, lambda t: np.full(np.shape(t), 100.0), 0.5, 1000.0)
    assert times[0] == 0.0 and times[-1] == 0.01  # ordinary motion still schedules


def test_generator_with_absurd_rpm_is_refused_naming_the_field(tmp_path):
    path = tmp_path / "fan.toml"
    path.write_text('[objects.fan]\ngenerator = "object_rotation"\nrpm = 1e15\nduration_s = 1.0\n')
    with pytest.raises(InputError, match=r"objects\.fan.*needs 1\.07e\+15 samples.*limit is 2,000,000"):
        load_trajectory(path)

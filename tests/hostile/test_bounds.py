"""Every run is bounded or refused up front (docs/trust.md, "Runs: bounded, or refused up front").

Each case was a run that went on for minutes with no output: an event camera's noise rate or step tolerance that
explodes the kernel's work, a results.csv of 20 001 rows, a manifest listing one recording 80 000 times, a Dask
scheduler address that accepts and never answers. Each is now refused with the figure, in seconds, or bounded.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from simspad import defaults
from simspad.io.render_dir import write_render_dir
from simspad.sensors.events.model import mean_shot_noise_ratio, noise_rates_hz, noise_work_problem
from simspad.sensors.events.model import sensor_current_1lux_e_s, sensor_photocurrent_e_s
from simspad.sensors.presets import sensor_params

#: Seconds a refusal may take (a child process importing SimSPAD on 2 busy cores, not the minutes of the run).
REFUSAL_S = 60


@pytest.fixture()
def small_render(tmp_path) -> Path:
    rng = np.random.default_rng(1)
    times = np.array([0.0, 0.005, 0.01])
    frames = [rng.uniform(0.1, 1.0, (12, 16, 3)).astype(np.float32) for _ in times]
    return write_render_dir(tmp_path / "render", times, frames).parent


def _one_error_line(proc) -> str:
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("simspad: error: "), proc.stderr[-2000:]
    return lines[0]


# ---- the event camera's noise work and internal steps ---------------------------------------------------------

@pytest.mark.parametrize("setting, field", [
    ("events.shot_noise_rate_hz_at_1lux=1e12", "sensors.events.shot_noise_rate_hz_at_1lux"),
    ("events.hot_pixel_rate_hz=1e14", "sensors.events.hot_pixel_rate_hz"),
])
def test_simulate_refuses_noise_rates_that_explode_the_work(simspad_cli, small_render, tmp_path, setting, field):
    out = tmp_path / "rec.h5"
    start = time.monotonic()
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "spad,events", "--set", setting,
                           "--out", out)
    assert time.monotonic() - start < REFUSAL_S
    line = _one_error_line(proc)
    assert field in line and "random draws, above the limit of 1e+10" in line and "SIMSPAD_IGNORE_LIMITS" in line
    assert "192 pixels × 0.01 s" in line  # the figure: pixels × seconds × rate
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["render"]


def test_simulate_refuses_a_substep_tolerance_below_the_floor(simspad_cli, small_render, tmp_path):
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.substep_tolerance=1e-12", "--out", tmp_path / "rec.h5")
    line = _one_error_line(proc)
    assert "sensors.events.substep_tolerance" in line and "[1e-06, 0.1]" in line and "1e-12" in line
    # a floor, like MIN_MAX_FLOW_PX: lifting the size bounds does not lift it
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.substep_tolerance=1e-12", "--out", tmp_path / "rec.h5",
                           env={"SIMSPAD_IGNORE_LIMITS": "1"})
    assert "substep_tolerance" in _one_error_line(proc)


def test_simulate_at_the_default_noise_runs(simspad_cli, small_render, tmp_path):
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.shot_noise_rate_hz_at_1lux=1000", "--out", tmp_path / "rec.h5")
    assert proc.returncode == 0, proc.stderr[-2000:]


SPEC = """
name = "hostile"
seed = 1
output = "out"
lux = [10]
[[sequences]]
scene = "office"
duration_s = 0.03
resolution = [80, 60]
spp = 4
[sensors.events]
preset = "prophesee_gen4"
{extra}
"""


@pytest.mark.parametrize("extra, expect", [
    ("shot_noise_rate_hz_at_1lux = 1e12", "4800 pixels × 0.03 s"),
    ("substep_tolerance = 1e-12", "must be in [1e-06, 0.1]"),
])
def test_spec_with_exploding_event_work_is_refused_before_estimating(simspad_cli, tmp_path, extra, expect):
    """`generate --estimate` sat at "probing simulation throughput": the spec is now refused when it is loaded."""
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.format(extra=extra))
    for args in (("info", spec), ("generate", spec, "--estimate")):
        start = time.monotonic()
        proc = simspad_cli.run(*args)
        assert time.monotonic() - start < REFUSAL_S
        assert proc.returncode == 2 and expect in proc.stderr, proc.stderr[-2000:]
        assert "probing" not in proc.stdout + proc.stderr
    assert not (tmp_path / "out").exists()


def test_noise_work_figure_is_pixels_times_seconds_times_rate(monkeypatch):
    monkeypatch.delenv("SIMSPAD_IGNORE_LIMITS", raising=False)
    params = sensor_params("events", None, {"shot_noise_rate_hz_at_1lux": 1e9, "hot_pixel_fraction": 0.5,
                                            "hot_pixel_rate_hz": 2e8})
    # at 1 lx the bound's ratio is 1: 1e9 shot + 0.5 × 2e8 hot = 1.1e9 per pixel-second
    assert noise_rates_hz(params, 1.0) == (1e9, 1e8)
    message = noise_work_problem(params, 1000, 0.5, 1.0)
    assert "5.5e+11 random draws" in message
    assert noise_work_problem(params, 10, 0.5, 1.0) is None  # 5.5e9: under the bound
    # brighter than 1 lx the mean pixel's current grows with the light: r₁·lux^−γ
    assert noise_rates_hz(params, 100.0)[0] == pytest.approx(1e9 * 100 ** -0.5)
    monkeypatch.setenv("SIMSPAD_IGNORE_LIMITS", "1")
    assert noise_work_problem(params, 1000, 0.5, 1.0) is None


@pytest.mark.parametrize("lux", [1e-3, 1.0, 10.0, 1e4])
def test_scene_free_noise_rate_is_a_lower_bound_of_any_scene(lux):
    """The spec's check (no render yet) never refuses more than the render's exact figure would."""
    params = sensor_params("events")
    rng = np.random.default_rng(int(lux * 1000))
    for scale in (1e10, 1e14, 1e18):  # dark to very bright scenes, photons s⁻¹ m⁻² at this lux level
        flux = scale * rng.lognormal(0.0, 1.5, (24, 32))
        current = sensor_photocurrent_e_s(flux, params)
        i1 = sensor_current_1lux_e_s(float(flux.mean()), lux, params)
        exact = mean_shot_noise_ratio(current, i1, params)
        bound = noise_rates_hz(params, lux)[0] / params.shot_noise_rate_hz_at_1lux
        assert bound <= exact * (1 + 1e-12)


def test_bounds_are_named_in_defaults():
    assert defaults.MAX_EVENT_NOISE_DRAWS == 1e10 and defaults.MIN_SUBSTEP_TOLERANCE == 1e-6

"""The gallery examples run on a real simulated recording and report statistics that hold."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simspad.io.render_dir import write_render_dir
from simspad.sensors.presets import sensor_params
from simspad.sensors.simulate import RecordingSettings, simulate_recording

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.slow
def test_inspect_recording_runs_and_the_spad_estimate_matches_its_predicted_spread(tmp_path, child_env):
    rng = np.random.default_rng(3)
    base = 0.2 + rng.random((24, 32))
    times = np.linspace(0.0, 0.02, 5)
    frames = np.stack([base * (1.0 + 0.2 * np.sin(40 * t)) for t in times]).astype(np.float32)
    write_render_dir(tmp_path / "render", times, frames)
    render = tmp_path / "render"
    sensors = {k: sensor_params(k) for k in ("spad", "frames", "events")}
    rec = simulate_recording(render, tmp_path / "rec.h5", RecordingSettings(lux=10.0, sensors=sensors, seed=5))
    out = tmp_path / "fig.png"
    res = subprocess.run([sys.executable, str(EXAMPLES / "inspect_recording.py"), str(rec), "--out", str(out)],
                         capture_output=True, text=True, timeout=120, env=child_env)
    assert res.returncode == 0, res.stderr
    assert out.stat().st_size > 10_000
    m = re.search(r"log error mean ([-+\d.]+), rms ([\d.]+) vs predicted ([\d.]+)", res.stdout)
    assert m, res.stdout
    mean, rms, predicted = map(float, m.groups())
    # The ML estimator is nearly unbiased and its scatter is the Cramér–Rao spread (the flux varies slightly
    # within the aggregate, hence the tolerance).
    assert abs(mean) < 0.05 and 0.8 < rms / predicted < 1.25

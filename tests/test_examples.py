"""The gallery examples run on a real simulated recording and report statistics that hold."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simspad.io.recording import open_recording
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.sensors.presets import sensor_params
from simspad.sensors.simulate import RecordingSettings, simulate_recording

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.slow
def test_inspect_recording_runs_and_the_spad_estimate_matches_its_predicted_spread(tmp_path, child_env):
    """A real office render (48×36, 4 spp) at 10 lx: hot pixels are present and must be excluded, not scored."""
    render = tmp_path / "render"
    render_sequence("office", None, RenderSettings(duration_s=0.01, resolution=(48, 36), spp=4, max_flow_px=1e6,
                                                   min_rate_hz=1e3), out_dir=render, progress=False)
    sensors = {k: sensor_params(k) for k in ("spad", "frames", "events")}
    rec = simulate_recording(render, tmp_path / "rec.h5", RecordingSettings(lux=10.0, sensors=sensors, seed=5))
    with open_recording(rec) as r:
        a = r.spad.attrs
        n_hot = int((r.spad.dcr_cps > np.sqrt(a["dcr_median_cps"] * a["hot_pixel_dcr_cps"])).sum())
    assert n_hot > 0  # 2 % of 1728 pixels: the case the self-check used to score as ln(0)
    out = tmp_path / "fig.png"
    res = subprocess.run([sys.executable, str(EXAMPLES / "inspect_recording.py"), str(rec), "--out", str(out)],
                         capture_output=True, text=True, timeout=120, env=child_env)
    assert res.returncode == 0, res.stderr
    assert out.stat().st_size > 10_000
    m = re.search(r"log error mean ([-+\d.]+), rms ([\d.]+) vs predicted ([\d.]+) \((\d+) pixels; excluded (\d+) hot",
                  res.stdout)
    assert m, res.stdout
    mean, rms, predicted = map(float, m.groups()[:3])
    n_pixels, n_excluded_hot = map(int, m.groups()[3:])
    assert n_excluded_hot == n_hot and n_pixels > 100
    # The ML estimator is nearly unbiased and its scatter is the Cramér–Rao spread (the flux varies slightly
    # within the aggregate, hence the tolerance).
    assert abs(mean) < 0.05 and 0.8 < rms / predicted < 1.25


def test_torch_dataset_example_batches_every_window_and_the_grids_sum_to_on_minus_off(tmp_path, child_env):
    from tests.io.export.conftest import random_events, write_event_recording

    rng = np.random.default_rng(8)
    t, x, y, p = random_events(rng, 20_000, 2_000, 42_000, 40, 30)
    rec = write_event_recording(tmp_path / "rec.h5", t, x, y, p, width=40, height=30, t_start_s=0.002,
                                t_end_s=0.042)
    res = subprocess.run([sys.executable, str(EXAMPLES / "torch_dataset.py"), str(rec.path), "--window-ms", "4",
                          "--bins", "3", "--batch", "3"], capture_output=True, text=True, timeout=120, env=child_env)
    assert res.returncode == 0, res.stderr
    assert re.search(r": 10 windows of 4 ms in 4 batches, grids \(3, 30, 40\)", res.stdout), res.stdout
    m = re.search(r"events (\d+), ON - OFF (-?\d+), voxel grid sum (-?[\d.]+)", res.stdout)
    assert m, res.stdout
    # The ten windows cover the whole span, so the counts are the file's own.
    assert int(m.group(1)) == t.size and int(m.group(2)) == int(np.where(p == 1, 1, -1).sum())
    assert float(m.group(3)) == pytest.approx(int(m.group(2)), abs=1e-2)


@pytest.mark.slow
def test_real_captures_example_imports_evaluates_and_ranks_by_star_mtf(tmp_path, child_env, simspad_cli):
    """docs/captures.md end to end: stand-in captures (a shifted, late event camera), the checked-in calibration,
    import, evaluate without ground truth, leaderboard. The homography and time offset undo the event camera's
    shift and delay exactly; the SPAD and frames pass through unchanged."""
    import shutil

    import h5py
    import hdf5plugin  # noqa: F401

    example = EXAMPLES / "real_captures"
    shutil.copy(example / "calibration.toml", tmp_path / "calibration.toml")
    res = subprocess.run([sys.executable, str(example / "make_stand_in_captures.py"), str(tmp_path / "captures"),
                          "--keep-simulation", str(tmp_path / "sim.h5")], capture_output=True, text=True,
                         timeout=600, env=child_env)
    assert res.returncode == 0, res.stderr
    r = simspad_cli.run("import", tmp_path / "calibration.toml", "--out", tmp_path / "real" / "star.h5",
                        "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "valid region 100.0 %" in r.stdout
    with open_recording(tmp_path / "sim.h5") as sim, open_recording(tmp_path / "real" / "star.h5") as imp:
        assert not imp.has("gt") and sim.has("gt")
        for name in ("spad/bits", "spad/t_start", "frames/dn", "frames/t_start", "events/t", "events/x",
                     "events/y", "events/p", "events/ms_to_idx"):
            np.testing.assert_array_equal(imp.h5[name][()], sim.h5[name][()], err_msg=name)
        # the dark count map estimated from 20 000 dark gates finds the hot pixels
        hot = sim.spad.dcr_cps > 1000
        assert hot.any() and np.median(imp.spad.dcr_cps[hot]) > 500 and np.median(imp.spad.dcr_cps[~hot]) < 100
    r = simspad_cli.run("evaluate", tmp_path / "real" / "star.h5", "--out", tmp_path / "real" / "results")
    assert r.returncode == 0, r.stderr
    r = simspad_cli.run("leaderboard", tmp_path / "real" / "results", "--out", tmp_path / "real" / "board")
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "real" / "board" / "leaderboard.md").read_text()
    section = md.split("## Real captures (no ground truth)")[1]
    rows = [line for line in section.splitlines() if line.startswith("| ") and "Method" not in line]
    assert len(rows) == 8
    mtf25 = [float(line.split("|")[2].strip().strip("*")) for line in rows]
    assert mtf25 == sorted(mtf25, reverse=True) and all(0.2 < m < 1.0 for m in mtf25)
    with h5py.File(tmp_path / "real" / "results" / "reconstructions" / "star_rig_100lx" / "ni.h5") as f:
        assert f["flux"].shape == (20, 96, 96) and np.isfinite(f["flux"][()]).all()


def test_torch_dataset_example_yields_each_windows_motion_field(tmp_path, child_env):
    """A camera sliding past a wall 2 m away, 4 mm per millisecond, f = 30 px: every 2 ms window's flow is
    f·8 mm/2 m = 0.12 px to the right, valid wherever the point stays in the image (all of a 40-px-wide grid)."""
    import h5py

    from tests.io.export.conftest import random_events, write_event_recording

    W, H, f = 40, 30, 30.0
    rng = np.random.default_rng(4)
    t, x, y, p = random_events(rng, 5_000, 0, 10_000, W, H)
    rec = write_event_recording(tmp_path / "rec.h5", t, x, y, p, width=W, height=H, t_start_s=0.0, t_end_s=0.01)
    n = 11
    poses = np.repeat(np.eye(4)[None], n, axis=0)
    poses[:, 0, 3] = np.arange(n) * 0.004
    with h5py.File(rec.path, "r+") as h:
        h["gt/t"] = np.arange(n) * 1e-3
        h["gt/flux"] = np.ones((n, H, W), np.float32)
        h["gt/depth"] = np.full((n, H, W), 2.0, np.float32)
        h["gt/instance"] = np.ones((n, H, W), np.uint16)
        h["gt/instance"].attrs["names"] = '["", "wall"]'
        h["gt/flow"] = np.zeros((n, H, W, 2), np.float32)
        h["gt/camera_to_world"] = poses
        h.create_group("camera").attrs.update({"width": W, "height": H, "focal_px": f})
        h["camera/K"] = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    res = subprocess.run([sys.executable, str(EXAMPLES / "torch_dataset.py"), str(rec.path), "--window-ms", "2",
                          "--bins", "3", "--flow"], capture_output=True, text=True, timeout=120, env=child_env)
    assert res.returncode == 0, res.stderr
    m = re.search(r"flow over each window: mean ([\d.]+) px where valid \(([\d.]+)% of pixels\)", res.stdout)
    assert m, res.stdout
    assert float(m.group(1)) == pytest.approx(f * 0.008 / 2.0, abs=1e-4) and float(m.group(2)) == 100.0
    bad = subprocess.run([sys.executable, str(EXAMPLES / "torch_dataset.py"), str(rec.path), "--window-ms", "1.5",
                          "--flow"], capture_output=True, text=True, timeout=120, env=child_env)
    assert bad.returncode == 2 and "not a ground-truth instant" in bad.stderr

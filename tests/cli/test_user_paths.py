"""What a user copies from SimSPAD's own output works: bundled trajectories as `simspad scenes` prints them, speed in
every recording table, an estimate that never divides by more workers than cores, examples that fail in one line."""

import subprocess
import sys
from pathlib import Path

import pytest

from simspad.dataset.estimate import Estimate, _here_line
from simspad.dataset.executors import default_workers
from simspad.io.bundled import TRAJECTORIES_DIR, find_trajectory
from simspad.cli.text import recording_table

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("name", ["trajectories/office.toml", "office.toml", "office"])
def test_a_bundled_trajectory_is_found_by_each_name_a_user_types(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert find_trajectory(name) == TRAJECTORIES_DIR / "office.toml"


def test_a_users_own_file_wins_over_the_bundled_one_of_the_same_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "trajectories").mkdir()
    (tmp_path / "trajectories" / "office.toml").write_text("[camera]\n")
    assert find_trajectory("trajectories/office.toml") == Path("trajectories/office.toml")
    assert find_trajectory("nowhere/office.toml") == Path("nowhere/office.toml")  # for the loader to refuse


def test_info_describes_the_trajectory_that_simspad_scenes_prints(simspad_cli, tmp_path):
    scenes = simspad_cli.run("scenes")
    assert scenes.returncode == 0, scenes.stderr
    printed = next(line.split()[1] for line in scenes.stdout.splitlines() if line.startswith("office "))
    assert printed == "trajectories/office.toml"
    res = subprocess.run([*simspad_cli.command("info", printed)], capture_output=True, text=True,
                         cwd=tmp_path, env=simspad_cli.env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("trajectory ") and "office.toml" in res.stdout.splitlines()[0]


def test_recording_tables_show_the_speed_so_x1_and_x16_rows_differ():
    entries = [{"sequence": "fan", "speed_factor": k, "lux": 100.0, "status": "complete", "size": 1000,
                "path": f"recordings/fan/fan{'' if k == 1 else '_x16'}_100lx.h5"} for k in (1.0, 16.0)]
    header, slow, fast = recording_table(entries, "path", lambda e: e["path"])
    assert header.split()[:3] == ["sequence", "speed", "lux"]
    assert slow.split()[1] == "×1" and fast.split()[1] == "×16"


def _estimate(render_cpu_s: float) -> Estimate:
    return Estimate(n_renders=1, n_keyframes=100, n_recordings=1, render_cpu_s=render_cpu_s, sim_cpu_s=0.0,
                    longest_sim_s=0.0, largest_render_cpu_s=render_cpu_s, keyframe_s=[(render_cpu_s / 100, 100)],
                    scene_load_s=[], disk_bytes=0, recordings_bytes=0, renders_bytes=0, peak_render_rss_bytes=None,
                    peak_sim_rss_bytes=None, cores=default_workers(), plan_s=0.0)


def test_the_estimate_here_never_divides_by_more_workers_than_cores():
    cores = default_workers()
    est = _estimate(3600.0 * cores * 10)

    def hours(s):
        return f"{s / 3600:.2f} h"

    asked = _here_line(est, cores * 4, hours)
    assert hours(est.wall_s(cores)) in asked and hours(est.wall_s(cores * 4)) not in asked
    assert f"{cores * 4} workers asked" in asked
    assert _here_line(est, cores, hours).endswith(f"here ({cores} worker(s))")


@pytest.mark.parametrize("script", ["inspect_recording.py", "torch_dataset.py"])
def test_examples_refuse_a_missing_recording_in_one_line(script, tmp_path, child_env):
    res = subprocess.run([sys.executable, str(EXAMPLES / script), str(tmp_path / "fan_100lx.h5")],
                         capture_output=True, text=True, timeout=120, env=child_env)
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "Traceback" not in res.stderr
    assert "fan_100lx.h5" in res.stderr

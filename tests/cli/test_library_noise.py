"""Library noise stays out of what the user sees: a corrupt OpenEXR keyframe is one line on stderr, nothing on
stdout (the OpenEXR bindings print "Warning: Exception raised reading pixel data …" on stdout themselves)."""

from __future__ import annotations

import numpy as np

from simspad.io.render_dir import read_render_dir, write_render_dir


def test_truncated_keyframe_is_one_line_and_stdout_stays_clean(tmp_path, simspad_cli):
    rng = np.random.default_rng(0)
    render = write_render_dir(tmp_path / "r", np.array([0.0, 0.01]),
                              rng.random((2, 60, 80, 3)).astype(np.float32)).parent
    frame = read_render_dir(render).files[1]
    data = frame.read_bytes()
    frame.write_bytes(data[:len(data) - 100])  # header intact, the last scanlines gone
    proc = simspad_cli.run("simulate", render, "--lux", "10", "--out", tmp_path / "a.h5")
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""  # before: "Warning: Exception raised reading pixel data for part 0 - …"
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert f"{frame.name}: file: not a readable OpenEXR file (EXR_ERR_BAD_CHUNK_LEADER: " in proc.stderr, proc.stderr


def test_leaderboard_where_every_method_failed_has_no_matplotlib_warning(tmp_path, simspad_cli, evaluation_dataset):
    import csv

    res = tmp_path / "res"
    assert simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni", "--out", res).returncode == 0
    with open(res / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:  # as when every method failed: no finite PSNR to plot
        row.update(psnr_db="nan", ssim="nan", error="ValueError: failed")
    with open(res / "results.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    proc = simspad_cli.run("leaderboard", res, "--out", tmp_path / "board")
    assert proc.returncode == 0, proc.stderr
    # before: "plots.py:71: UserWarning: No artists with labels found to put in legend. …"
    assert "Warning" not in proc.stderr and "Warning" not in proc.stdout, proc.stderr


def test_no_resource_tracker_warning_after_the_driver_is_killed(tmp_path, simspad_cli):
    import signal
    import subprocess
    import time
    from pathlib import Path

    proc = subprocess.Popen(simspad_cli.command("generate", "mini", "--out", tmp_path / "mini", "--workers", 2),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=simspad_cli.env)
    deadline = time.monotonic() + 120
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    while proc.poll() is None and len(children.read_text().split()) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    proc.kill()  # kill -9: the resource tracker outlives the driver and cleans up its semaphores
    _, err = proc.communicate(timeout=120)
    # before: "resource_tracker: There appear to be 6 leaked semaphore objects to clean up at shutdown"
    assert "resource_tracker" not in err.decode() and "leaked" not in err.decode(), err.decode()[-2000:]

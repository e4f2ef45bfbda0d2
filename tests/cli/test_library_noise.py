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
